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
//! Two more readings are each held-out run's own, for any declared model ([`settle`]): whether
//! a run read from the fit run's end is read so or as measured (whichever predicts it better),
//! and the instant at which it takes each jump the fit found (or none): a test slips or steps
//! when it does. Under this rule a third: whether the torque zero its rest reads is taken, or
//! none (whichever predicts it better): a rest can hold a load the model has no state for.
//!
//! The rule applies to the linear spring (the springs' model) when every run starts at rest;
//! the fit runs' states are refined with the fit (three rounds), the held-out runs' are set
//! from the final coefficients: the held-out data chooses a state as a tare chooses zeros, never
//! a coefficient.

use super::effects::{Effect, Shaped};
use super::model::{Fitted, Signals, Transform, fit};
use super::rows::{Problem, Tare, resolution};
use super::select::{HELDOUT_LR, Rows, confirmed_held_out};
use super::signals::stop_operator_from;
use super::stats::{effective_samples, mean, median, span};
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

/// The fit of `trial` on the fit rows with each held-out run's states read from that run:
/// its loop's state and torque zero from its rest ([`settle_rests`]), and the instant of
/// each jump in `trial` ([`read_jumps`]). Sets `p.states`, `p.shifts` and `p.jumps`.
pub(crate) fn settle(
    p: &mut Problem,
    trial: &[Shaped],
    rows: &Rows,
) -> Result<Fitted, IdentifyError> {
    let (fixed, read) = settle_both(p, trial, rows)?;
    Ok(read.unwrap_or(fixed))
}

/// As [`settle`], keeping the fit from before the held-out runs read their own jump instants
/// (every jump at its fitted instant in every run): `(fixed, read)`, `read` `None` where no
/// instant moved (it is `fixed`). `p` is left as for the last of them.
pub(crate) fn settle_both(
    p: &mut Problem,
    trial: &[Shaped],
    rows: &Rows,
) -> Result<(Fitted, Option<Fitted>), IdentifyError> {
    p.jumps.clear();
    p.frames.clear();
    p.at_rest.clear();
    let mut f = settle_rests(p, trial, rows)?;
    if choose_frames(p, trial, rows, &f)? {
        f = settle_rests(p, trial, rows)?;
    }
    let read = if read_jumps(p, trial, rows)? {
        Some(settle_rests(p, trial, rows)?)
    } else {
        None
    };
    Ok((f, read))
}

/// Each held-out run's encoder frame: the one it was given, or one of two others, whichever
/// predicts the run best with the fit's coefficients (`f`: the prediction in the given
/// frames); sets `p.frames`, and says whether any run is read otherwise than given. One
/// reading per run, chosen as a tare's zeros are, never a coefficient. The others:
/// - *as measured* (`p.other_frames`), where its frame was carried from the fit runs. The
///   carried frame is a reading of the test protocol (module docs) that a run zeroed at its
///   start may not share: a generator or a lab that zeroes every test at the same unloaded
///   point puts a gap's centre at zero in every run, and read from where the fit run ended
///   (one edge of the gap) the run was shifted by up to the gap's half-width;
/// - *its rest where the fit run's is* (`p.rest_frames`), in the fit run's state at rest:
///   its zero moved between the tests (a spring re-seated in its fixture, an encoder that
///   slipped), and the rest is unloaded as the fit run's was — the rest rule's reading. A
///   zero that moved by less than the loop holds was read as a load: the stops started
///   loaded, were swept clear within a swing, and left the moved zero as a bias for the rest
///   of the run (measured spring 5 at 4 N·m fitted on its second test: its first, zeroed at
///   its start, was read from where the second ended; read from its own rest, a held-out
///   bias of 0.124 N·m went to 0.023). It replaces the reading before it only where the
///   held-out check would confirm an effect (its likelihood ratio on the run's effective
///   samples over χ²₁'s 99 % point): chosen on a hair, it changes what the held-out check
///   keeps (measured spring 4 at 1.5 N·m fitted on its second test lost a stiffness step that
///   gains 0.21 N·m held out).
///
/// At rest the readings fit alike; the motion tells them apart.
fn choose_frames(
    p: &mut Problem,
    trial: &[Shaped],
    rows: &Rows,
    f: &Fitted,
) -> Result<bool, IdentifyError> {
    // (frames, whether they are the rests': those must beat the reading before them by more
    // than noise explains)
    let alternatives: Vec<(Vec<f64>, bool)> = [(&p.other_frames, false), (&p.rest_frames, true)]
        .into_iter()
        .filter(|(d, _)| d.iter().any(|d| *d != 0.0))
        .map(|(d, at_rest)| (d.clone(), at_rest))
        .collect();
    if alternatives.is_empty() {
        return Ok(false);
    }
    // The given frames' states and zeros, which `f` was predicted with.
    let given = (p.states.clone(), p.shifts.clone(), p.untaken.clone());
    let residual = |p: &Problem, h: &Fitted, k: usize| -> Vec<f64> {
        h.residual_on(&p.tau, within(&rows.held, p.bounds[k]))
    };
    let sse = |p: &Problem, h: &Fitted, k: usize| -> f64 {
        residual(p, h, k).iter().map(|e| e * e).sum()
    };
    // Per run: the best squared error so far, the frame that gave it (0: the given one) and
    // whether it is the rest's.
    let mut best: Vec<(f64, f64, bool)> = (0..p.runs.len())
        .map(|k| (if k < p.fit_runs { 0.0 } else { sse(p, f, k) }, 0.0, false))
        .collect();
    for (frames, at_rest) in alternatives {
        p.at_rest = frames.iter().map(|d| at_rest && *d != 0.0).collect();
        p.frames = frames;
        let g = settle_rests(p, trial, rows)?;
        for (k, b) in best.iter_mut().enumerate().skip(p.fit_runs) {
            let d = p.frame(k);
            if d == 0.0 {
                continue;
            }
            let r = residual(p, &g, k);
            let e: f64 = r.iter().map(|e| e * e).sum();
            let better = if at_rest {
                confirmed_held_out(b.0, e, effective_samples(&[&r]), HELDOUT_LR)
            } else {
                e < b.0
            };
            if better {
                *b = (e, d, at_rest);
            }
        }
    }
    p.frames = best.iter().map(|b| b.1).collect();
    p.at_rest = best.iter().map(|b| b.2).collect();
    let any = p.frames.iter().any(|d| *d != 0.0);
    if !any {
        p.frames.clear();
        p.at_rest.clear();
        (p.states, p.shifts, p.untaken) = given;
    }
    Ok(any)
}

/// Each held-out run's own instant for each jump in `trial` (an offset's step, an encoder
/// slip, a stiffness step), set in `p.jumps`; whether any moved. A jump is an event of a run,
/// not a property of the spring: a test slips or steps when it does. So, as a tare reads a
/// run's zeros, each held-out run's instant is read from its own samples, with the size fitted
/// on the fit runs: the instant (from 2 % to 98 % of the run, as the fit side searches) that
/// lowers the run's squared error most, or none where no instant lowers it. Searching one
/// instant for a step of fixed size d gains more than x·σ² on pure noise with probability
/// about e^(−x/2) (the supremum of a random walk with drift −d/2), so the held-out check asks
/// such a jump for 2·ln 100 = 9.21 rather than χ²₁'s 6.63 — or for 6.63 with the jump at its
/// fitted instant in every run (a test protocol that jumps alike in every run): 2 % at most
/// for the two, after the jump has passed the fit rows' selection.
///
/// The error with the jump at t is the error without it less Σ_{s≥t} (2·e₀·Δ − Δ²), e₀ the
/// residual without the jump and Δ what the jump adds (the prediction with it throughout the
/// run less without it): exact for a torque or stiffness step and for a slip through a model
/// without memory; the prediction is then made again at the chosen instant. The jumps are read
/// one after another, each with those before it placed.
fn read_jumps(p: &mut Problem, trial: &[Shaped], rows: &Rows) -> Result<bool, IdentifyError> {
    let held: Vec<usize> = (p.fit_runs..p.runs.len()).collect();
    let jumps: Vec<f64> = trial
        .iter()
        .filter(|c| c.is_jump())
        .map(|c| c.shape)
        .collect();
    if held.is_empty() || jumps.is_empty() {
        return Ok(false);
    }
    let tr = Transform::of(trial);
    p.jumps = vec![Vec::new(); p.runs.len()];
    let mut moved = false;
    for &tj in &jumps {
        // The held-out runs' prediction with this jump at `at` (the fit rows, and so the
        // coefficients, are unchanged).
        let with_jump_at = |p: &mut Problem, at: f64| -> Result<Vec<f64>, IdentifyError> {
            for &k in &held {
                place(&mut p.jumps[k], tj, at);
            }
            let f = fit(&p.signals(tr), trial, &p.tau, &rows.fit).ok_or(IdentifyError::Solve)?;
            Ok(f.prediction)
        };
        let without = with_jump_at(p, f64::INFINITY)?;
        let throughout = with_jump_at(p, f64::NEG_INFINITY)?;
        for &k in &held {
            let (a, b) = p.bounds[k];
            let zero = p.shifts.get(k).copied().unwrap_or(0.0);
            let run = &p.runs[k];
            let (t0, duration) = (run.t[0], run.t[run.t.len() - 1] - run.t[0]);
            // Σ_{s≥t} (2·e₀·Δ − Δ²) from the run's end back, the best instant kept.
            let (mut gain, mut best) = (0.0, (0.0, f64::INFINITY));
            for &i in within(&rows.held, (a, b)).iter().rev() {
                let e0 = p.tau[i] - without[i] - zero;
                let d = throughout[i] - without[i];
                gain += 2.0 * e0 * d - d * d;
                let t = run.t[i - a] - t0;
                let inside = t > 0.02 * duration && t < 0.98 * duration;
                if inside && gain > best.0 {
                    best = (gain, t);
                }
            }
            place(&mut p.jumps[k], tj, best.1);
            moved |= best.1 != tj;
        }
    }
    Ok(moved)
}

/// The rows (in order) that lie in the run of rows `a..b`.
fn within(rows: &[usize], (a, b): (usize, usize)) -> &[usize] {
    &rows[rows.partition_point(|&i| i < a)..rows.partition_point(|&i| i < b)]
}

/// Sets the run's own instant `at` for the jump fitted at `tj`.
fn place(run: &mut Vec<(f64, f64)>, tj: f64, at: f64) {
    match run.iter_mut().find(|(fitted, _)| *fitted == tj) {
        Some(j) => j.1 = at,
        None => run.push((tj, at)),
    }
}

/// The fit of `trial` on the fit rows with each run's state set from its rest (module docs),
/// its prediction on held-out rows carrying their torque zeros. Sets `p.states`, `p.shifts`
/// and `p.untaken`. Without rests to read (`p.loop_rests` unset), the plain fit.
///
/// A held-out run's zero is what its rest reads, or none, whichever predicts the run better
/// with the fit's coefficients (one bit per run, as its frame: [`choose_frames`]). A rest can
/// read a load the model cannot hold: a loop not named (no state to put it in), or a zero that
/// moves again within the test — the measured spring 1 at 2 N·m, its second test fitted, the
/// first held out: through the line, that test's rest lies 0.45 N·m off the fit test's, yet
/// it passes the same angle later 0.36 N·m lower on its own loading branch, and at its holds
/// reads within 0.11 N·m of the fit test. Taken for a zero, that rest made the held-out error
/// 0.31 N·m against 0.27 with none.
fn settle_rests(p: &mut Problem, trial: &[Shaped], rows: &Rows) -> Result<Fitted, IdentifyError> {
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
                states[k] = at_rest(p, &s, &f, Some(h), k, *rest, None).0;
            }
            p.states = Some(states.clone());
            (s, f) = fit_once(p)?;
        }
    }
    // What the model misses at the fit runs' rests (nothing, where the loop holds them) is
    // the protocol's, not a zero: each held-out run's torque zero is its own less that.
    let missed = (0..p.fit_runs)
        .map(|k| at_rest(p, &s, &f, hyst, k, rests[k], None).1)
        .sum::<f64>()
        / p.fit_runs.max(1) as f64;
    let mut shifts = vec![0.0; n];
    for k in p.fit_runs..n {
        // A run read with its rest where the first fit run's is rests as that run did, in its
        // state: what differs at rest is a torque zero (the rest rule, within the loop).
        let state = p
            .at_rest
            .get(k)
            .copied()
            .unwrap_or(false)
            .then(|| states[0]);
        (states[k], shifts[k]) = at_rest(p, &s, &f, hyst, k, rests[k], state);
        shifts[k] -= missed;
    }
    if hyst.is_some() {
        // The fit rows' columns are unchanged (each run's operators restart): the same
        // coefficients, the held-out rows predicted from their own states.
        p.states = Some(states);
        (_, f) = fit_once(p)?;
    }
    // Each held-out run's zero read at rest, or none: whichever predicts the run better
    // (above), then carried by its prediction.
    let mut untaken = vec![0.0; n];
    for k in p.fit_runs..n {
        let d = shifts[k];
        let e = f.residual_on(&p.tau, within(&rows.held, p.bounds[k]));
        let with: f64 = e.iter().map(|e| (e - d) * (e - d)).sum();
        let without: f64 = e.iter().map(|e| e * e).sum();
        if d != 0.0 && without < with {
            (untaken[k], shifts[k]) = (d, 0.0);
        }
        let (a, b) = p.bounds[k];
        f.prediction[a..b].iter_mut().for_each(|v| *v += shifts[k]);
    }
    p.shifts = shifts;
    p.untaken = untaken;
    Ok(f)
}

/// Run `k`'s state λ and torque zero from its rest: λ puts the model's mean over the rest on
/// the measured mean torque there, within [−1, 1]; what is left is the zero. `hyst`: the index
/// of the hysteresis effect in the fit (none: λ = 0, the whole difference is the zero).
/// `state`: λ given (the zero is then what it leaves).
fn at_rest(
    p: &Problem,
    s: &Signals,
    f: &Fitted,
    hyst: Option<usize>,
    k: usize,
    (start, end): (usize, usize),
    state: Option<f64>,
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
    if let Some(lam) = state {
        return (lam, target - loop_at(lam));
    }
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
    use super::super::signals::uniforms;
    use super::super::{Holdout, Options, identify};
    use super::*;

    /// A torsion spring with a loop: k·x plus three stop operators (written here, not the
    /// library's), each started at `lam` of its half-width. 200 Hz, 5 s at rest at `x_rest`,
    /// then a decaying two-tone swing about it; a little deterministic noise on the torque.
    fn spring(name: &str, lam: f64, x_rest: f64, phase: f64) -> Run {
        let stops = [(0.004, 0.6), (0.01, 0.8), (0.02, 0.5)];
        spring_with(name, lam, x_rest, phase, &stops)
    }

    /// [`spring`] with its stops given (half-width, weight): none is a spring without a loop.
    fn spring_with(name: &str, lam: f64, x_rest: f64, phase: f64, stops: &[(f64, f64)]) -> Run {
        let k = 20.0;
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
                for (sj, &(r, w)) in s.iter_mut().zip(stops) {
                    *sj = (*sj + x - prev).clamp(-r, r);
                    h += w * *sj;
                }
                prev = x;
                k * x + h + 1e-3 * ((i * 7919) % 13) as f64 / 13.0
            })
            .collect();
        named(name, t, tau, phi)
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

    #[test]
    fn a_spring_without_a_loop_has_no_state_of_a_loop_read_at_its_rests() {
        // k·x alone, both tests at rest at the same angle: no loop is named, so neither rest is
        // read as a loop's state (the rule reads them, every state 0; the report must not say
        // "a state of the loop" where the model has none).
        let fit = [spring_with("fit", 0.0, 0.0, 0.0, &[])];
        let held = [spring_with("held", 0.0, 0.0, 1.0, &[])];
        let res = identify(&fit, Holdout::Runs(&held), &linear(true), &mut |_, _| {}).unwrap();
        assert!(res.effects.is_empty(), "{:?}", res.effects);
        assert_eq!(res.tare.len(), 2);
        assert!(
            res.tare.iter().all(|t| t.loop_state.is_none()),
            "{:?}",
            res.tare
        );
        // With the loop the same rests are read as its states (the test above).
        let looped = identify(
            &[spring("fit", 0.0, 0.0, 0.0)],
            Holdout::Runs(&[spring("held", 0.0, 0.0, 1.0)]),
            &linear(true),
            &mut |_, _| {},
        )
        .unwrap();
        assert!(looped.tare.iter().all(|t| t.loop_state.is_some()));
    }

    #[test]
    fn a_held_out_test_whose_zero_moved_is_read_with_its_rest_where_the_fit_tests_rest_is() {
        // The same spring, unloaded at rest in both tests (λ = 0), but between them its
        // encoder's zero moved by 0.5 mrad (the spring re-seated in its fixture): the held-out
        // test reads 0.5 mrad more everywhere. Read in the fit test's frame, its rest reads
        // k·0.5 mrad = 0.01 N·m through the spring where it measures none, within what the
        // loop can hold (±0.0204 N·m): a load the stops would hold (λ ≈ −0.5), forgotten as
        // soon as the swing sweeps them, leaving the 0.01 N·m for the rest of the test. With
        // its rest where the fit test's is, the run is the fit test's spring again.
        let fit = [spring("fit", 0.0, 0.0, 0.0)];
        let held = shifted(&spring("held", 0.0, 0.0, 1.0), 0.0005);
        let res = identify(
            &fit,
            Holdout::Runs(std::slice::from_ref(&held)),
            &linear(true),
            &mut |_, _| {},
        )
        .unwrap();
        let t = &res.tare[1];
        assert!(t.frame_at_rest, "{t:?}");
        assert!(
            (t.deflection_zero - 0.0005).abs() < 1e-5,
            "its rest, 0.5 mrad: {}",
            t.deflection_zero
        );
        assert!(
            res.effects.iter().any(|e| e.effect == Effect::Hysteresis),
            "{:?}",
            res.effects
        );
        // The torque's noise is 0.29 mN·m rms (uniform over 1 mN·m); the moved zero 10 mN·m.
        // (Read in the fit test's frame, the rest's 10 mN·m was a torque zero, the stops
        // started unloaded, and the loop was named viscous friction.)
        assert!(
            res.after.rmse < 1e-3,
            "held-out RMSE {} N·m",
            res.after.rmse
        );
    }

    /// A run of deflection and torque samples at the times `t`.
    fn named(name: &str, t: Vec<f64>, tau: Vec<f64>, phi: Vec<f64>) -> Run {
        Run {
            name: name.into(),
            t,
            tau,
            phi: Some(phi),
            ..Run::default()
        }
    }

    fn run(phi: Vec<f64>, tau: Vec<f64>) -> Run {
        let t = (0..phi.len()).map(|i| i as f64 * 0.01).collect();
        named("r", t, tau, phi)
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
    /// A linear spring (20 N·m/rad) seen through a gap of half-width `gap` in series, 200 Hz:
    /// 4 s at rest with the encoder zeroed at the gap's centre, then a two-tone swing of
    /// ±0.08 rad about it for 30 s more, ending at rest at `end_x`; a torque step of `step` N·m
    /// at `step_at` s (none: NaN); uniform noise of ±[`NOISE`] (0.4 % of the peak torque rms).
    fn geared(name: &str, gap: f64, phase: f64, end_x: f64, step: f64, step_at: f64) -> Run {
        let secs = 30.0;
        let mut uniform = uniforms((phase * 1e6) as u64);
        let n = ((4.0 + secs + 2.0) * 200.0) as usize;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 200.0).collect();
        let phi: Vec<f64> = t
            .iter()
            .map(|&t| {
                let m = t - 4.0;
                if m <= 0.0 {
                    0.0
                } else if m >= secs {
                    end_x
                } else {
                    let env = (std::f64::consts::PI * m / secs).sin();
                    let swing =
                        0.08 * env * (0.7 * (1.3 * m + phase).sin() + 0.3 * (3.7 * m).sin());
                    swing + end_x * (m / secs).powi(4)
                }
            })
            .collect();
        let tau = phi
            .iter()
            .zip(&t)
            .map(|(&x, &t)| {
                let inside = if x.abs() <= gap {
                    0.0
                } else {
                    x - gap * x.signum()
                };
                let jump = if t >= step_at { step } else { 0.0 };
                20.0 * inside + jump + NOISE * (2.0 * uniform() - 1.0)
            })
            .collect();
        named(name, t, tau, phi)
    }

    /// Half the range of the uniform torque noise of [`geared`] [N·m] (rms 5.8 mN·m).
    const NOISE: f64 = 0.01;

    #[test]
    fn a_held_out_runs_torque_step_is_read_at_its_own_instant_and_a_run_without_one_reads_none() {
        // The fit run steps 0.2 N·m at 15 s; one held-out run steps at 24 s, the other not.
        let fit = [geared("fit", 0.0, 0.0, 0.0, 0.2, 15.0)];
        let held = [
            geared("later", 0.0, 1.0, 0.0, 0.2, 24.0),
            geared("none", 0.0, 2.0, 0.0, 0.0, f64::NAN),
        ];
        let r = identify(&fit, Holdout::Runs(&held), &linear(true), &mut |_, _| {}).unwrap();
        let names: Vec<_> = r.effects.iter().map(|e| e.effect).collect();
        assert_eq!(names, vec![Effect::Offset], "{:?}", r.effects);
        let at = &r.effects[0].held_out_at_s;
        assert_eq!(at.len(), 2, "{at:?}");
        let later = at[0].1.expect("the later run's step read");
        assert!(
            (later - 24.0).abs() < 0.02,
            "read at {later} s, made at 24 s"
        );
        assert_eq!(at[1], ("none".to_string(), None));
        // Read at the fitted 15 s instead, both held-out runs would carry a 0.2 N·m error
        // for 9 s or 30 s; read, only the noise (rms NOISE/√3) is left.
        let floor = NOISE / 3f64.sqrt();
        assert!(
            r.after.rmse < 1.05 * floor && r.before.rmse > 10.0 * floor,
            "held-out RMSE {} → {}, the noise's {floor}",
            r.before.rmse,
            r.after.rmse
        );
    }

    #[test]
    fn a_held_out_rest_that_reads_a_load_its_motion_lacks_is_not_taken_for_a_zero() {
        // A linear spring (no loop: no state to hold a load in). Both held-out runs rest
        // reading 0.15 N·m; one keeps that offset throughout (its zero moved), the other
        // reads on the fit run's line once it moves (the rest was loaded, or the sensor
        // settled).
        let fit = [geared("fit", 0.0, 0.0, 0.0, 0.0, f64::NAN)];
        let mut moved = geared("moved", 0.0, 1.0, 0.0, 0.0, f64::NAN);
        moved.tau.iter_mut().for_each(|v| *v += 0.15);
        let mut loaded = geared("loaded", 0.0, 2.0, 0.0, 0.0, f64::NAN);
        for (v, t) in loaded.tau.iter_mut().zip(&loaded.t) {
            *v += if *t < 4.0 { 0.15 } else { 0.0 };
        }
        let floor = NOISE / 3f64.sqrt();
        let r = identify(&fit, Holdout::Runs(&[moved]), &linear(true), &mut |_, _| {}).unwrap();
        let t = &r.tare[1];
        assert!(t.zero_not_taken.is_none(), "{t:?}");
        assert!(
            (t.torque_zero - 0.15).abs() < 2e-3,
            "zero {}",
            t.torque_zero
        );
        assert!(
            r.after.rmse < 1.05 * floor,
            "held-out RMSE {}",
            r.after.rmse
        );
        let r = identify(
            &fit,
            Holdout::Runs(&[loaded]),
            &linear(true),
            &mut |_, _| {},
        )
        .unwrap();
        let t = &r.tare[1];
        let untaken = t.zero_not_taken.expect("the rest's zero not taken");
        assert!((untaken - 0.15).abs() < 2e-3, "untaken {untaken}");
        assert_eq!(t.torque_zero, 0.0);
        // Taken, the zero would put 0.15 N·m on the 32 s of 36 that move (0.141 N·m rms);
        // not taken, it is on the 4 s of rest (0.05 N·m rms), as before anything was added.
        let rest_only = 0.15 * (4.0f64 / 36.0).sqrt();
        assert!(
            r.after.rmse < 1.05 * rest_only.hypot(floor),
            "held-out RMSE {} against {rest_only} at rest",
            r.after.rmse
        );
        assert!(r.after.rmse <= r.before.rmse * (1.0 + 1e-9));
    }

    #[test]
    fn a_held_out_run_zeroed_where_the_fit_run_did_not_leave_the_spring_is_read_as_measured() {
        // A gap of ±10 mrad; every run's encoder zeroed at its centre. The fit run ends at rest
        // at +8 mrad, inside the gap and unloaded: read from there, the held-out run would be
        // 8 mrad off, its gap no longer where the fit run found it.
        let fit = [geared("fit", 0.01, 0.0, 0.008, 0.0, f64::NAN)];
        let held = [geared("held", 0.01, 1.0, 0.0, 0.0, f64::NAN)];
        let r = identify(&fit, Holdout::Runs(&held), &linear(true), &mut |_, _| {}).unwrap();
        let names: Vec<_> = r.effects.iter().map(|e| e.effect).collect();
        assert_eq!(names, vec![Effect::Backlash], "{:?}", r.effects);
        let t = &r.tare[1];
        assert_eq!(
            t.read_after, None,
            "read as measured, not from the fit run's end"
        );
        assert!(
            t.deflection_zero.abs() < 1e-3,
            "deflection zero {}",
            t.deflection_zero
        );
        assert!(
            r.after.rmse < 0.1 * r.before.rmse,
            "held-out RMSE {} → {}",
            r.before.rmse,
            r.after.rmse
        );
    }
}
