//! The prediction: the declared model's columns on the (possibly corrected) inputs, plus the
//! columns of the added effects, with coefficients fitted by bounded least squares.

use std::cell::RefCell;

use super::effects::{Effect, Place, Shaped};
use super::rows::{Problem, Role, jump_in};
use super::signals::{self, dead_zone};
use super::stats::{Bound, bounded_least_squares, combine, rmse};
use super::{Declared, IdentifyError};
use crate::hysteresis::{
    FitOptions, FitSample, RestoringCurve, RestoringParams, RestoringTorqueModel,
    fit_restoring_beside,
};
use crate::lever::LeverVsa;

/// How the measured inputs are changed before the declared model sees them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Transform {
    /// The model is fed x(t − delay) [s].
    pub delay: f64,
    /// The lag is a sensor's first-order low-pass of time constant |delay|, not a pure delay:
    /// delay > 0 the torque path's (the model is fed F·x: for a model linear in its inputs,
    /// F·τ̂), delay < 0 the angle path's (fed F⁻¹·x = x + |delay|·ẋ).
    pub filter: bool,
    /// Half-width of a gap in series with the spring [rad] (0: none).
    pub gap: f64,
    /// Whether the declared model's slope dτ̂/dx is wanted (by an encoder offset searched).
    pub slope: bool,
    /// An encoder offset of known size: the input becomes x + δ from t_j on (t_j NaN: always).
    pub slip: Option<(f64, f64)>,
}

impl Transform {
    /// The transform the chosen input effects make.
    pub fn of(chosen: &[Shaped]) -> Self {
        let mut t = Transform::default();
        for c in chosen {
            t = t.with(c);
        }
        t
    }

    /// The encoder correction at time `t` since the run's start [rad].
    pub fn slip_at(&self, t: f64) -> f64 {
        match self.slip {
            // A constant offset (t_j NaN) applies throughout.
            Some((tj, d)) if tj.is_nan() || t >= tj => d,
            _ => 0.0,
        }
    }

    /// As it acts in one run: an encoder slip at the run's own instant (`instant` of the
    /// fitted one, see [`Problem::jumps`]).
    pub fn in_run(mut self, instant: impl Fn(f64) -> f64) -> Self {
        if let Some((tj, d)) = self.slip.filter(|(tj, _)| tj.is_finite()) {
            self.slip = Some((instant(tj), d));
        }
        self
    }

    /// A run's signal `x` over times `t` as the lag has it: delayed, low-passed or with a
    /// low-pass undone (`rate`: x's own rate where known, else a centred difference).
    pub fn lagged(&self, t: &[f64], x: &[f64], rate: Option<&[f64]>) -> Vec<f64> {
        if !self.filter || self.delay == 0.0 {
            return signals::shifted(t, x, self.delay);
        }
        if self.delay > 0.0 {
            return signals::low_passed(t, x, self.delay);
        }
        let own;
        let rate = match rate {
            Some(v) => v,
            None => {
                own = signals::centred_rate(t, x);
                &own
            }
        };
        signals::low_pass_undone(x, rate, -self.delay)
    }

    /// With one more (or a replaced) input effect.
    pub fn with(mut self, c: &Shaped) -> Self {
        match (c.effect, c.on) {
            (Effect::SensorDelay, _) => {
                self.delay = c.shape;
                self.filter = c.filter;
            }
            (Effect::Backlash, _) => self.gap = c.shape,
            (Effect::Offset, Place::Deflection) if c.size.is_finite() => {
                self.slip = Some((c.shape, c.size));
            }
            (Effect::Offset, Place::Deflection) => self.slope = true,
            _ => {}
        }
        self
    }
}

/// Signals over all runs, concatenated, for one input transform.
#[derive(Debug, Clone)]
pub struct Signals {
    /// Deflection φ (joint torque) or link angle q (link equation), delayed.
    pub x: Vec<f64>,
    /// What the spring sees of it (through a gap, when there is backlash).
    pub xs: Vec<f64>,
    pub xdot: Vec<f64>,
    pub xddot: Vec<f64>,
    /// The direction of motion: sgn of the rate, 0 where it is within the dead band.
    pub dir: Vec<f64>,
    /// The direction a stuck contact's friction keeps: `dir` with its still stretches given
    /// the direction that entered them ([`signals::held_sign`]).
    pub dir_held: Vec<f64>,
    /// The rate whose sign is `dir` [rad/s] (the weak form's own rates on the link equation).
    pub sign_rate: Vec<f64>,
    /// Pivot position [m] (0 where absent).
    pub d: Vec<f64>,
    /// Link angle, when known.
    pub q: Option<Vec<f64>>,
    /// Angle a ripple is periodic in (q when known, else x).
    pub angle: Vec<f64>,
    /// Time since the run's start [s].
    pub t_rel: Vec<f64>,
    /// Longest run [s].
    pub duration: f64,
    pub lever: Option<LeverVsa>,
    pub base_has_intercept: bool,
    /// The declared model is a linear spring: its first column is k·x.
    pub linear_spring: bool,
    /// The declared model is the link equation: its first column is I·q̈.
    pub link: bool,
    /// The model must read zero torque at zero deflection: every run was tared at its rest and
    /// the declared model has no intercept to take an effect's value there.
    pub zero_at_rest: bool,
    /// Half-widths of hysteresis's stop operators [rad].
    pub widths: Vec<f64>,
    /// dτ̂/dx of the declared model along the path (the restoring model; a linear spring's
    /// is its constant k, so an encoder offset there is a torque offset).
    pub slope: Option<Vec<f64>>,
    /// The declared model's columns.
    pub(crate) base: Vec<Vec<f64>>,
    /// Those of its columns that are elastic torque (what a stiffness drift scales).
    pub(crate) elastic: Vec<Vec<f64>>,
    /// Row ranges of the runs.
    bounds: Vec<(usize, usize)>,
    /// Each run's hysteresis start state, a fraction of each stop's half-width, when the rests
    /// set it (see [`super::states`]); `None`: the hysteresis candidate's shape, for every run.
    pub(crate) states: Option<Vec<f64>>,
    /// The weak form (the link equation): the smoother's half-support [s] and each run's
    /// sampling step [s]; every effect's column is smoothed as the torque was.
    pub(crate) weak: Option<(f64, Vec<f64>)>,
    /// Each run's own jump instants ([`Problem::jumps`]).
    pub(crate) jumps: Vec<Vec<(f64, f64)>>,
    /// Hysteresis's stop-operator columns already built from these signals, by the start state
    /// they were built from (`None`: the rests' `states`); see [`Self::stop_columns`].
    stops: StopColumns,
}

/// How many sets of stop-operator columns a [`Signals`] keeps (a loop's start states searched
/// are few; a set is a column per width, as long as the runs).
const STOP_SETS_KEPT: usize = 4;

/// The stop-operator columns a [`Signals`] has built, by start state. A clone starts empty:
/// what is kept belongs to the signals it was built from, and a copy owes nothing to them.
#[derive(Debug, Default)]
struct StopColumns(RefCell<Vec<StopSet>>);

/// A start state's bits (`None`: the rests' states) and the stop operators' columns, a column
/// per width.
type StopSet = (Option<u64>, Vec<Vec<f64>>);

impl Clone for StopColumns {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl Signals {
    /// `col` through the weak form's smoother, run by run (unchanged without the weak form).
    pub(crate) fn smoothed(&self, col: Vec<f64>) -> Vec<f64> {
        match &self.weak {
            None => col,
            Some((h, dts)) => self.per_run_k(|k, a, b| {
                signals::weak_smooth_at(&self.t_rel[a..b], &col[a..b], *h, dts[k])
            }),
        }
    }

    /// The step 1[t ≥ t_j] of a jump fitted at `tj` [s in the run], each run's at its own
    /// instant.
    pub(crate) fn step(&self, tj: f64) -> Vec<f64> {
        self.per_run_k(|k, a, b| {
            let at = jump_in(&self.jumps, k, tj);
            self.t_rel[a..b]
                .iter()
                .map(|&t| f64::from(t >= at))
                .collect()
        })
    }

    /// The stop operators' columns of hysteresis started from `state` (`None`: each run's from
    /// the rests' `states`), built by `build` the first time and kept: every fit builds each
    /// chosen effect's columns afresh, and the search fits hundreds of times beside the same
    /// loop (a measured spring's identification spent 38 % of its time rebuilding them). The
    /// signals are not changed once built ([`Problem::signals`] is the only writer), so what is
    /// kept stays right.
    pub(crate) fn stop_columns(
        &self,
        state: Option<f64>,
        build: impl FnOnce() -> Vec<Vec<f64>>,
    ) -> Vec<Vec<f64>> {
        let key = state.map(f64::to_bits);
        if let Some((_, cols)) = self.stops.0.borrow().iter().find(|(k, _)| *k == key) {
            return cols.clone();
        }
        let cols = build();
        let mut kept = self.stops.0.borrow_mut();
        if kept.len() == STOP_SETS_KEPT {
            kept.remove(0);
        }
        kept.push((key, cols.clone()));
        cols
    }

    /// A column built run by run (stateful operators restart at each run).
    pub(crate) fn per_run(&self, f: impl Fn(usize, usize) -> Vec<f64>) -> Vec<f64> {
        self.per_run_k(|_, a, b| f(a, b))
    }

    /// As [`Self::per_run`], told the run's index too.
    pub(crate) fn per_run_k(&self, f: impl Fn(usize, usize, usize) -> Vec<f64>) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.x.len());
        for (k, &(a, b)) in self.bounds.iter().enumerate() {
            out.extend(f(k, a, b));
        }
        out
    }
}

impl Problem {
    /// The signals with the inputs changed by `tr`.
    pub(crate) fn signals(&self, tr: Transform) -> Signals {
        let joint = self.model.is_joint();
        let has_q = self.runs.iter().all(|r| r.q.is_some());
        let mut s = Signals {
            x: vec![],
            xs: vec![],
            xdot: vec![],
            xddot: vec![],
            dir: vec![],
            dir_held: vec![],
            sign_rate: vec![],
            d: vec![],
            q: None,
            angle: vec![],
            t_rel: vec![],
            duration: 0.0,
            lever: self.lever,
            linear_spring: self.model == Declared::Linear,
            link: self.model == Declared::Link,
            base_has_intercept: self.model == Declared::Linear
                || (self.model == Declared::Restoring && self.loop_offset),
            zero_at_rest: self.tared && self.model != Declared::Linear,
            widths: self.widths.clone(),
            slope: None,
            base: vec![],
            elastic: vec![],
            bounds: self.bounds.clone(),
            states: self.states.clone(),
            weak: self.weak().then(|| (self.rate_window, self.steps.clone())),
            jumps: self.jumps.clone(),
            stops: StopColumns::default(),
        };
        let mut q_all = Vec::new();
        for (k, r) in self.runs.iter().enumerate() {
            let n = r.t.len();
            let xs = if joint { r.phi.as_ref() } else { r.q.as_ref() };
            let (v, a) = (&self.rates[k].0, &self.rates[k].1);
            let mut x = tr.lagged(&r.t, xs.map_or(&[][..], Vec::as_slice), Some(v));
            if joint {
                let frame = self.frame(k);
                x.iter_mut().for_each(|v| *v += frame);
            }
            // The rates of x(t − δ) are the rates at t − δ: shifted, not computed again (and
            // a filter's, filtered: it commutes with the derivative). The weak form's rates
            // are read back from its uniform grid at the samples' own instants
            // ([`signals::weak_smooth_at`]), so they are shifted and differentiated there.
            let (v, a) = (tr.lagged(&r.t, v, Some(a)), tr.lagged(&r.t, a, None));
            // The weak form's direction of motion is from its own rates, not the smoothed q̇.
            // A filter moves it by its time constant, as a delay would: undone on the sign's
            // own rate (a derivative of a rate) it would add that noise to where the turns are.
            let weak_sign = self
                .weak_sign_rate(k)
                .map(|v| signals::shifted(&r.t, v, tr.delay));
            let rate = weak_sign.as_ref().unwrap_or(&v);
            let dir = signals::rate_sign(rate, self.still());
            // Turns out of a hold are placed where the fit rows' torque steps; the held-out
            // rows' (NaN here: a hold that reaches them is not searched) by the rate alone, as
            // the live estimator can, so the error held out is not helped by its own torque.
            let (start, held_run) = (self.bounds[k].0, k >= self.fit_runs);
            let tau: Vec<f64> = (r.tau.iter().enumerate())
                .map(|(j, &v)| {
                    if held_run || self.role[start + j] == Role::Holdout {
                        f64::NAN
                    } else {
                        v
                    }
                })
                .collect();
            s.dir_held
                .extend(signals::held_sign(&r.t, rate, &dir, &tau));
            s.dir.extend(dir);
            s.sign_rate.extend_from_slice(rate);
            let d =
                r.d.as_ref()
                    .map_or(vec![0.0; n], |d| tr.lagged(&r.t, d, None));
            if has_q {
                let q = r.q.as_ref().map_or(&[][..], Vec::as_slice);
                q_all.extend(tr.lagged(&r.t, q, (!joint).then_some(&self.rates[k].0[..])));
            }
            let t0 = r.t[0];
            s.duration = s.duration.max(r.t[n - 1] - t0);
            s.t_rel.extend(r.t.iter().map(|t| t - t0));
            let tr_k = tr.in_run(|tj| jump_in(&self.jumps, k, tj));
            s.xs.extend(x.iter().zip(&r.t).map(|(&v, &t)| {
                if joint {
                    dead_zone(v + tr_k.slip_at(t - t0), tr.gap)
                } else {
                    v
                }
            }));
            s.x.extend(x);
            s.xdot.extend(v);
            s.xddot.extend(a);
            s.d.extend(d);
        }
        s.angle = if has_q { q_all.clone() } else { s.x.clone() };
        if has_q {
            s.q = Some(q_all);
        }
        match self.model {
            Declared::Linear => {
                s.base = vec![s.xs.clone(), vec![1.0; s.xs.len()]];
                s.elastic = vec![s.xs.clone()];
            }
            Declared::Link => s.base = vec![s.xddot.clone(), s.xdot.clone()],
            Declared::Restoring => {
                let Some(curve) = self.restoring.clone() else {
                    return s;
                };
                let replay = |shift: f64| {
                    s.per_run(|a, b| {
                        let mut m = RestoringTorqueModel::new(curve.clone(), self.loop_dead_band);
                        (a..b).map(|i| m.update(s.xs[i] + shift, s.d[i])).collect()
                    })
                };
                let base = replay(0.0);
                if tr.slope {
                    let eps = self.dead_band.max(1e-9);
                    let (up, down) = (replay(eps), replay(-eps));
                    s.slope = Some(
                        up.iter()
                            .zip(&down)
                            .map(|(u, d)| (u - d) / (2.0 * eps))
                            .collect(),
                    );
                }
                s.elastic = vec![base.clone()];
                s.base = vec![base];
                if self.loop_offset {
                    s.base.push(vec![1.0; s.xs.len()]);
                }
            }
        }
        s
    }
}

/// A model: the declared columns and the shaped effects, with fitted coefficients.
#[derive(Debug, Clone)]
pub(crate) struct Fitted {
    pub coefs: Vec<f64>,
    pub prediction: Vec<f64>,
    /// Column count per part: base first, then each effect.
    pub widths: Vec<usize>,
}

/// Fits the declared model and `effects` (input effects must already be in `s`) on `rows`.
pub(crate) fn fit(s: &Signals, effects: &[Shaped], tau: &[f64], rows: &[usize]) -> Option<Fitted> {
    let mut cols: Vec<Vec<f64>> = s.base.clone();
    let mut bounds = vec![Bound::Free; s.base.len()];
    // A linear spring beside a Prandtl–Ishlinskii loop: k·x is the slope left once every stop
    // has slipped, the spring's own stiffness, and a spring's torque does not fall as it is
    // wound further. With k free, the widest stops (half the fit run's range: within it they
    // act as a stiffness) and a negative k trade off; what that pair does beyond the fit
    // run's range is not a spring's (measured spring 2 at 4 N·m, fitted on its second test:
    // k = −7 000 to −21 700 N·m/rad in the search's fits, the linear spring's 2 100; the
    // loop was refused on the first test, which goes 1.5 mrad further).
    if s.linear_spring && effects.iter().any(|e| e.effect == Effect::Hysteresis) {
        bounds[0] = Bound::NonNegative;
    }
    // A link's inertia is not negative. Free, it went negative where a torque lag δ made a
    // link whose damping outweighs its inertia look I − δ·N lighter, and so held the lag's
    // first-order share (the fourth generator's link of I = 0.006 kg·m², N = 0.33 with a
    // 21 ms torque delay: I = −0.0016 without the lag, and the lag refused).
    if s.link {
        bounds[0] = Bound::NonNegative;
    }
    let mut widths = vec![s.base.len()];
    for e in effects {
        let c = e.columns(s);
        widths.push(c.len());
        for (col, b) in c {
            cols.push(col);
            bounds.push(b);
        }
    }
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let coefs = bounded_least_squares(&refs, &bounds, tau, rows)?;
    let prediction = combine(&refs, &coefs, tau.len());
    Some(Fitted {
        coefs,
        prediction,
        widths,
    })
}

impl Fitted {
    /// Coefficients of part `k` (0: the declared model, then the effects in order).
    pub fn part(&self, k: usize) -> &[f64] {
        let start: usize = self.widths[..k].iter().sum();
        &self.coefs[start..start + self.widths[k]]
    }

    pub fn residual_on(&self, tau: &[f64], rows: &[usize]) -> Vec<f64> {
        rows.iter().map(|&i| tau[i] - self.prediction[i]).collect()
    }

    pub fn error_on(&self, tau: &[f64], rows: &[usize]) -> f64 {
        rmse(&self.residual_on(tau, rows))
    }
}

/// Refits the restoring-torque model to the torque less the chosen effects' share, on the
/// inputs as the chosen input effects change them.
pub(crate) fn refit_restoring(
    p: &Problem,
    chosen: &[Shaped],
    rows: &[usize],
) -> Result<RestoringCurve, IdentifyError> {
    let tr = Transform::of(chosen);
    let target = loop_target(p, &p.signals(tr), chosen, rows)?;
    fit_restoring_on(p, rows, &target, tr)
}

/// What the loop is fitted to: the torque less the share of the `chosen` effects, their
/// coefficients fitted on `rows` beside the current loop (in the signals `s`).
pub(crate) fn loop_target(
    p: &Problem,
    s: &Signals,
    chosen: &[Shaped],
    rows: &[usize],
) -> Result<Vec<f64>, IdentifyError> {
    let f = fit(s, chosen, &p.tau, rows).ok_or(IdentifyError::Solve)?;
    let c0 = f.part(0).first().copied().unwrap_or(1.0);
    let base = s.base.first().map_or(&[][..], Vec::as_slice);
    Ok((0..p.tau.len())
        .map(|i| p.tau[i] - (f.prediction[i] - c0 * base.get(i).copied().unwrap_or(0.0)))
        .collect())
}

/// The loop's samples on `rows`, the inputs changed by `tr`, the torque `target`; and each
/// sample's row.
fn loop_samples(
    p: &Problem,
    rows: &[usize],
    target: &[f64],
    tr: Transform,
) -> (Vec<FitSample>, Vec<usize>) {
    let mut samples = Vec::with_capacity(rows.len());
    let mut at = Vec::with_capacity(rows.len());
    let mut offset = 0;
    for (run, r) in p.runs.iter().enumerate() {
        let n = r.t.len();
        let tr = tr.in_run(|tj| p.jump_instant(run, tj));
        let frame = p.frame(run);
        let phi = tr.lagged(
            &r.t,
            r.phi.as_ref().map_or(&[][..], Vec::as_slice),
            Some(&p.rates[run].0),
        );
        let d = r.d.as_ref().map(|d| tr.lagged(&r.t, d, None));
        for k in 0..n.min(phi.len()) {
            let i = offset + k;
            if rows.binary_search(&i).is_ok() {
                samples.push(FitSample {
                    phi: dead_zone(phi[k] + frame + tr.slip_at(r.t[k] - r.t[0]), tr.gap),
                    tau: target[i],
                    d: d.as_ref().map_or(0.0, |d| d[k]),
                });
                at.push(i);
            }
        }
        offset += n;
    }
    (samples, at)
}

fn loop_options(p: &Problem, start: Option<RestoringParams>) -> FitOptions {
    FitOptions {
        dead_band: p.loop_dead_band,
        d_tolerance: 1e-4,
        envelope: p.envelope,
        start,
        ..FitOptions::default()
    }
}

/// Fits the restoring-torque model on the fit rows, the inputs changed by `tr`.
pub(crate) fn fit_restoring_on(
    p: &Problem,
    rows: &[usize],
    target: &[f64],
    tr: Transform,
) -> Result<RestoringCurve, IdentifyError> {
    let (samples, _) = loop_samples(p, rows, target, tr);
    // A refit after a small change starts from the loop it replaces as well.
    let start = p
        .restoring
        .as_ref()
        .map(|c| c.at(samples.first().map_or(0.0, |s| s.d)));
    fit_loop(p, &samples, vec![], start)
}

/// Fits the loop afresh (from the grid's starts only, not from the loop it would replace)
/// together with the coefficients of `columns` (each over every row) beside it: the loop of
/// a torque offset's candidate. Fitted after the loop, an offset gains nothing: the loop has
/// already held it (see [`fit_restoring_beside`]).
pub(crate) fn fit_restoring_beside_on(
    p: &Problem,
    rows: &[usize],
    target: &[f64],
    tr: Transform,
    columns: &[Vec<f64>],
) -> Result<RestoringCurve, IdentifyError> {
    let (samples, at) = loop_samples(p, rows, target, tr);
    let cols: Vec<Vec<f64>> = columns
        .iter()
        .map(|c| at.iter().map(|&i| c[i]).collect())
        .collect();
    fit_loop(p, &samples, cols, None)
}

/// The loop fitted on `samples` beside `columns` (one value per sample) and, where the
/// problem's loop holds an offset ([`Problem::loop_offset`]), a torque constant.
fn fit_loop(
    p: &Problem,
    samples: &[FitSample],
    mut columns: Vec<Vec<f64>>,
    start: Option<RestoringParams>,
) -> Result<RestoringCurve, IdentifyError> {
    if p.loop_offset {
        columns.push(vec![1.0; samples.len()]);
    }
    let refs: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
    fit_restoring_beside(samples, &refs, &loop_options(p, start))
        .map(|(f, _)| f.curve)
        .map_err(IdentifyError::Restoring)
}

/// The declared model's parameters.
pub(crate) fn base_params(
    model: Declared,
    c: &[f64],
    curve: Option<&RestoringCurve>,
) -> Vec<(&'static str, f64)> {
    match model {
        Declared::Linear => vec![("stiffness_nm_per_rad", c[0]), ("offset_nm", c[1])],
        Declared::Link => vec![("inertia_kgm2", c[0]), ("damping_nms_per_rad", c[1])],
        Declared::Restoring => {
            let mut v = vec![("scale", c[0])];
            if let Some(&offset) = c.get(1) {
                v.push(("offset_nm", offset));
            }
            if let Some(curve) = curve {
                let t = curve.table();
                if let Some((_, p)) = t.first() {
                    v.extend([
                        ("stiffness_nm_per_rad", p.k),
                        ("loop_half_height_nm", p.h),
                        ("a_s", p.a_s),
                        ("n", p.n),
                    ]);
                }
            }
            v
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Holdout, Options, Run};
    use super::*;

    /// Two runs of a swinging deflection (their stop operators restart at each run's start).
    fn problem() -> Problem {
        let run = |name: &str, phase: f64| {
            let t: Vec<f64> = (0..1500).map(|k| k as f64 / 500.0).collect();
            let phi: Vec<f64> = t
                .iter()
                .map(|&t| 0.01 * (4.0 * t + phase).sin() + 0.003 * (11.0 * t).sin())
                .collect();
            Run {
                name: name.into(),
                tau: phi.iter().map(|p| 50.0 * p).collect(),
                t,
                phi: Some(phi),
                d: None,
                q: None,
            }
        };
        let opts = Options {
            model: Declared::Linear,
            ..Options::default()
        };
        Problem::new(
            &[run("a", 0.0), run("b", 1.0)],
            &[],
            &Holdout::Blocks,
            &opts,
        )
    }

    #[test]
    fn hysteresis_columns_kept_between_fits_are_those_built_afresh_for_every_start_state() {
        let p = problem();
        let s = p.signals(Transform::default());
        assert!(s.widths.len() > 3 && s.bounds.len() == 2);
        // Each start state's columns, built from the stop operators directly, run by run.
        let fresh = |state: f64| -> Vec<Vec<f64>> {
            (s.widths.iter())
                .map(|&w| {
                    (s.bounds.iter())
                        .flat_map(|&(a, b)| signals::stop_operator_from(&s.xs[a..b], w, state * w))
                        .collect()
                })
                .collect()
        };
        // More states than are kept, and back to the first ones: each asked twice or more.
        let states = [-1.0, 0.0, 1.0, 0.5, -0.5, 0.25, -1.0, 0.0, 1.0, -1.0];
        for &state in &states {
            let got: Vec<Vec<f64>> = Shaped::new(Effect::Hysteresis, state)
                .columns(&s)
                .into_iter()
                .map(|(c, b)| {
                    assert_eq!(b, Bound::NonNegative);
                    c
                })
                .collect();
            assert_eq!(got, fresh(state), "start state {state}");
        }
        // A copy of the signals starts with nothing kept, and builds the same columns.
        let copy = s.clone();
        assert!(copy.stops.0.borrow().is_empty());
        assert_eq!(
            Shaped::new(Effect::Hysteresis, 0.5).columns(&copy).len(),
            s.widths.len()
        );
    }
}
