//! Closing the loop with measured data (MODEL.md §6): fit a declared model, look at what it
//! leaves (the residual), trace that to an effect the model lacks, add the effect, refit, and
//! report the error before and after — always on data held out of the fit.
//!
//! The prediction is linear in its coefficients: the declared model's columns (the replayed
//! restoring-torque model, or k·φ + c, or I·q̈ + N·q̇) plus, per added effect, its columns
//! ([`effects`]). Shapes that are not linear (a delay, a play width, a jump time, a period)
//! are searched on grids. Selection is forward and greedy: each round tries every candidate
//! at every shape, fitting on part of the fit data and scoring on the rest (interleaved time
//! blocks, never the held-out data); the best is added only if it lowers that validation
//! error by at least [`Options::min_gain`]. So on data with nothing missing, nothing is
//! added. The held-out data then gives every "before" and "after" figure.

pub mod effects;
pub mod monitor;
pub mod signals;
pub mod stats;

use crate::hysteresis::{
    FitOptions, FitSample, RestoringCurve, RestoringTorqueModel, fit_restoring,
};
use crate::lever::LeverVsa;
use effects::Sign;
pub use effects::{Effect, Shaped};
use stats::{combine, least_squares, mae, mean, rmse};
use thiserror::Error;

/// The declared model identification starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Declared {
    /// Paper B's restoring-torque model (hysteresis driven by deflection alone): τ from φ, d.
    Restoring,
    /// A linear spring with offset: τ = k·φ + c.
    Linear,
    /// Paper A's link equation: τ = I·q̈ + N·q̇ (τ the net torque on the link).
    Link,
}

impl Declared {
    pub fn name(self) -> &'static str {
        match self {
            Declared::Restoring => "restoring",
            Declared::Linear => "linear",
            Declared::Link => "link",
        }
    }

    /// Effects the declared model already has.
    pub fn declares(self) -> &'static [Effect] {
        match self {
            Declared::Restoring => &[Effect::Hysteresis],
            Declared::Linear => &[],
            Declared::Link => &[Effect::ViscousFriction],
        }
    }

    /// Whether the model predicts a joint's torque from its deflection (not the link equation).
    fn is_joint(self) -> bool {
        self != Declared::Link
    }
}

/// One measured run (a file, or one recording's joint), in SI units.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Run {
    pub name: String,
    /// Time [s], strictly increasing.
    pub t: Vec<f64>,
    /// Measured torque [N·m].
    pub tau: Vec<f64>,
    /// Deflection [rad].
    pub phi: Option<Vec<f64>>,
    /// Pivot position [m].
    pub d: Option<Vec<f64>>,
    /// Link angle [rad].
    pub q: Option<Vec<f64>>,
}

/// Options of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    pub model: Declared,
    /// The lever joint, when a config names one: enables `geometric_stiffness`.
    pub lever: Option<LeverVsa>,
    /// Direction dead band [rad]; `None`: three quantisation steps of the angle.
    pub dead_band: Option<f64>,
    /// Time blocks per run for interleaving.
    pub blocks: usize,
    /// Smallest relative drop of the validation RMSE that adds an effect.
    pub min_gain: f64,
    /// Most effects added.
    pub max_effects: usize,
    /// Largest sensor delay searched, either way [s].
    pub max_delay: f64,
    /// Half-window of the local fits giving rates [s].
    pub rate_window: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            model: Declared::Restoring,
            lever: None,
            dead_band: None,
            blocks: 12,
            min_gain: 0.02,
            max_effects: 6,
            max_delay: 0.1,
            rate_window: 0.02,
        }
    }
}

/// Errors of identification: each names what is wrong with the data.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum IdentifyError {
    #[error("no data to fit")]
    NoData,
    #[error("{run}: {what}")]
    Run { run: String, what: String },
    #[error("the declared restoring model could not be fitted: {0}")]
    Restoring(String),
    #[error("the least-squares fit failed (the columns are not finite)")]
    Solve,
}

/// RMSE and MAE [N·m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Errors {
    pub rmse: f64,
    pub mae: f64,
}

impl Errors {
    fn of(e: &[f64]) -> Self {
        Self {
            rmse: rmse(e),
            mae: mae(e),
        }
    }
}

/// An effect added to the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    pub effect: Effect,
    pub params: Vec<(&'static str, f64)>,
    /// Held-out RMSE before this effect less after it (effects in the order added) [N·m].
    pub gain_rmse: f64,
    /// The relative drop of the validation RMSE that selected it.
    pub validation_gain: f64,
}

/// A candidate that was tried and refused, with its best relative validation gain.
#[derive(Debug, Clone, PartialEq)]
pub struct Refused {
    pub effect: Effect,
    pub best_gain: f64,
    pub why: &'static str,
}

/// The largest correlation of the residual with one input, and where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct Correlation {
    pub input: &'static str,
    pub max_abs: f64,
    /// Lag [s]: positive when the residual follows the input late.
    pub lag_s: f64,
}

/// What the residual (held-out, after) still shows.
#[derive(Debug, Clone, PartialEq)]
pub struct Residual {
    pub white: bool,
    pub max_autocorr: f64,
    /// Its lag [s].
    pub max_autocorr_lag_s: f64,
    /// The band |ρ| must stay within (Bonferroni over the lags, 5 %).
    pub band: f64,
    pub lags: usize,
    pub autocorr: Vec<f64>,
    pub cross: Vec<Correlation>,
    /// Cross-correlation curves (lag [s], ρ) per input, for plots.
    pub cross_curves: Vec<(&'static str, Vec<(f64, f64)>)>,
    /// Plain-language remarks on structure left unexplained.
    pub structure: Vec<String>,
}

/// Held-out series for plots and per-run bias.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Heldout {
    pub run: Vec<usize>,
    pub t: Vec<f64>,
    pub x: Vec<f64>,
    pub measured: Vec<f64>,
    pub before: Vec<f64>,
    pub after: Vec<f64>,
}

/// The result of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct Identified {
    pub model: Declared,
    pub fit_samples: usize,
    pub holdout_samples: usize,
    pub before: Errors,
    pub after: Errors,
    /// The declared model's own parameters, before and after the effects were added.
    pub base_before: Vec<(&'static str, f64)>,
    pub base_after: Vec<(&'static str, f64)>,
    pub effects: Vec<Found>,
    pub refused: Vec<Refused>,
    /// Candidates not tried, and why.
    pub not_applicable: Vec<(Effect, &'static str)>,
    pub residual: Residual,
    /// Mean held-out residual (after) per held-out run: offsets that differ between runs.
    pub bias: Vec<(String, f64)>,
    pub heldout: Heldout,
    /// Sampling period used for correlations [s].
    pub dt: f64,
    pub dead_band: f64,
}

/// Where the held-out data comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Holdout<'a> {
    /// Whole runs held out.
    Runs(&'a [Run]),
    /// Interleaved time blocks of the fit runs.
    Blocks,
}

/// The role of a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Train,
    Validate,
    Holdout,
}

/// Signals over all runs, concatenated, for one sensor delay.
#[derive(Debug, Clone)]
pub struct Signals {
    /// Deflection φ (joint torque) or link angle q (link equation), delayed.
    pub x: Vec<f64>,
    pub xdot: Vec<f64>,
    pub xddot: Vec<f64>,
    pub dir: Vec<f64>,
    /// Pivot position [m] (0 where absent).
    pub d: Vec<f64>,
    /// Link angle, when known.
    pub q: Option<Vec<f64>>,
    /// Angle a ripple is periodic in (q when known, else x).
    pub angle: Vec<f64>,
    /// Time since the run's start [s].
    pub t_rel: Vec<f64>,
    pub lever: Option<LeverVsa>,
    pub base_has_intercept: bool,
    /// Row ranges of the runs.
    bounds: Vec<(usize, usize)>,
    /// The declared model's columns.
    base: Vec<Vec<f64>>,
}

impl Signals {
    /// A column built run by run (stateful operators restart at each run).
    pub(crate) fn per_run(&self, f: impl Fn(usize, usize) -> Vec<f64>) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.x.len());
        for &(a, b) in &self.bounds {
            out.extend(f(a, b));
        }
        out
    }
}

/// Everything fixed across candidates: the runs, concatenated, and row roles.
struct Problem<'a> {
    runs: Vec<&'a Run>,
    bounds: Vec<(usize, usize)>,
    tau: Vec<f64>,
    role: Vec<Role>,
    opts: &'a Options,
    dead_band: f64,
    /// Quantisation step of the angle [rad] (0 when not quantised).
    resolution: f64,
    restoring: Option<RestoringCurve>,
}

impl Problem<'_> {
    fn rows(&self, want: &[Role]) -> Vec<usize> {
        (0..self.tau.len())
            .filter(|&i| want.contains(&self.role[i]))
            .collect()
    }

    /// The signals with the inputs delayed by `delay` [s].
    fn signals(&self, delay: f64) -> Signals {
        let joint = self.opts.model.is_joint();
        let mut s = Signals {
            x: vec![],
            xdot: vec![],
            xddot: vec![],
            dir: vec![],
            d: vec![],
            q: None,
            angle: vec![],
            t_rel: vec![],
            lever: self.opts.lever,
            base_has_intercept: self.opts.model == Declared::Linear,
            bounds: self.bounds.clone(),
            base: vec![],
        };
        let has_q = self.runs.iter().all(|r| r.q.is_some());
        let mut q_all = Vec::new();
        for r in &self.runs {
            let n = r.t.len();
            let xs = if joint { r.phi.as_ref() } else { r.q.as_ref() };
            let x = signals::shifted(&r.t, xs.map_or(&[][..], Vec::as_slice), delay);
            let (v, a) = signals::local_rates(&r.t, &x, self.opts.rate_window);
            s.dir.extend(signals::rate_sign(
                &v,
                0.5 * self.resolution / self.opts.rate_window,
            ));
            let d =
                r.d.as_ref()
                    .map_or(vec![0.0; n], |d| signals::shifted(&r.t, d, delay));
            if has_q {
                q_all.extend(signals::shifted(
                    &r.t,
                    r.q.as_ref().map_or(&[][..], Vec::as_slice),
                    delay,
                ));
            }
            let t0 = r.t[0];
            s.t_rel.extend(r.t.iter().map(|t| t - t0));
            s.x.extend(x);
            s.xdot.extend(v);
            s.xddot.extend(a);
            s.d.extend(d);
        }
        s.angle = if has_q { q_all.clone() } else { s.x.clone() };
        if has_q {
            s.q = Some(q_all);
        }
        s.base = match self.opts.model {
            Declared::Linear => vec![s.x.clone(), vec![1.0; s.x.len()]],
            Declared::Link => vec![s.xddot.clone(), s.xdot.clone()],
            Declared::Restoring => {
                let Some(curve) = self.restoring.clone() else {
                    return s;
                };
                vec![s.per_run(|a, b| {
                    let mut m = RestoringTorqueModel::new(curve.clone(), self.dead_band);
                    (a..b).map(|i| m.update(s.x[i], s.d[i])).collect()
                })]
            }
        };
        s
    }
}

/// A model: the declared columns and the shaped effects, with fitted coefficients.
struct Fitted {
    coefs: Vec<f64>,
    prediction: Vec<f64>,
    /// Column count per part: base first, then each effect.
    widths: Vec<usize>,
}

fn fit(s: &Signals, effects: &[Shaped], tau: &[f64], rows: &[usize]) -> Option<Fitted> {
    let mut cols: Vec<Vec<f64>> = s.base.clone();
    let mut widths = vec![s.base.len()];
    for e in effects {
        let c = e.columns(s);
        widths.push(c.len());
        cols.extend(c);
    }
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let coefs = least_squares(&refs, tau, rows)?;
    let prediction = combine(&refs, &coefs, tau.len());
    Some(Fitted {
        coefs,
        prediction,
        widths,
    })
}

impl Fitted {
    /// Coefficients of part `k` (0: the declared model, then the effects in order).
    fn part(&self, k: usize) -> &[f64] {
        let start: usize = self.widths[..k].iter().sum();
        &self.coefs[start..start + self.widths[k]]
    }

    fn error_on(&self, tau: &[f64], rows: &[usize]) -> f64 {
        let e: Vec<f64> = rows.iter().map(|&i| tau[i] - self.prediction[i]).collect();
        rmse(&e)
    }
}

/// Checks a run's columns for the model; returns its length.
fn check_run(r: &Run, model: Declared) -> Result<(), IdentifyError> {
    let bad = |what: String| IdentifyError::Run {
        run: r.name.clone(),
        what,
    };
    let n = r.t.len();
    if n < 20 {
        return Err(bad(format!("{n} samples; at least 20 are needed")));
    }
    let need: &[(&str, Option<&Vec<f64>>)] = match model {
        Declared::Link => &[("q", r.q.as_ref())],
        _ => &[("phi", r.phi.as_ref())],
    };
    for (name, col) in need {
        match col {
            None => {
                return Err(bad(format!(
                    "the {} model needs a column {name}",
                    model.name()
                )));
            }
            Some(c) if c.len() != n => {
                return Err(bad(format!(
                    "column {name} has {} rows, t has {n}",
                    c.len()
                )));
            }
            _ => {}
        }
    }
    if r.tau.len() != n {
        return Err(bad(format!(
            "column tau has {} rows, t has {n}",
            r.tau.len()
        )));
    }
    for (name, c) in [("d", r.d.as_ref()), ("q", r.q.as_ref())] {
        if let Some(c) = c
            && c.len() != n
        {
            return Err(bad(format!(
                "column {name} has {} rows, t has {n}",
                c.len()
            )));
        }
    }
    if let Some(i) = (1..n).find(|&i| r.t[i] <= r.t[i - 1]) {
        return Err(bad(format!("time does not increase at row {i}")));
    }
    let cols = [
        Some(&r.t),
        Some(&r.tau),
        r.phi.as_ref(),
        r.d.as_ref(),
        r.q.as_ref(),
    ];
    if cols
        .iter()
        .flatten()
        .any(|c| c.iter().any(|v| !v.is_finite()))
    {
        return Err(bad("a value is not finite".into()));
    }
    Ok(())
}

/// The smallest nonzero step of a quantised signal (its resolution), or 0.
fn resolution(x: &[f64]) -> f64 {
    let mut steps: Vec<f64> = x
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|v| *v > 1e-12)
        .collect();
    if steps.is_empty() {
        return 0.0;
    }
    steps.sort_by(f64::total_cmp);
    steps[steps.len() / 20]
}

/// Logarithmically spaced values from `lo` to `hi`.
fn logspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo) || n < 2 {
        return vec![];
    }
    (0..n)
        .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}

/// Identifies what the declared model lacks. `progress(done, total)` is called as candidate
/// fits finish (total is an estimate: rounds are not known in advance).
pub fn identify(
    fit_runs: &[Run],
    holdout: Holdout<'_>,
    opts: &Options,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Identified, IdentifyError> {
    if fit_runs.is_empty() {
        return Err(IdentifyError::NoData);
    }
    let held: &[Run] = match holdout {
        Holdout::Runs(h) => h,
        Holdout::Blocks => &[],
    };
    for r in fit_runs.iter().chain(held) {
        check_run(r, opts.model)?;
    }
    // Rows and roles.
    let blocks = opts.blocks.max(4);
    let mut runs: Vec<&Run> = Vec::new();
    let (mut bounds, mut tau, mut role) = (Vec::new(), Vec::new(), Vec::new());
    for (r, is_held) in fit_runs
        .iter()
        .map(|r| (r, false))
        .chain(held.iter().map(|r| (r, true)))
    {
        let start = tau.len();
        let (t0, t1) = (r.t[0], r.t[r.t.len() - 1]);
        for &t in &r.t {
            let b = (((t - t0) / (t1 - t0).max(1e-12)) * blocks as f64).min(blocks as f64 - 1.0)
                as usize;
            role.push(match (is_held, matches!(holdout, Holdout::Blocks), b % 4) {
                (true, _, _) => Role::Holdout,
                (false, true, 3) => Role::Holdout,
                (false, _, 1) => Role::Validate,
                _ => Role::Train,
            });
        }
        tau.extend_from_slice(&r.tau);
        bounds.push((start, tau.len()));
        runs.push(r);
    }
    let joint = opts.model.is_joint();
    let angle_of = |r: &Run| -> Vec<f64> {
        if joint { r.phi.clone() } else { r.q.clone() }.unwrap_or_default()
    };
    let all_x: Vec<f64> = runs.iter().flat_map(|r| angle_of(r)).collect();
    let res = runs
        .iter()
        .map(|r| resolution(&angle_of(r)))
        .fold(f64::INFINITY, f64::min);
    let dead_band = opts.dead_band.unwrap_or(if res.is_finite() && res > 0.0 {
        3.0 * res
    } else {
        1e-6
    });
    let mut p = Problem {
        runs,
        bounds,
        tau,
        role,
        opts,
        dead_band,
        resolution: if res.is_finite() { res } else { 0.0 },
        restoring: None,
    };
    let train = p.rows(&[Role::Train]);
    let validate = p.rows(&[Role::Validate]);
    let fit_rows = p.rows(&[Role::Train, Role::Validate]);
    let held_rows = p.rows(&[Role::Holdout]);
    if train.is_empty() || validate.is_empty() || held_rows.is_empty() {
        return Err(IdentifyError::NoData);
    }
    if opts.model == Declared::Restoring {
        p.restoring = Some(fit_restoring_on(&p, &fit_rows, &p.tau, 0.0)?);
    }

    // Candidates and their shape grids, from the fit data's ranges.
    let fit_x: Vec<f64> = fit_rows.iter().map(|&i| all_x[i]).collect();
    let x_max = fit_x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let x_range = fit_x.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - fit_x.iter().cloned().fold(f64::INFINITY, f64::min);
    let dt = p
        .runs
        .iter()
        .map(|r| signals::median_step(&r.t))
        .fold(f64::INFINITY, f64::min);
    let duration = p
        .runs
        .iter()
        .map(|r| r.t[r.t.len() - 1] - r.t[0])
        .fold(0.0f64, f64::max);
    let has_q = p.runs.iter().all(|r| r.q.is_some());
    let has_d = p.runs.iter().all(|r| r.d.is_some());
    let q_all: Vec<f64> = p
        .runs
        .iter()
        .flat_map(|r| r.q.clone().unwrap_or_default())
        .collect();
    let q_range = q_all.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - q_all.iter().cloned().fold(f64::INFINITY, f64::min);
    let mut not_applicable: Vec<(Effect, &'static str)> = Vec::new();
    let mut candidates: Vec<(Effect, Vec<f64>)> = Vec::new();
    for e in Effect::ALL {
        if opts.model.declares().contains(&e) {
            continue;
        }
        let grid: Result<Vec<f64>, &'static str> = match (e, joint) {
            // Hysteresis is gradual (a stop wider than the direction dead band: narrower is
            // Coulomb friction); backlash may be as narrow as the encoder resolves.
            (Effect::Hysteresis, true) => Ok(logspace(10.0 * dead_band, 0.25 * x_range, 16)),
            (Effect::Backlash, true) => Ok(logspace(dead_band / 3.0, 0.25 * x_range, 20)),
            (Effect::Hysteresis | Effect::Backlash | Effect::HardStop, false) => {
                Err("a joint-torque effect; the link equation has no spring")
            }
            (Effect::GeometricStiffness, false) => Err("a joint-torque effect"),
            (Effect::StiffnessDrift, false) => Err("the link equation has no spring"),
            (Effect::HardStop, true) => Ok([0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95]
                .iter()
                .map(|f| f * x_max)
                .collect()),
            (Effect::GeometricStiffness, true) if opts.lever.is_none() => {
                Err("needs a lever joint (--config) to know G(φ, d)")
            }
            (Effect::GeometricStiffness, true) if !has_d => Err("needs the pivot column d"),
            (Effect::Gravity, true) if !has_q => Err("needs the link angle column q"),
            // sin q and cos q of a link that hardly turns are a constant and a slope: an
            // offset and a spring, not gravity.
            (Effect::Gravity, _) if q_range < 0.5 => {
                Err("the link angle moves less than 0.5 rad: gravity cannot be told from an offset")
            }
            (Effect::SensorDelay, _) => {
                // The torque sensor lags (filters, transport). A torque that leads the
                // encoder by δ is, at these speeds, k·δ·ẋ: viscous friction, named so.
                let step = dt.max(opts.max_delay / 40.0);
                let k = (opts.max_delay / step).floor() as i64;
                Ok((1..=k).map(|i| i as f64 * step).collect())
            }
            (Effect::Offset, _) => {
                let mut g: Vec<f64> = (1..24).map(|i| duration * i as f64 / 24.0).collect();
                if opts.model != Declared::Linear {
                    g.push(f64::NAN);
                }
                Ok(g)
            }
            (Effect::PeriodicRipple, _) => {
                let angle: Vec<f64> = if has_q {
                    p.runs
                        .iter()
                        .flat_map(|r| r.q.clone().unwrap_or_default())
                        .collect()
                } else {
                    all_x.clone()
                };
                let range = angle.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                    - angle.iter().cloned().fold(f64::INFINITY, f64::min);
                Ok(logspace(range / 60.0, range / 3.0, 30))
            }
            _ => Ok(vec![f64::NAN]),
        };
        match grid {
            Ok(g) if !g.is_empty() => candidates.push((e, g)),
            Ok(_) => not_applicable.push((e, "the data's range is too small")),
            Err(why) => not_applicable.push((e, why)),
        }
    }

    // Forward selection on validation blocks.
    let per_round: usize = candidates.iter().map(|(_, g)| g.len()).sum();
    let total = per_round * (opts.max_effects + 1).min(candidates.len() + 1);
    let mut done = 0usize;
    let mut chosen: Vec<Shaped> = Vec::new();
    let mut gains: Vec<f64> = Vec::new();
    let mut best_refused: Vec<(Effect, f64)>;
    let restoring_before = p.restoring.clone();
    let mut sig = p.signals(0.0);
    let mut current = fit(&sig, &chosen, &p.tau, &train)
        .ok_or(IdentifyError::Solve)?
        .error_on(&p.tau, &validate);
    loop {
        let mut best: Option<(Shaped, f64)> = None;
        let mut per_effect: Vec<(Effect, f64)> = Vec::new();
        for (e, grid) in &candidates {
            if chosen.iter().any(|c| c.effect == *e) {
                continue;
            }
            let mut tick = || {
                done += 1;
                progress(done, total.max(done));
            };
            let found = search(
                &p,
                Some(&sig),
                &chosen,
                *e,
                grid,
                &train,
                &validate,
                &mut tick,
            );
            per_effect.push((*e, found.map_or(f64::NEG_INFINITY, |f| 1.0 - f.1 / current)));
            if let Some(f) = found
                && best.as_ref().is_none_or(|b| f.1 < b.1)
            {
                best = Some(f);
            }
        }
        best_refused = per_effect;
        let Some((cand, err)) = best else { break };
        let gain = 1.0 - err / current;
        if gain < opts.min_gain || chosen.len() >= opts.max_effects {
            break;
        }
        chosen.push(cand);
        gains.push(gain);
        if opts.model == Declared::Restoring {
            // The declared model was fitted with the effect's share in its data (a lag
            // widens its loop, friction raises it): refit it without, and search the delay
            // again against the refitted model.
            // Alternate until the delay settles (a lag and a loop trade off slowly).
            for _ in 0..8 {
                p.restoring = Some(refit_restoring(&p, &chosen, &fit_rows)?);
                let Some(k) = chosen.iter().position(|c| c.effect == Effect::SensorDelay) else {
                    break;
                };
                let Some((_, grid)) = candidates.iter().find(|(e, _)| *e == Effect::SensorDelay)
                else {
                    break;
                };
                let others: Vec<Shaped> = chosen
                    .iter()
                    .copied()
                    .filter(|c| c.effect != Effect::SensorDelay)
                    .collect();
                let before = chosen[k].shape;
                if let Some((d, _)) = search(
                    &p,
                    None,
                    &others,
                    Effect::SensorDelay,
                    grid,
                    &train,
                    &validate,
                    &mut || {},
                ) {
                    chosen[k] = d;
                }
                if chosen[k].shape == before {
                    break;
                }
            }
        }
        // The new baseline (with the restoring model, against its refitted loop).
        sig = p.signals(delay_of(&chosen));
        current = fit(&sig, &chosen, &p.tau, &train)
            .ok_or(IdentifyError::Solve)?
            .error_on(&p.tau, &validate);
    }
    progress(total.max(done), total.max(done));

    // Final fits on all the fit data; every figure on the held-out rows.
    let refitted = std::mem::replace(&mut p.restoring, restoring_before);
    let sig0 = p.signals(0.0);
    let before = fit(&sig0, &[], &p.tau, &fit_rows).ok_or(IdentifyError::Solve)?;
    let mut held_errs = vec![before.error_on(&p.tau, &held_rows)];
    let base_before = base_params(opts.model, before.part(0), p.restoring.as_ref());
    p.restoring = refitted;
    // Each chosen effect, in order, must also lower the held-out error; one that does not
    // is refused (it fitted something of the fit data that the held-out data lacks).
    let mut kept: Vec<Shaped> = Vec::new();
    let mut kept_gains: Vec<f64> = Vec::new();
    let mut refused: Vec<Refused> = Vec::new();
    for (c, g) in chosen.iter().zip(&gains) {
        let mut trial = kept.clone();
        trial.push(*c);
        let s = p.signals(delay_of(&trial));
        let f = fit(&s, &trial, &p.tau, &fit_rows).ok_or(IdentifyError::Solve)?;
        let e = f.error_on(&p.tau, &held_rows);
        if e < held_errs[held_errs.len() - 1] {
            kept = trial;
            kept_gains.push(*g);
            held_errs.push(e);
        } else {
            refused.push(Refused {
                effect: c.effect,
                best_gain: *g,
                why: "lowered the validation error but not the held-out error",
            });
        }
    }
    let chosen = kept;
    let sig = p.signals(delay_of(&chosen));
    let after = fit(&sig, &chosen, &p.tau, &fit_rows).ok_or(IdentifyError::Solve)?;
    let effects: Vec<Found> = chosen
        .iter()
        .enumerate()
        .map(|(k, c)| Found {
            effect: c.effect,
            params: c.params(after.part(k + 1), sig.base_has_intercept),
            gain_rmse: held_errs[k] - held_errs[k + 1],
            validation_gain: kept_gains[k],
        })
        .collect();
    refused.extend(best_refused.into_iter().map(|(effect, best_gain)| Refused {
        effect,
        best_gain,
        why: "its best validation gain is below the threshold",
    }));
    let err_of = |f: &Fitted| -> Vec<f64> {
        held_rows
            .iter()
            .map(|&i| p.tau[i] - f.prediction[i])
            .collect()
    };
    let (e_before, e_after) = (err_of(&before), err_of(&after));
    let heldout = Heldout {
        run: held_rows
            .iter()
            .map(|&i| {
                p.bounds
                    .iter()
                    .position(|&(a, b)| i >= a && i < b)
                    .unwrap_or(0)
            })
            .collect(),
        t: held_rows.iter().map(|&i| sig0.t_rel[i]).collect(),
        x: held_rows.iter().map(|&i| sig0.x[i]).collect(),
        measured: held_rows.iter().map(|&i| p.tau[i]).collect(),
        before: held_rows.iter().map(|&i| before.prediction[i]).collect(),
        after: held_rows.iter().map(|&i| after.prediction[i]).collect(),
    };
    let bias = p
        .runs
        .iter()
        .enumerate()
        .filter_map(|(k, r)| {
            let e: Vec<f64> = heldout
                .run
                .iter()
                .zip(&e_after)
                .filter(|(run, _)| **run == k)
                .map(|(_, e)| *e)
                .collect();
            (!e.is_empty()).then(|| (r.name.clone(), mean(&e)))
        })
        .collect();
    let residual = diagnose(&p, &sig, &held_rows, &e_after, dt, opts);
    Ok(Identified {
        model: opts.model,
        fit_samples: fit_rows.len(),
        holdout_samples: held_rows.len(),
        before: Errors::of(&e_before),
        after: Errors::of(&e_after),
        base_before,
        base_after: base_params(opts.model, after.part(0), p.restoring.as_ref()),
        effects,
        refused,
        not_applicable,
        residual,
        bias,
        heldout,
        dt,
        dead_band,
    })
}

/// The shaped effect's delay, if one is chosen [s].
fn delay_of(c: &[Shaped]) -> f64 {
    c.iter()
        .find(|s| s.effect == Effect::SensorDelay)
        .map_or(0.0, |s| s.shape)
}

/// The best shape of `effect` on its grid, refined between the best point's neighbours:
/// the effects in `chosen` plus it, fitted on `train`, scored (RMSE) on `validate`. Shapes
/// whose coefficient has the wrong sign for the effect's meaning are skipped. `sig` are the
/// signals of `chosen`; a sensor delay makes its own per shape and needs none.
#[allow(clippy::too_many_arguments)]
fn search(
    p: &Problem,
    sig: Option<&Signals>,
    chosen: &[Shaped],
    effect: Effect,
    grid: &[f64],
    train: &[usize],
    validate: &[usize],
    tick: &mut dyn FnMut(),
) -> Option<(Shaped, f64)> {
    let trial_at = |shape: f64| -> Option<f64> {
        let cand = Shaped { effect, shape };
        let mut trial = chosen.to_vec();
        trial.push(cand);
        let delayed;
        let s = match sig {
            Some(s) if effect != Effect::SensorDelay => s,
            _ => {
                delayed = p.signals(shape);
                &delayed
            }
        };
        let f = fit(s, &trial, &p.tau, train)?;
        let c0 = f.part(trial.len()).first().copied().unwrap_or(0.0);
        let ok = match cand.sign() {
            Sign::Positive => c0 > 0.0,
            Sign::Negative => c0 < 0.0,
            Sign::Any => true,
        };
        ok.then(|| f.error_on(&p.tau, validate))
    };
    let mut scored: Vec<(f64, f64)> = Vec::new();
    for &shape in grid {
        tick();
        if let Some(err) = trial_at(shape) {
            scored.push((shape, err));
        }
    }
    let best = |v: &[(f64, f64)]| v.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((shape, _)) = best(&scored)
        && shape.is_finite()
        && grid.len() > 2
    {
        let at = grid.iter().position(|g| *g == shape).unwrap_or(0);
        let lo = grid[at.saturating_sub(1)];
        let hi = grid[(at + 1).min(grid.len() - 1)];
        for j in 1..8 {
            let shape = lo + (hi - lo) * j as f64 / 8.0;
            // On an even grid the midpoint is the grid point itself, already scored.
            if (shape - grid[at]).abs() <= 1e-12 * grid[at].abs() {
                continue;
            }
            if let Some(err) = trial_at(shape) {
                scored.push((shape, err));
            }
        }
    }
    best(&scored).map(|(shape, err)| (Shaped { effect, shape }, err))
}

/// Refits the restoring-torque model to the torque less the chosen effects' share, with the
/// inputs delayed as chosen.
fn refit_restoring(
    p: &Problem,
    chosen: &[Shaped],
    rows: &[usize],
) -> Result<RestoringCurve, IdentifyError> {
    let delay = delay_of(chosen);
    let s = p.signals(delay);
    let f = fit(&s, chosen, &p.tau, rows).ok_or(IdentifyError::Solve)?;
    let c0 = f.part(0).first().copied().unwrap_or(1.0);
    let base = s.base.first().map_or(&[][..], Vec::as_slice);
    let target: Vec<f64> = (0..p.tau.len())
        .map(|i| p.tau[i] - (f.prediction[i] - c0 * base.get(i).copied().unwrap_or(0.0)))
        .collect();
    fit_restoring_on(p, rows, &target, delay)
}

/// Fits the restoring-torque model on the fit rows, the inputs delayed by `delay` [s].
fn fit_restoring_on(
    p: &Problem,
    rows: &[usize],
    target: &[f64],
    delay: f64,
) -> Result<RestoringCurve, IdentifyError> {
    let mut samples = Vec::with_capacity(rows.len());
    let mut offset = 0;
    for r in &p.runs {
        let n = r.t.len();
        let phi = signals::shifted(&r.t, r.phi.as_ref().map_or(&[][..], Vec::as_slice), delay);
        let d = r.d.as_ref().map(|d| signals::shifted(&r.t, d, delay));
        for k in 0..n {
            let i = offset + k;
            if rows.binary_search(&i).is_ok() && k < phi.len() {
                samples.push(FitSample {
                    phi: phi[k],
                    tau: target[i],
                    d: d.as_ref().map_or(0.0, |d| d[k]),
                });
            }
        }
        offset += n;
    }
    let fo = FitOptions {
        dead_band: p.dead_band,
        d_tolerance: 1e-4,
        ..FitOptions::default()
    };
    fit_restoring(&samples, &fo)
        .map(|f| f.curve)
        .map_err(|e| IdentifyError::Restoring(e.to_string()))
}

/// The declared model's parameters.
fn base_params(
    model: Declared,
    c: &[f64],
    curve: Option<&RestoringCurve>,
) -> Vec<(&'static str, f64)> {
    match model {
        Declared::Linear => vec![("stiffness_nm_per_rad", c[0]), ("offset_nm", c[1])],
        Declared::Link => vec![("inertia_kgm2", c[0]), ("damping_nms_per_rad", c[1])],
        Declared::Restoring => {
            let mut v = vec![("scale", c[0])];
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

/// Whiteness and cross-correlations of the held-out residual, and what they point to.
fn diagnose(
    p: &Problem,
    s: &Signals,
    rows: &[usize],
    e: &[f64],
    dt: f64,
    opts: &Options,
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
    let mut start = 0;
    let t_abs: Vec<f64> = p.runs.iter().flat_map(|r| r.t.iter().copied()).collect();
    for k in 1..=rows.len() {
        if k == rows.len() || rows[k] != rows[k - 1] + 1 {
            let idx = &rows[start..k];
            let t: Vec<f64> = idx.iter().map(|&i| t_abs[i]).collect();
            let ee = &e[start..k];
            seg_e.extend(signals::uniform_segments(&t, ee, dt, 5.0 * dt));
            for (j, (_, x)) in inputs.iter().enumerate() {
                let xs: Vec<f64> = idx.iter().map(|&i| x[i]).collect();
                seg_in[j].extend(signals::uniform_segments(&t, &xs, dt, 5.0 * dt));
            }
            start = k;
        }
    }
    let n: usize = seg_e.iter().map(|s| s.len()).sum();
    let lags = 50usize;
    // Two-sided 5 % over 50 lags, Bonferroni: z = Φ⁻¹(1 − 0.025/50) = 3.29.
    let band = 3.29 / (n.max(1) as f64).sqrt();
    let autocorr = stats::autocorrelation(&seg_e, lags);
    let (kmax, max_autocorr) = autocorr
        .iter()
        .enumerate()
        .map(|(k, r)| (k + 1, r.abs()))
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
            "the residual is not white: autocorrelation {max_autocorr:.2} at lag {:.3} s (band ±{band:.3}) — slow structure no candidate explains",
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
    Residual {
        white,
        max_autocorr,
        max_autocorr_lag_s: kmax as f64 * dt,
        band,
        lags,
        autocorr,
        cross,
        cross_curves,
        structure,
    }
}
