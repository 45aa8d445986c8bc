//! The declared loop's envelope where the joint's geometry is not given: straight lines (paper
//! B), or lines that soften toward the ends as a lever swung far does ([`Envelope::Softening`]).
//!
//! This is a choice of the declared model, not an effect: a lever's spring torque is not
//! straight in its deflection (MODEL.md §1), and straight lines fitted to it leave a residual
//! that bends with the deflection — a floor under which a real effect of the size of the noise
//! cannot be told (paper B's lever at 2–16 mm, ±0.02–0.26 rad: the floors 3–10× the noise
//! toward the pivot's ends). With the lever's geometry (`--config`) the lines follow the lever
//! itself, and nothing here runs.
//!
//! The bend is chosen as an effect's shape is — on the validation rows, the loop fitted on the
//! training rows alone for each shape — and kept only where it lowers the validation error by
//! `min_gain` and the held-out error by more than noise explains (the held-out check of
//! [`super::select::with_heldout_veto`]).

use super::effects::Shaped;
use super::model::{Fitted, refit_restoring};
use super::rows::Problem;
use super::select::{Rows, golden_section, held_out_prefers, validation_error};
use super::states::settle;
use super::{IdentifyError, Options};
use crate::hysteresis::Envelope;

/// How much softer than at rest the joint is at the fit rows' largest deflection, for the
/// shapes tried: a lever at 2–16 mm swung over 8–25 % of its spring's travel is 1–42 % softer.
const SOFTER_AT_EDGE: [f64; 8] = [0.02, 0.04, 0.07, 0.1, 0.15, 0.2, 0.3, 0.45];

/// The bend kept.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Softening {
    /// c of s(φ) = φ/√(1 + c·φ²) [1/rad²].
    pub c: f64,
    /// The fit rows' largest deflection from rest [rad].
    pub x_max: f64,
    /// How much softer than at rest the loop's centre line is at ±`x_max` (0.1: 10 %).
    pub softer: f64,
    /// Relative drop of the validation RMSE against straight lines.
    pub validation_gain: f64,
    /// Held-out RMSE with straight lines and with the bend, beside the effects found with
    /// straight lines [N·m]. For a bend kept beside an effect the held-out check refused
    /// ([`soften_beside`]), `validation_gain` and the second RMSE are of the bend and that
    /// effect together.
    pub held_out: (f64, f64),
}

/// c such that the slope at `x` is `1 − softer` of the slope at rest.
fn c_for(softer: f64, x: f64) -> f64 {
    ((1.0 - softer).powf(-2.0 / 3.0) - 1.0) / (x * x)
}

/// `p` with envelope `env`, its loop refitted on `rows` beside the `chosen` effects (twice:
/// the effects' share is taken beside the loop it replaces, then beside the new one).
fn with_envelope(
    p: &Problem,
    env: Envelope,
    chosen: &[Shaped],
    rows: &[usize],
) -> Result<Problem, IdentifyError> {
    let mut q = p.clone();
    q.envelope = env;
    for _ in 0..2 {
        q.restoring = Some(refit_restoring(&q, chosen, rows)?);
    }
    Ok(q)
}

/// Where `p`'s declared loop has straight lines: the bend that pays beside the `chosen`
/// effects (`p.restoring` their loop, `after` their fit), or `None` where straight lines do
/// as well. Looked for after the effects, not before: before them a bend takes up what it can
/// of an effect (a torque offset on a lever at ±0.15 rad bent the lines 47 % where the lever
/// is 13 %, and a stop was named beside the offset).
///
/// Where no bend pays beside the `chosen` alone, it is tried beside each of the `unconfirmed`
/// too — effects the selection chose on the fit run but whose held-out error did not drop by
/// more than noise explains. A gap in series with a lever's spring makes the joint softer at
/// rest, the lever makes it softer at its ends: on straight lines the two cancel into one
/// secant, so neither pays alone, and a gap fitted against straight lines extrapolates to a
/// wider held-out swing worse than no gap (the fifth generator's backlash seed 4: ramps to
/// ±0.20 rad fitted, a chirp to ±0.24 rad held out, the gap's held-out RSS 14 % up). The
/// bend and the effect together must lower what was found (straight lines beside `chosen`:
/// `after`) by `min_gain` on the validation rows and by more than noise explains held out.
/// The bend is a shape of the declared model either way: the identification then runs again
/// with it and chooses every effect afresh, the unconfirmed one held to every rule as before.
pub(crate) fn soften_beside(
    p: &Problem,
    chosen: &[Shaped],
    rows: &Rows,
    opts: &Options,
    after: &Fitted,
    unconfirmed: &[Shaped],
) -> Result<Option<Softening>, IdentifyError> {
    let (lo, hi) = p.range_of_fit_angle();
    let x_max = lo.abs().max(hi.abs());
    if !(x_max.is_finite() && x_max > 0.0) || p.envelope != Envelope::Linear {
        return Ok(None);
    }
    // Straight lines beside what was found: what every bend is judged against.
    let straight = validation_error(
        &with_envelope(p, Envelope::Linear, chosen, &rows.train)?,
        chosen,
        rows,
    )?;
    if let Some(bend) = bend_beside(p, chosen, rows, opts, (after, straight), x_max)? {
        return Ok(Some(bend));
    }
    for c in unconfirmed {
        let beside: Vec<Shaped> = chosen.iter().copied().chain([*c]).collect();
        if let Some(bend) = bend_beside(p, &beside, rows, opts, (after, straight), x_max)? {
            return Ok(Some(bend));
        }
    }
    Ok(None)
}

/// The bend that pays beside the effects `beside`: the best of the grid and its refinement on
/// the validation rows, which must lower the validation error of what was found (`found`: its
/// fit and its validation error, straight lines) by `min_gain`, and its held-out error by more
/// than noise explains: the effects' own held-out check ([`held_out_prefers`], its power
/// weighed the same way).
fn bend_beside(
    p: &Problem,
    beside: &[Shaped],
    rows: &Rows,
    opts: &Options,
    found: (&Fitted, f64),
    x_max: f64,
) -> Result<Option<Softening>, IdentifyError> {
    let (after, straight) = found;
    let validation = |env: Envelope| -> Result<f64, IdentifyError> {
        validation_error(&with_envelope(p, env, beside, &rows.train)?, beside, rows)
    };
    let mut tried = Vec::with_capacity(SOFTER_AT_EDGE.len());
    for softer in SOFTER_AT_EDGE {
        tried.push(validation(Envelope::Softening(c_for(softer, x_max)))?);
    }
    let Some(i) = (0..tried.len()).min_by(|&a, &b| tried[a].total_cmp(&tried[b])) else {
        return Ok(None);
    };
    // Refined between the shapes either side of the grid's best.
    let lo = if i == 0 { 0.0 } else { SOFTER_AT_EDGE[i - 1] };
    let hi = SOFTER_AT_EDGE.get(i + 1).copied().unwrap_or(0.6);
    let (softer, v) = golden_section(
        (lo, hi),
        (SOFTER_AT_EDGE[i], (tried[i], tried[i])),
        |softer| {
            validation(Envelope::Softening(c_for(softer, x_max)))
                .ok()
                .map(|v| (v, v))
        },
    );
    let validation_gain = (straight - v) / straight;
    if validation_gain.is_nan() || validation_gain < opts.min_gain {
        return Ok(None);
    }
    let c = c_for(softer, x_max);
    let mut q = with_envelope(p, Envelope::Softening(c), beside, &rows.fit)?;
    let bent = settle(&mut q, beside, rows)?;
    // No smallest held-out gain: the check's likelihood ratio alone (a confirmed fit is lower).
    if held_out_prefers((p, after), (&q, &bent), &rows.held, 0.0).is_none() {
        return Ok(None);
    }
    Ok(Some(Softening {
        c,
        x_max,
        softer,
        validation_gain,
        held_out: (
            after.error_on(&p.tau, &rows.held),
            bent.error_on(&q.tau, &rows.held),
        ),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shapes_c_gives_the_named_softening_at_the_edge() {
        for softer in SOFTER_AT_EDGE {
            let x = 0.13;
            let c = c_for(softer, x);
            let slope = Envelope::Softening(c).slope(x, 0.0);
            assert!((slope - (1.0 - softer)).abs() < 1e-12, "{softer}: {slope}");
            // The slope is the derivative of s (central difference).
            let h = 1e-6;
            let env = Envelope::Softening(c);
            let fd = (env.s(x + h, 0.0) - env.s(x - h, 0.0)) / (2.0 * h);
            assert!((fd - slope).abs() < 1e-8, "{fd} against {slope}");
        }
    }
}
