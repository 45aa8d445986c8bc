//! Rests as states of the loop: the tare rule for a spring with hysteresis.
//!
//! A spring with friction or hysteresis at rest sits somewhere between its loading and
//! unloading branches: friction holds it loaded. Taking that rest's torque and deflection as
//! zeros (the rest rule, [`super::rows::apply_tare`]) takes a load for a zero. Under this rule
//! nothing is subtracted from the deflection (the encoder's frame is kept from run to run), and
//! each run starts its stop operators at the common fraction λ ∈ [−1, 1] of their half-widths
//! that puts the model through the run's rest point; only what the loop cannot hold there
//! (beyond |λ| = 1) is a torque zero, less what the model misses at the fit runs' rests (a
//! property of the test's protocol, carried to the held-out runs). A model without hysteresis
//! has no state to set: for a linear spring that is the rest rule again.
//!
//! One more reading, of how an encoder is zeroed: where a held-out run's encoder was zeroed at
//! its start (its first reading is zero), it was zeroed where the test before it left the
//! spring. The last fit run, a test of the same protocol, stands for that test: the held-out
//! run is read in its frame, shifted by where it ends unloaded (its last deflection less its
//! last torque over the linear stiffness).
//!
//! The rule applies to the linear spring (the springs' model) when every run starts at rest;
//! the fit runs' states are refined with the fit (three rounds), the held-out runs' are set
//! from the final coefficients: the held-out data chooses a state as a tare chooses zeros, never
//! a coefficient.

use super::effects::{Effect, Shaped};
use super::model::{Fitted, Signals, Transform, fit};
use super::rows::{Problem, Tare, resolution};
use super::select::Rows;
use super::signals::stop_operator_from;
use super::stats::{mean, median, span};
use super::{Declared, IdentifyError, Run};

/// Each run's rest (its samples), when the loop-state rule applies: the linear spring, every
/// run tared at rest (the tare is every run's or none).
pub(crate) fn rests(model: Declared, tare: &[Tare]) -> Option<Vec<(usize, usize)>> {
    (model == Declared::Linear && !tare.is_empty()).then(|| tare.iter().map(|t| t.rest).collect())
}

/// Whether the run's encoder was zeroed at its start: its first reading within three
/// quantisation steps of zero (0.1 % of the run's range where the angle is not quantised); a
/// frame carried over from earlier tests reads elsewhere.
pub(crate) fn zeroed_at_start(r: &Run) -> bool {
    let Some(phi) = r.phi.as_deref().filter(|p| !p.is_empty()) else {
        return false;
    };
    let range = span(phi);
    let step = resolution(phi);
    let within = if step > 0.0 { 3.0 * step } else { 1e-3 * range };
    range > 0.0 && phi[0].abs() <= within
}

/// Where a run ends unloaded [rad]: the medians of its last 0.25 s of deflection and torque,
/// the deflection less the torque over the stiffness `k` (the deflection alone when `k` is not
/// a positive stiffness). `None` unless the run ends nearly unloaded (its last torque within
/// 10 % of its largest): where a test ends loaded, the state it left the spring in is unknown.
pub(crate) fn end_unloaded(r: &Run, k: f64) -> Option<f64> {
    let phi = r.phi.as_deref().filter(|p| !p.is_empty())?;
    let t_end = r.t[r.t.len() - 1];
    let a =
        r.t.partition_point(|t| *t < t_end - 0.25)
            .min(r.t.len() - 1);
    let (x, tau) = (median(&phi[a..]), median(&r.tau[a..]));
    let peak = r.tau.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if tau.abs() > 0.1 * peak {
        return None;
    }
    Some(if k.is_finite() && k > 0.0 {
        x - tau / k
    } else {
        x
    })
}

/// The deflection each run is shifted by (added to its readings) to be read in the first fit
/// run's frame: `(fit, held)`, `None` where a run is read as measured. A run zeroed at its
/// start was zeroed where the run before it left the spring, so it follows that run's frame,
/// shifted by where that run ends unloaded, when that run was zeroed at its start too and
/// ended unloaded. The fit runs chain in the order given (the second fit run follows the
/// first, and so on); every held-out run follows the last fit run. With one fit run the
/// held-out run's shift is where it ends unloaded; with two, where the first ends plus where
/// the second ends in its own readings.
pub(crate) fn continuity(
    fit: &[Run],
    held: &[Run],
    k: f64,
) -> (Vec<Option<f64>>, Vec<Option<f64>>) {
    // Where a run ends unloaded in the first fit run's frame, given its own shift: what a run
    // zeroed after it is shifted by.
    let next = |r: &Run, shift: Option<f64>| -> Option<f64> {
        zeroed_at_start(r)
            .then(|| end_unloaded(r, k))
            .flatten()
            .map(|e| shift.unwrap_or(0.0) + e)
    };
    let mut fit_shift: Vec<Option<f64>> = Vec::with_capacity(fit.len());
    for (i, r) in fit.iter().enumerate() {
        let s = match i.checked_sub(1) {
            Some(j) if zeroed_at_start(r) => next(&fit[j], fit_shift[j]),
            _ => None,
        };
        fit_shift.push(s);
    }
    let end = fit.last().and_then(|r| next(r, fit_shift[fit.len() - 1]));
    let held_shift = held
        .iter()
        .map(|h| end.filter(|_| zeroed_at_start(h)))
        .collect();
    (fit_shift, held_shift)
}

/// The run with `shift` added to its deflection.
pub(crate) fn shifted(r: &Run, shift: f64) -> Run {
    let mut out = r.clone();
    if let Some(phi) = out.phi.as_mut() {
        phi.iter_mut().for_each(|v| *v += shift);
    }
    out
}

/// The fit of `trial` on the fit rows with each run's state set from its rest (module docs),
/// its prediction on held-out rows carrying their torque zeros. Sets `p.states` and
/// `p.shifts`. Without rests to read (`p.loop_rests` unset), the plain fit.
pub(crate) fn settle(
    p: &mut Problem,
    trial: &[Shaped],
    rows: &Rows,
) -> Result<Fitted, IdentifyError> {
    let tr = Transform::of(trial);
    let fit_once = |p: &Problem| -> Result<(Signals, Fitted), IdentifyError> {
        let s = p.signals(tr);
        let f = fit(&s, trial, &p.tau, &rows.fit).ok_or(IdentifyError::Solve)?;
        Ok((s, f))
    };
    let Some(rests) = p.loop_rests.clone() else {
        p.states = None;
        return Ok(fit_once(p)?.1);
    };
    let n = p.runs.len();
    let hyst = trial.iter().position(|c| c.effect == Effect::Hysteresis);
    let mut states = vec![0.0; n];
    p.states = Some(states.clone());
    let (mut s, mut f) = fit_once(p)?;
    if let Some(h) = hyst {
        for _ in 0..3 {
            for (k, rest) in rests.iter().enumerate().take(p.fit_runs) {
                states[k] = at_rest(p, &s, &f, Some(h), k, *rest).0;
            }
            p.states = Some(states.clone());
            (s, f) = fit_once(p)?;
        }
    }
    // What the model misses at the fit runs' rests (nothing, where the loop holds them) is
    // the protocol's, not a zero: each held-out run's torque zero is its own less that.
    let missed = (0..p.fit_runs)
        .map(|k| at_rest(p, &s, &f, hyst, k, rests[k]).1)
        .sum::<f64>()
        / p.fit_runs.max(1) as f64;
    let mut shifts = vec![0.0; n];
    for k in p.fit_runs..n {
        (states[k], shifts[k]) = at_rest(p, &s, &f, hyst, k, rests[k]);
        shifts[k] -= missed;
    }
    if hyst.is_some() {
        // The fit rows' columns are unchanged (each run's operators restart): the same
        // coefficients, the held-out rows predicted from their own states.
        p.states = Some(states);
        (_, f) = fit_once(p)?;
    }
    for (k, &d) in shifts.iter().enumerate().skip(p.fit_runs) {
        let (a, b) = p.bounds[k];
        f.prediction[a..b].iter_mut().for_each(|v| *v += d);
    }
    p.shifts = shifts;
    Ok(f)
}

/// Run `k`'s state λ and torque zero from its rest: λ puts the model's mean over the rest on
/// the measured mean torque there, within [−1, 1]; what is left is the zero. `hyst`: the index
/// of the hysteresis effect in the fit (none: λ = 0, the whole difference is the zero).
fn at_rest(
    p: &Problem,
    s: &Signals,
    f: &Fitted,
    hyst: Option<usize>,
    k: usize,
    (start, end): (usize, usize),
) -> (f64, f64) {
    let a = p.bounds[k].0;
    let rows = a + start..a + end;
    let tau = mean(&p.tau[rows.clone()]);
    let predicted = mean(&f.prediction[rows]);
    let Some(h) = hyst else {
        return (0.0, tau - predicted);
    };
    let weights = f.part(h + 1);
    let xs = &s.xs[a..a + end];
    // The stops' mean contribution over the rest from state λ (non-decreasing in λ: each
    // stop's output is, and its weight is ≥ 0).
    let loop_at = |lam: f64| -> f64 {
        s.widths
            .iter()
            .zip(weights)
            .map(|(&r, &w)| w * mean(&stop_operator_from(xs, r, lam * r)[start..]))
            .sum()
    };
    let now = p.states.as_ref().map_or(0.0, |v| v[k]);
    let target = tau - (predicted - loop_at(now));
    let (lo, hi) = (loop_at(-1.0), loop_at(1.0));
    if target <= lo {
        return (-1.0, target - lo);
    }
    if target >= hi {
        return (1.0, target - hi);
    }
    let (mut l, mut u) = (-1.0, 1.0);
    for _ in 0..40 {
        let m = 0.5 * (l + u);
        if loop_at(m) < target {
            l = m;
        } else {
            u = m;
        }
    }
    (0.5 * (l + u), 0.0)
}

#[cfg(test)]
mod tests {
    use super::super::{Holdout, Options, identify};
    use super::*;

    /// A torsion spring with a loop: k·x plus three stop operators (written here, not the
    /// library's), each started at `lam` of its half-width. 200 Hz, 5 s at rest at `x_rest`,
    /// then a decaying two-tone swing about it; a little deterministic noise on the torque.
    fn spring(name: &str, lam: f64, x_rest: f64, phase: f64) -> Run {
        let (k, stops) = (20.0, [(0.004, 0.6), (0.01, 0.8), (0.02, 0.5)]);
        let t: Vec<f64> = (0..6000).map(|i| i as f64 / 200.0).collect();
        let phi: Vec<f64> = t
            .iter()
            .map(|&t| {
                let m = (t - 5.0).max(0.0);
                let a = 0.06 * (1.0 - (-m).exp()) * (-m / 40.0).exp();
                x_rest + a * ((1.1 * m + phase).sin() + 0.4 * (2.9 * m).sin())
            })
            .collect();
        let mut s: Vec<f64> = stops.iter().map(|(r, _)| lam * r).collect();
        let mut prev = phi[0];
        let tau = phi
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let mut h = 0.0;
                for (sj, (r, w)) in s.iter_mut().zip(stops) {
                    *sj = (*sj + x - prev).clamp(-r, r);
                    h += w * *sj;
                }
                prev = x;
                k * x + h + 1e-3 * ((i * 7919) % 13) as f64 / 13.0
            })
            .collect();
        Run {
            name: name.into(),
            t,
            tau,
            phi: Some(phi),
            ..Run::default()
        }
    }

    fn linear(loop_states: bool) -> Options {
        Options {
            model: Declared::Linear,
            loop_states,
            ..Options::default()
        }
    }

    #[test]
    fn a_rest_the_loop_holds_loaded_is_read_as_its_state_not_taken_for_a_zero() {
        // The held-out test rests where friction left it, loaded by its stops (λ = +0.6), at
        // an angle of the same encoder frame.
        let fit = [spring("fit", 0.0, 0.0, 0.0)];
        let held = [spring("held", 0.6, 0.004, 1.0)];
        let by_state = identify(&fit, Holdout::Runs(&held), &linear(true), &mut |_, _| {}).unwrap();
        let by_rest = identify(&fit, Holdout::Runs(&held), &linear(false), &mut |_, _| {}).unwrap();
        assert!(
            by_state
                .effects
                .iter()
                .any(|e| e.effect == Effect::Hysteresis)
        );
        let t = &by_state.tare[1];
        let lam = t.loop_state.expect("read as a state");
        assert!((lam - 0.6).abs() < 0.1, "state {lam}, made 0.6");
        assert!(t.torque_zero.abs() < 5e-3, "torque zero {}", t.torque_zero);
        // One frame: both files' deflection zero is the fit file's rest.
        assert_eq!(t.deflection_zero, by_state.tare[0].deflection_zero);
        // The rest rule takes the stops' load (0.6·Σ w·r = 0.0126 N·m) for a zero.
        assert!(by_rest.tare[1].loop_state.is_none());
        assert!(
            by_state.after.rmse < 0.5 * by_rest.after.rmse,
            "held-out RMSE {} by state, {} by rest",
            by_state.after.rmse,
            by_rest.after.rmse
        );
    }

    fn run(phi: Vec<f64>, tau: Vec<f64>) -> Run {
        Run {
            name: "r".into(),
            t: (0..phi.len()).map(|i| i as f64 * 0.01).collect(),
            tau,
            phi: Some(phi),
            ..Run::default()
        }
    }

    /// A test zeroed at its start (first reading 0): a swing of ±0.1 rad through a 10 N·m/rad
    /// spring, then at rest at `end_x` reading `end_tau`.
    fn swing(end_x: f64, end_tau: f64) -> Run {
        let mut phi: Vec<f64> = (0..100).map(|i| 0.1 * (i as f64 * 0.1).sin()).collect();
        let mut tau: Vec<f64> = phi.iter().map(|x| 10.0 * x).collect();
        phi.extend([end_x; 50]);
        tau.extend([end_tau; 50]);
        run(phi, tau)
    }

    #[test]
    fn an_encoder_zeroed_at_the_start_is_read_from_where_the_fit_run_ended_unloaded() {
        // Zeroed (first reading 0), a swing of ±0.1 rad, ending at 0.01 rad and 0.02 N·m of a
        // 1 N·m peak: unloaded at 0.01 − 0.02/10 = 0.008 rad through k = 10 N·m/rad.
        let fit = swing(0.01, 0.02);
        let zeroed = swing(0.0, 0.0);
        let carried: Run = shifted(&zeroed, 0.03);
        assert!(zeroed_at_start(&fit) && zeroed_at_start(&zeroed));
        assert!(!zeroed_at_start(&carried));
        let (f, c) = continuity(std::slice::from_ref(&fit), &[zeroed.clone(), carried], 10.0);
        assert_eq!(f, vec![None], "the first fit run is the frame");
        assert!((c[0].unwrap() - 0.008).abs() < 1e-12, "{c:?}");
        assert_eq!(c[1], None, "a frame carried over is kept");
        // A fit run that ends loaded (0.5 N·m of 1) says nothing of where the spring rests.
        let loaded = swing(0.05, 0.5);
        assert_eq!(continuity(&[loaded], &[zeroed], 10.0).1, vec![None]);
    }

    #[test]
    fn fit_runs_each_zeroed_at_the_start_chain_their_frames_and_the_held_out_run_follows_the_last()
    {
        // Three tests of one protocol, each zeroed where the one before left the spring: the
        // first ends unloaded at 0.008 rad (0.01 − 0.02/10), the second at 0.004 rad in its own
        // readings (0.005 − 0.01/10). In the first's frame the second starts at 0.008 and the
        // held-out third at 0.008 + 0.004, not at 0.004 (where the second ends in its own).
        let (first, second, third) = (swing(0.01, 0.02), swing(0.005, 0.01), swing(0.0, 0.0));
        let (f, h) = continuity(
            &[first.clone(), second.clone()],
            std::slice::from_ref(&third),
            10.0,
        );
        assert!(
            f[0].is_none() && (f[1].unwrap() - 0.008).abs() < 1e-12,
            "{f:?}"
        );
        assert!((h[0].unwrap() - 0.012).abs() < 1e-12, "{h:?}");
        // A second fit run whose frame was carried over (not zeroed) is read as measured, and
        // the held-out run, zeroed after it, then follows where it ends in its own readings.
        let carried = shifted(&second, 0.03);
        let (f, h) = continuity(&[first, carried], &[third], 10.0);
        assert_eq!(f, vec![None, None]);
        assert_eq!(
            h,
            vec![None],
            "a fit run not zeroed at its start gives no chain"
        );
    }
}
