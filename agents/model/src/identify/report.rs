//! What the held-out residual still shows: its whiteness, its correlations with the inputs,
//! the orientation of its loop, and the series the plots draw.

use super::model::{Fitted, Signals};
use super::rows::Problem;
use super::{Correlation, Declared, Effect, Heldout, Options, Residual, Shaped, signals, stats};
use crate::hysteresis::Envelope;

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

/// How the held-out residual bends with the deflection, beside a line in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bend {
    /// The share of the residual's sum of squares about a line in x (a + b·x) that an odd
    /// cubic c·x³ beside the line takes, in [0, 1].
    pub share: f64,
    /// The swing: the 99th percentile of |x| over the rows [rad].
    pub x_max: f64,
    /// The joint's slope at ±x_max over its slope at rest, less one (< 0: softer toward the
    /// ends): 3c·x_max²/k, with k the measured torque's slope at rest (τ ≈ a + k·x + c′·x³).
    pub change: f64,
}

/// A bend is said where the cubic takes this share of the residual ...
pub(crate) const BEND_SHARE: f64 = 0.25;
/// ... and the stiffness changes toward the ends by this much ...
pub(crate) const BEND_CHANGE: f64 = 0.03;
/// ... but not by this much: beyond it the cubic's first-order reading fails (a joint 90 %
/// softer or stiffer at its ends is not a smooth bend: a stop, a slip, a fault).
pub(crate) const BEND_CHANGE_MAX: f64 = 0.9;

/// The cubic coefficient of `e` beside a line in x over the rows of `x` where `keep` holds, and
/// the share of the residual about the line it takes.
fn cubic_beside_line(x: &[f64], e: &[f64], keep: impl Fn(usize) -> bool) -> Option<(f64, f64)> {
    let idx: Vec<usize> = (0..x.len()).filter(|&i| keep(i)).collect();
    if idx.len() < 10 {
        return None;
    }
    let ones = vec![1.0; x.len()];
    let cubes: Vec<f64> = x.iter().map(|v| v * v * v).collect();
    let rss = |cols: &[&[f64]]| -> Option<(f64, Vec<f64>)> {
        let c = stats::least_squares(cols, e, &idx)?;
        let fit = stats::combine(cols, &c, e.len());
        Some((idx.iter().map(|&i| (e[i] - fit[i]).powi(2)).sum(), c))
    };
    let (line, _) = rss(&[&ones, x])?;
    let (cubic, c) = rss(&[&ones, x, &cubes])?;
    (line > 0.0).then(|| (c[2], (1.0 - cubic / line).clamp(0.0, 1.0)))
}

/// The bend of the residual `e` (indexed like `rows`) with the deflection `x` (indexed by
/// row), and the measured torque `tau` (indexed by row) for the slope at rest. What straight
/// lines leave of a joint whose stiffness changes with its deflection — a lever's geometry
/// softens it toward the ends of its travel, a progressive spring or a stop's onset stiffens
/// it — is an odd function of the deflection, to first order c·x³, and the same loading and
/// unloading. A loop's misfit at its tips is not: it lies where the motion turns, on one
/// branch. So the bend is read only where the cubics of the loading rows and of the unloading
/// rows (`dir`, indexed by row: > 0 loading, < 0 unloading) have one sign and are within a
/// factor of two of each other. `None` with under ten rows either way, a residual of another
/// length, a degenerate fit or branches that disagree.
pub(crate) fn bend(x: &[f64], tau: &[f64], dir: &[f64], rows: &[usize], e: &[f64]) -> Option<Bend> {
    if rows.len() < 10 || e.len() != rows.len() {
        return None;
    }
    let xs: Vec<f64> = rows.iter().map(|&i| x[i]).collect();
    let ds: Vec<f64> = rows.iter().map(|&i| dir[i]).collect();
    let (up, _) = cubic_beside_line(&xs, e, |i| ds[i] > 0.0)?;
    let (down, _) = cubic_beside_line(&xs, e, |i| ds[i] < 0.0)?;
    if up * down <= 0.0 || up.abs().max(down.abs()) > 2.0 * up.abs().min(down.abs()) {
        return None;
    }
    let (c, share) = cubic_beside_line(&xs, e, |_| true)?;
    let ts: Vec<f64> = rows.iter().map(|&i| tau[i]).collect();
    let ones = vec![1.0; xs.len()];
    let cubes: Vec<f64> = xs.iter().map(|v| v * v * v).collect();
    let all: Vec<usize> = (0..xs.len()).collect();
    let k = stats::least_squares(&[&ones, &xs, &cubes], &ts, &all)?[1];
    let mut mags: Vec<f64> = xs.iter().map(|v| v.abs()).collect();
    mags.sort_by(f64::total_cmp);
    let x_max = mags[(mags.len() * 99 / 100).min(mags.len() - 1)];
    (k != 0.0 && x_max > 0.0).then(|| Bend {
        share,
        x_max,
        change: 3.0 * c * x_max * x_max / k,
    })
}

/// The share of held-out samples beyond the fit rows' input range over which
/// [`diagnose`] says so ([`BEYOND_ERROR_RATIO`] too).
const BEYOND_SHARE: f64 = 0.01;
/// How much larger the held-out error beyond the fit rows' input range must be than within
/// it: an input the fit never reached where the model still holds is no finding.
const BEYOND_ERROR_RATIO: f64 = 2.0;

/// Held-out samples whose input lies outside the range the fit rows covered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Beyond {
    /// The fit rows' input range [rad].
    pub fit: (f64, f64),
    /// The held-out rows' input range [rad].
    pub held: (f64, f64),
    /// The share of held-out samples outside `fit`.
    pub share: f64,
    /// The held-out residual's rms outside `fit` over its rms within (∞ where it is 0 within).
    pub error_ratio: f64,
}

/// Where the held-out input `x` (rows `held`, residual `e` indexed like `held`) leaves the
/// range of the fit rows `fit`. None where it never does, or where no sample lies within.
pub(crate) fn beyond_the_fit(
    x: &[f64],
    fit: &[usize],
    held: &[usize],
    e: &[f64],
) -> Option<Beyond> {
    let range = |rows: &[usize]| {
        rows.iter()
            .map(|&i| x[i])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    };
    let (lo, hi) = range(fit);
    let (mut out, mut within) = ((0.0, 0usize), (0.0, 0usize));
    for (&i, r) in held.iter().zip(e) {
        let acc = if (lo..=hi).contains(&x[i]) {
            &mut within
        } else {
            &mut out
        };
        acc.0 += r * r;
        acc.1 += 1;
    }
    if out.1 == 0 || within.1 == 0 {
        return None;
    }
    let rms = |(ss, n): (f64, usize)| (ss / n as f64).sqrt();
    Some(Beyond {
        fit: (lo, hi),
        held: range(held),
        share: out.1 as f64 / held.len() as f64,
        error_ratio: rms(out) / rms(within),
    })
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
    fit: &[usize],
    chosen: &[Shaped],
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
    // Straight lines for a joint whose stiffness changes with its deflection (the restoring
    // loop with a config's lever envelope, or softened by identify, follows a lever; nothing
    // follows a progressive spring).
    let straight = opts.model == Declared::Linear
        || (opts.model == Declared::Restoring && p.envelope == Envelope::Linear);
    let bent = straight
        .then(|| bend(&s.x, &p.tau, &s.dir, rows, e))
        .flatten();
    if let Some(b) = bent
        && b.share >= BEND_SHARE
        && (BEND_CHANGE..=BEND_CHANGE_MAX).contains(&b.change.abs())
    {
        structure.push(format!(
            "it bends with the deflection: an odd cubic takes {:.0} % of it beyond a line, and the joint is {:.0} % {} at ±{:.3} rad than at rest where the model's lines are straight — {}",
            100.0 * b.share,
            100.0 * b.change.abs(),
            if b.change < 0.0 { "softer" } else { "stiffer" },
            b.x_max,
            if b.change < 0.0 {
                "a lever's geometry (the restoring model given the lever by --config follows its curve)"
            } else {
                "a progressive spring, or a stop's onset"
            }
        ));
    }
    if let Some(b) = beyond_the_fit(&s.x, fit, rows, e)
        && b.share >= BEYOND_SHARE
        && b.error_ratio >= BEYOND_ERROR_RATIO
    {
        structure.push(format!(
            "the held-out data go beyond the fit data's {} ({:+.4} to {:+.4} rad; held out {:+.4} to {:+.4} rad): {:.0} % of the held-out samples lie outside it and their error is {:.1}× that of the samples within — what acts there (a stop, a bend) is not in the fit data, so no effect could be found for it; fit on a test that covers the held-out range",
            inputs[0].0,
            b.fit.0,
            b.fit.1,
            b.held.0,
            b.held.1,
            100.0 * b.share,
            b.error_ratio
        ));
    }
    if opts.model.is_joint() && loop_before < -LOOP_BACKWARDS {
        // A lag of the torque path (δ > 0) runs the loop backwards.
        let lag_found = chosen
            .iter()
            .any(|c| c.effect == Effect::SensorDelay && c.shape > 0.0);
        let others: Vec<&str> = chosen
            .iter()
            .filter(|c| c.effect != Effect::SensorDelay)
            .map(|c| c.effect.name())
            .collect();
        // Where the effects found (no lag among them) leave a held-out residual that no
        // longer loops backwards, the loop was theirs: a stiffness that grows over the run
        // unloads stiffer than it loaded (the third generator's drift seed 70: −0.14 before,
        // +0.00 after), and a stop or a gap the declared model crosses with a line, or its
        // own loop bent to hold them, leaves the same sign. Saying "a lag or a sign error"
        // there sends a lab after the wrong part.
        let explained = if lag_found {
            " — it is the torque lagging the deflection (found: sensor_delay), or a sign error"
                .to_string()
        } else if !others.is_empty() && loop_after >= -LOOP_BACKWARDS {
            format!(
                " — with what was found ({}) the held-out residual no longer does ({loop_after:+.2}): it was theirs (a stiffness that changes over the run, a stop or a gap the model's line or loop bends across), not a lag between the sensors",
                others.join(", ")
            )
        } else if opts.model == Declared::Restoring {
            " — against the declared loop: the torque lagging the deflection, a sign error, or the loop fitted taller than the data's where it bends to hold something it lacks".to_string()
        } else {
            " — no passive part does that; it is the torque lagging the deflection, or a sign error"
                .to_string()
        };
        structure.push(format!(
            "the declared model's residual loops the other way round ({loop_before:+.2}: loading below unloading, it gives energy back){explained}"
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
        bend: bent,
        structure,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_softening_spring_seen_through_a_line_bends_by_its_closed_form_and_noise_does_not() {
        // τ = k·x − c·x³ over a sine's whole cycles: its slope at ±A is k − 3c·A², so the
        // change toward the ends is −3c·A²/k; what a line leaves of it is all cubic.
        let (k, c, a) = (2.0, 10.0, 0.2);
        let n = 4000;
        let x: Vec<f64> = (0..n)
            .map(|i| a * (std::f64::consts::TAU * 3.0 * i as f64 / n as f64).sin())
            .collect();
        let tau: Vec<f64> = x.iter().map(|x| k * x - c * x * x * x).collect();
        let rows: Vec<usize> = (0..n).collect();
        let ones = vec![1.0; n];
        // A model of straight lines: the secant a line fit gives.
        let line = stats::least_squares(&[&ones, &x], &tau, &rows).unwrap();
        let e: Vec<f64> = (0..n).map(|i| tau[i] - line[0] - line[1] * x[i]).collect();
        // Loading where x rises, unloading where it falls: the same bend on both.
        let dir: Vec<f64> = (0..n)
            .map(|i| {
                if i + 1 < n && x[i + 1] < x[i] {
                    -1.0
                } else {
                    1.0
                }
            })
            .collect();
        let b = bend(&x, &tau, &dir, &rows, &e).unwrap();
        assert!(b.share > 0.999, "{b:?}");
        assert!(b.x_max > 0.99 * a && b.x_max <= a, "{b:?}");
        let want = -3.0 * c * b.x_max * b.x_max / k;
        assert!((b.change - want).abs() < 1e-9, "{b:?} against {want}");
        // White noise has no cubic in it beyond what chance gives, ~1/n of its squares.
        let mut u = signals::uniforms(12345);
        let noise: Vec<f64> = (0..n).map(|_| u() - 0.5).collect();
        // (its branches' cubics may disagree: then no bend at all)
        if let Some(b) = bend(&x, &tau, &dir, &rows, &noise) {
            assert!(b.share < 0.01, "{b:?}");
        }
        // A misfit on one branch only (a loop's tips, where the motion turns) is no bend.
        let tips: Vec<f64> = (0..n)
            .map(|i| if dir[i] > 0.0 { e[i] } else { 0.0 })
            .collect();
        assert_eq!(bend(&x, &tau, &dir, &rows, &tips), None);
        // Too few rows, or a residual of another length: no answer.
        assert_eq!(bend(&x, &tau, &dir, &rows[..5], &e[..5]), None);
        assert_eq!(bend(&x, &tau, &dir, &rows, &e[..10]), None);
    }

    #[test]
    fn held_out_samples_beyond_the_fit_range_are_counted_with_their_errors_ratio() {
        // Fit rows sweep ±0.2 rad, held-out rows ±0.3 rad evenly: a third of them lie beyond
        // (|x| > 0.2), where the residual is 0.5 against 0.05 within.
        let fit: Vec<usize> = (0..201).collect();
        let held: Vec<usize> = (201..502).collect();
        let x: Vec<f64> = (0..201)
            .map(|i| -0.2 + 0.4 * i as f64 / 200.0)
            .chain((0..301).map(|i| -0.3 + 0.6 * i as f64 / 300.0))
            .collect();
        let e: Vec<f64> = held
            .iter()
            .map(|&i| if x[i].abs() > 0.2 + 1e-12 { 0.5 } else { 0.05 })
            .collect();
        let b = beyond_the_fit(&x, &fit, &held, &e).unwrap();
        assert!((b.fit.0 + 0.2).abs() < 1e-12 && (b.fit.1 - 0.2).abs() < 1e-12);
        assert!((b.held.0 + 0.3).abs() < 1e-12 && (b.held.1 - 0.3).abs() < 1e-12);
        let outside = held.iter().filter(|&&i| x[i].abs() > 0.2 + 1e-12).count();
        assert_eq!(outside, 100);
        assert!((b.share - 100.0 / 301.0).abs() < 1e-12, "{b:?}");
        assert!((b.error_ratio - 10.0).abs() < 1e-9, "{b:?}");
        // Held-out rows within the fit's range: nothing to say.
        assert_eq!(beyond_the_fit(&x, &held, &fit, &e[..201]), None);
    }
}
