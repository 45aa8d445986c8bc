//! Rows and roles: the runs checked, tared, concatenated, and each row given its role (fit:
//! train or validate; held out). The tare takes each run's zeros from the rest it starts with.

use super::{Declared, Holdout, IdentifyError, Options, Run, signals};
use crate::hysteresis::RestoringCurve;
use crate::lever::LeverVsa;

/// The role of a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    Train,
    Validate,
    Holdout,
}

/// A run's tare: its torque and deflection zeros, the means over the rest it starts with
/// (calibration, not physics: a lab tares). A test that rests at zero command before it
/// moves has its spring unloaded there, up to the friction that holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct Tare {
    pub run: String,
    /// Length of the rest segment [s].
    pub window_s: f64,
    /// Mean torque at rest, subtracted [N·m].
    pub torque_zero: f64,
    /// Mean deflection at rest, subtracted [rad].
    pub deflection_zero: f64,
    /// Standard deviation of the torque at rest (its noise) [N·m].
    pub torque_noise: f64,
}

/// The rest segment a run starts with: the samples `..end`, the mean torque and deflection
/// over them, and the torque's noise there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rest {
    pub end: usize,
    pub window_s: f64,
    pub torque: f64,
    pub deflection: f64,
    pub noise: f64,
}

/// The rest a run starts with: the longest prefix over which deflection and torque stay within
/// a band of their values in the first 0.25 s (2 % of their range, and at least three encoder
/// steps or five times the torque's noise there), less 0.1 s at its end. `None` when that is
/// shorter than 0.5 s or 10 samples: the run starts moving.
pub fn find_rest(r: &Run, resolution: f64) -> Option<Rest> {
    let phi = r.phi.as_ref()?;
    let n = r.t.len();
    let t0 = r.t[0];
    let head =
        r.t.iter()
            .take_while(|t| **t < t0 + 0.25)
            .count()
            .max(5)
            .min(n);
    let median = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    };
    let range = |v: &[f64]| {
        v.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - v.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    let std = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
    };
    let (x_ref, tau_ref) = (median(&phi[..head]), median(&r.tau[..head]));
    let band_x = (0.02 * range(phi)).max(3.0 * resolution);
    let band_tau = (0.02 * range(&r.tau)).max(5.0 * std(&r.tau[..head]));
    let moved = (0..n)
        .find(|&i| (phi[i] - x_ref).abs() > band_x || (r.tau[i] - tau_ref).abs() > band_tau)
        .unwrap_or(n);
    if moved == 0 {
        return None;
    }
    let t_end = r.t[moved - 1] - 0.1;
    let end = r.t.partition_point(|t| *t <= t_end);
    if end < 10 || t_end - t0 < 0.5 {
        return None;
    }
    Some(Rest {
        end,
        window_s: r.t[end - 1] - t0,
        torque: super::stats::mean(&r.tau[..end]),
        deflection: super::stats::mean(&phi[..end]),
        noise: std(&r.tau[..end]),
    })
}

/// Every run's tare, or none with why: a run tared and another not would carry different
/// zeros, so one run that does not start at rest leaves them all as they are.
pub fn tare(runs: &[Run]) -> (Vec<Tare>, Option<String>) {
    let mut out = Vec::new();
    for r in runs {
        match find_rest(r, resolution(r.phi.as_deref().unwrap_or(&[]))) {
            Some(rest) => out.push(Tare {
                run: r.name.clone(),
                window_s: rest.window_s,
                torque_zero: rest.torque,
                deflection_zero: rest.deflection,
                torque_noise: rest.noise,
            }),
            None => {
                return (
                    vec![],
                    Some(format!(
                        "not tared: {} does not start at rest (at least 0.5 s still), and a tare must treat every file alike",
                        r.name
                    )),
                );
            }
        }
    }
    (out, None)
}

/// The run with the tare's zeros subtracted.
pub fn apply_tare(r: &Run, t: &Tare) -> Run {
    let mut out = r.clone();
    out.tau.iter_mut().for_each(|v| *v -= t.torque_zero);
    if let Some(phi) = out.phi.as_mut() {
        phi.iter_mut().for_each(|v| *v -= t.deflection_zero);
    }
    out
}

/// Everything fixed across candidates: the runs, concatenated, and row roles.
#[derive(Debug, Clone)]
pub(crate) struct Problem {
    pub runs: Vec<Run>,
    pub bounds: Vec<(usize, usize)>,
    pub tau: Vec<f64>,
    pub role: Vec<Role>,
    pub model: Declared,
    pub lever: Option<LeverVsa>,
    pub dead_band: f64,
    /// Quantisation step of the angle [rad] (0 when not quantised).
    pub resolution: f64,
    pub rate_window: f64,
    /// Rate and acceleration of each run's angle (set with the window).
    pub rates: Vec<(Vec<f64>, Vec<f64>)>,
    pub restoring: Option<RestoringCurve>,
    /// Half-widths of hysteresis's stop operators [rad].
    pub widths: Vec<f64>,
    /// How many runs are fit runs (the rest are held out).
    pub fit_runs: usize,
}

impl Problem {
    /// Concatenates the runs (already checked) and assigns roles: whole held-out runs, or
    /// every fourth of `blocks` time blocks of each fit run; of the fit rows, every fourth
    /// block validates.
    pub fn new(fit: &[Run], held: &[Run], holdout: &Holdout<'_>, opts: &Options) -> Self {
        let blocks = opts.blocks.max(4);
        let (mut bounds, mut tau, mut role) = (Vec::new(), Vec::new(), Vec::new());
        let mut runs = Vec::new();
        for (r, is_held) in fit
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
            runs.push(r.clone());
        }
        let joint = opts.model.is_joint();
        let angle_of = |r: &Run| -> Vec<f64> {
            if joint { r.phi.clone() } else { r.q.clone() }.unwrap_or_default()
        };
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
            model: opts.model,
            lever: opts.lever,
            dead_band,
            resolution: if res.is_finite() { res } else { 0.0 },
            rate_window: 0.0,
            rates: vec![],
            restoring: None,
            widths: vec![],
            fit_runs: fit.len(),
        };
        p.set_rate_window(opts.rate_window.unwrap_or(0.02));
        // Hysteresis: stops from ten dead bands (narrower is Coulomb friction) to half the
        // fit data's range, eight per the span.
        let (lo, hi) = p.range_of_fit_angle();
        p.widths = super::logspace(
            (10.0 * dead_band).max((hi - lo) / 1000.0),
            0.5 * (hi - lo),
            8,
        );
        p
    }

    /// Sets the half-window of the rates and computes them, run by run.
    pub fn set_rate_window(&mut self, w: f64) {
        let joint = self.model.is_joint();
        self.rate_window = w;
        self.rates = self
            .runs
            .iter()
            .map(|r| {
                let x = if joint { r.phi.as_ref() } else { r.q.as_ref() };
                signals::local_rates(&r.t, x.map_or(&[][..], Vec::as_slice), w)
            })
            .collect();
    }

    pub fn rows(&self, want: &[Role]) -> Vec<usize> {
        (0..self.tau.len())
            .filter(|&i| want.contains(&self.role[i]))
            .collect()
    }

    /// The smallest and largest angle (deflection or link angle) on the fit rows.
    pub fn range_of_fit_angle(&self) -> (f64, f64) {
        let joint = self.model.is_joint();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (k, r) in self.runs.iter().enumerate().take(self.fit_runs) {
            let x = if joint { r.phi.as_ref() } else { r.q.as_ref() };
            let (a, _) = self.bounds[k];
            for (j, v) in x.map_or(&[][..], Vec::as_slice).iter().enumerate() {
                if self.role[a + j] != Role::Holdout {
                    lo = lo.min(*v);
                    hi = hi.max(*v);
                }
            }
        }
        if lo.is_finite() { (lo, hi) } else { (0.0, 0.0) }
    }

    /// Contiguous stretches of `rows` within runs, as ranges into `rows`.
    pub fn stretches(&self, rows: &[usize]) -> Vec<(usize, usize)> {
        let run_of = |i: usize| self.bounds.iter().position(|&(a, b)| i >= a && i < b);
        let mut out = Vec::new();
        let mut start = 0;
        for k in 1..=rows.len() {
            if k == rows.len()
                || rows[k] != rows[k - 1] + 1
                || run_of(rows[k]) != run_of(rows[k - 1])
            {
                if k > start {
                    out.push((start, k));
                }
                start = k;
            }
        }
        out
    }

    /// The angle column of every row.
    pub fn angle(&self) -> Vec<f64> {
        let joint = self.model.is_joint();
        self.runs
            .iter()
            .flat_map(|r| if joint { r.phi.clone() } else { r.q.clone() }.unwrap_or_default())
            .collect()
    }
}

/// Checks a run's columns for the model.
pub(crate) fn check_run(r: &Run, model: Declared) -> Result<(), IdentifyError> {
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
pub(crate) fn resolution(x: &[f64]) -> f64 {
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

/// The median sampling step over the runs [s] (the smallest run's).
pub(crate) fn sampling_step(runs: &[Run]) -> f64 {
    runs.iter()
        .map(|r| signals::median_step(&r.t))
        .fold(f64::INFINITY, f64::min)
}
