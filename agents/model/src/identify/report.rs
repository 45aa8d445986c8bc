//! What the held-out residual still shows: its whiteness, its correlations with the inputs,
//! the orientation of its loop, and the series the plots draw.

use super::model::{Fitted, Signals};
use super::rows::Problem;
use super::{Correlation, Heldout, Options, Residual, signals, stats};

/// Held-out series: measured (tared), the declared model's and the final prediction.
pub(crate) fn heldout(
    p: &Problem,
    rows: &[usize],
    sig0: &Signals,
    base: &Fitted,
    after: &Fitted,
) -> Heldout {
    Heldout {
        run: rows
            .iter()
            .map(|&i| {
                p.bounds
                    .iter()
                    .position(|&(a, b)| i >= a && i < b)
                    .unwrap_or(0)
            })
            .collect(),
        t: rows.iter().map(|&i| sig0.t_rel[i]).collect(),
        x: rows.iter().map(|&i| sig0.x[i]).collect(),
        measured: rows.iter().map(|&i| p.tau[i]).collect(),
        before: rows.iter().map(|&i| base.prediction[i]).collect(),
        after: rows.iter().map(|&i| after.prediction[i]).collect(),
    }
}

/// Mean held-out residual per held-out run.
pub(crate) fn bias(p: &Problem, h: &Heldout, e: &[f64]) -> Vec<(String, f64)> {
    p.runs
        .iter()
        .enumerate()
        .filter_map(|(k, r)| {
            let v: Vec<f64> = h
                .run
                .iter()
                .zip(e)
                .filter(|(run, _)| **run == k)
                .map(|(_, e)| *e)
                .collect();
            (!v.is_empty()).then(|| (r.name.clone(), stats::mean(&v)))
        })
        .collect()
}

/// A residual loop more negative than this runs backwards beyond what noise draws: the report
/// says it is a lag of the torque path, and selection takes that as evidence for one.
pub(crate) const LOOP_BACKWARDS: f64 = 0.1;

/// The orientation of the residual's loop against the angle: ∮e·dx / (rms(e)·∮|dx|) over the
/// contiguous stretches of `rows` (`e` is indexed like `rows`). Positive: loading above
/// unloading (dissipative, what friction and hysteresis leave); negative: it gives energy
/// back — no passive part does that: the torque lags the deflection, or a sign is wrong.
pub(crate) fn loop_area(p: &Problem, x: &[f64], rows: &[usize], e: &[f64]) -> f64 {
    let (mut area, mut path) = (0.0, 0.0);
    for (a, b) in p.stretches(rows) {
        for k in a + 1..b.saturating_sub(1) {
            let dx = 0.5 * (x[rows[k + 1]] - x[rows[k - 1]]);
            area += e[k] * dx;
            path += dx.abs();
        }
    }
    let r = stats::rmse(e);
    if path > 0.0 && r > 0.0 {
        area / (path * r)
    } else {
        0.0
    }
}

/// Whiteness, cross-correlations and loop orientation of the held-out residual `e` (indexed
/// like `rows`), and what they point to.
#[allow(clippy::too_many_arguments)]
pub(crate) fn diagnose(
    p: &Problem,
    s: &Signals,
    rows: &[usize],
    e: &[f64],
    dt: f64,
    opts: &Options,
    (loop_before, loop_after): (f64, f64),
    lag_found: bool,
) -> Residual {
    // Contiguous held-out stretches, resampled onto a uniform grid (sampling may be irregular).
    let mut seg_e = Vec::new();
    let mut seg_in: Vec<Vec<Vec<f64>>> = vec![Vec::new(); 3];
    let inputs: [(&'static str, &[f64]); 3] = [
        (
            if opts.model.is_joint() {
                "deflection"
            } else {
                "angle"
            },
            &s.x,
        ),
        ("rate", &s.xdot),
        ("direction", &s.dir),
    ];
    let t_abs: Vec<f64> = p.runs.iter().flat_map(|r| r.t.iter().copied()).collect();
    for (a, b) in p.stretches(rows) {
        let idx = &rows[a..b];
        let t: Vec<f64> = idx.iter().map(|&i| t_abs[i]).collect();
        seg_e.extend(signals::uniform_segments(&t, &e[a..b], dt, 5.0 * dt));
        for (j, (_, x)) in inputs.iter().enumerate() {
            let xs: Vec<f64> = idx.iter().map(|&i| x[i]).collect();
            seg_in[j].extend(signals::uniform_segments(&t, &xs, dt, 5.0 * dt));
        }
    }
    let n: usize = seg_e.iter().map(|s| s.len()).sum();
    let lags = 50usize;
    // What noise alone shows: nothing at any lag, or in the weak form (the link equation) the
    // smoother's own autocorrelation ρ_S, each estimate then with the variance
    // Σ_j ρ_S(j)² / n (Bartlett) instead of 1/n. Whiteness is the residual's autocorrelation
    // against that: a smoothed residual is not "slow structure" for being smoothed.
    let expected = if p.weak() {
        signals::weak_autocorrelation(p.rate_window, dt)
    } else {
        vec![1.0]
    };
    let spread: f64 = 1.0 + 2.0 * expected.iter().skip(1).map(|r| r * r).sum::<f64>();
    // Two-sided 5 % over 50 lags, Bonferroni: z = Φ⁻¹(1 − 0.025/50) = 3.29.
    let band = 3.29 * (spread / n.max(1) as f64).sqrt();
    let autocorr = stats::autocorrelation(&seg_e, lags);
    let (kmax, max_autocorr) = autocorr
        .iter()
        .enumerate()
        .map(|(k, r)| {
            (
                k + 1,
                (r - expected.get(k + 1).copied().unwrap_or(0.0)).abs(),
            )
        })
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let white = max_autocorr <= band;
    let lag_span = ((opts.max_delay / dt).round() as i64).clamp(5, 200);
    let mut cross = Vec::new();
    let mut cross_curves = Vec::new();
    for (j, (name, _)) in inputs.iter().enumerate() {
        let c = stats::cross_correlation(&seg_e, &seg_in[j], -lag_span, lag_span);
        let (lag, r) =
            c.iter().copied().fold(
                (0, 0.0f64),
                |a, b| if b.1.abs() > a.1.abs() { b } else { a },
            );
        cross.push(Correlation {
            input: name,
            max_abs: r.abs(),
            lag_s: lag as f64 * dt,
        });
        cross_curves.push((*name, c.iter().map(|&(k, r)| (k as f64 * dt, r)).collect()));
    }
    let mut structure = Vec::new();
    if !white {
        structure.push(format!(
            "the residual is not white: autocorrelation {}{max_autocorr:.2} at lag {:.3} s (band ±{band:.3}) — slow structure no candidate explains",
            if p.weak() { "off the smoother's own by " } else { "" },
            kmax as f64 * dt
        ));
    }
    for c in &cross {
        if c.max_abs > band.max(0.1) {
            structure.push(format!(
                "it correlates with the {} ({:.2} at {:+.3} s)",
                c.input, c.max_abs, c.lag_s
            ));
        }
    }
    if opts.model.is_joint() && loop_before < -LOOP_BACKWARDS {
        structure.push(format!(
            "the declared model's residual loops the other way round ({loop_before:+.2}: loading below unloading, it gives energy back) — no passive part does that; it is the torque lagging the deflection{}, or a sign error",
            if lag_found { " (found: sensor_delay)" } else { "" }
        ));
    }
    Residual {
        white,
        max_autocorr,
        max_autocorr_lag_s: kmax as f64 * dt,
        band,
        lags,
        autocorr,
        cross,
        cross_curves,
        loop_before,
        loop_after,
        structure,
    }
}
