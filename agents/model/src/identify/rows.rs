//! Rows and roles: the runs checked, tared, concatenated, and each row given its role (fit:
//! train or validate; held out). The tare takes each run's zeros from the rest it starts with.

use super::{Declared, Holdout, IdentifyError, Options, Run, signals};
use crate::hysteresis::{AS5048A_COUNT_RAD, Envelope, RestoringCurve};
use crate::lever::LeverVsa;

/// The role of a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    Train,
    Validate,
    Holdout,
    /// In the weak form, the samples within the widest smoother's half-support of a run's
    /// ends: their smoothed sums are short and their rates one-sided, so their noise is
    /// several times the rest's. They take no part.
    Edge,
}

/// A run's tare: its torque and deflection zeros, the means over the rest it starts with
/// (calibration, not physics: a lab tares). A test that rests at zero command before it
/// moves has its spring unloaded there, up to the friction that holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct Tare {
    pub run: String,
    /// Where the rest segment begins, from the run's first sample [s] (0 unless the sensors
    /// settle first: a start-up sample or transient, left out of the zeros).
    pub from_s: f64,
    /// Length of the rest segment [s].
    pub window_s: f64,
    /// Mean torque at rest, subtracted [N·m].
    pub torque_zero: f64,
    /// Mean deflection at rest, subtracted [rad].
    pub deflection_zero: f64,
    /// Standard deviation of the torque at rest (its noise) [N·m].
    pub torque_noise: f64,
    /// How far this run's rest lies from the first fit run's, through the declared model
    /// fitted untared: the mean residual at rest less the first run's [N·m]. A torque or
    /// encoder zero that moved shows here; so does friction holding the spring elsewhere.
    pub rest_shift_nm: f64,
    /// Whether this run's rest lies within the loop the first fit run traced at its angle:
    /// friction can hold the spring there, so part of the shift may be a load, not a zero.
    pub within_loop: bool,
    /// The state of the loop at rest (the fraction of each stop's half-width its operators
    /// start from) when the rest is read as a state of the loop ([`super::states`]): then the
    /// zeros above are what the loop cannot hold (torque) and the frame's shift (deflection).
    /// `None` under the rest rule, and where the model has no loop (no state to read).
    pub loop_state: Option<f64>,
    /// The file this run was read after, under the same rule: its encoder zeroed at its start
    /// where that file left the spring, it is read from where that file ended unloaded
    /// ([`super::states::continuity`]). `None`: read as measured.
    pub read_after: Option<String>,
    /// A held-out run's torque zero that its rest read and the loop-state rule did not take
    /// [N·m]: with the fit's coefficients the run as measured predicts it better — its rest
    /// was loaded, or the zero moved again within the test ([`super::states`]). `None`: taken,
    /// or nothing to take.
    pub zero_not_taken: Option<f64>,
    /// A held-out run whose deflection is read from its own rest, put where the first fit
    /// run's rest is: its zero moved between the tests, which predicted the run better than the
    /// frame it was given ([`super::states`]). Its `deflection_zero` is then its rest's.
    pub frame_at_rest: bool,
    /// The samples of the rest, within the run.
    pub(crate) rest: (usize, usize),
}

/// The rest segment a run starts with: the samples `start..end`, the median torque and
/// deflection over them, and the torque's noise there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rest {
    pub start: usize,
    pub end: usize,
    pub window_s: f64,
    pub torque: f64,
    pub deflection: f64,
    pub noise: f64,
}

/// The rest a run starts with. Its reference is the medians of deflection and torque over
/// `[0.5 s, 0.75 s)` from the start (past a sensor's start-up: a first sample read before the
/// stream settles, a filter's transient); the rest is every sample around it that stays within
/// a band of that reference (2 % of the run's range, at least three encoder steps, and five
/// times each signal's noise there), back towards the start and forward until the run moves,
/// less 0.1 s at its end. Start-up samples before it are not part of the tare. `None` when the
/// rest is shorter than 0.5 s or 10 samples, or begins later than 0.5 s in: the run starts
/// moving.
pub fn find_rest(r: &Run, resolution: f64) -> Option<Rest> {
    const SETTLE_S: f64 = 0.5;
    const REFERENCE_S: f64 = 0.25;
    let phi = r.phi.as_ref()?;
    let n = r.t.len();
    let t0 = r.t[0];
    let a = r.t.partition_point(|t| *t < t0 + SETTLE_S);
    // At least 5 samples: a logger may pause at its start.
    let b =
        r.t.partition_point(|t| *t < t0 + SETTLE_S + REFERENCE_S)
            .max(a + 5);
    if b > n {
        return None;
    }
    let (median, range) = (super::stats::median, super::stats::span);
    let (x_ref, tau_ref) = (median(&phi[a..b]), median(&r.tau[a..b]));
    // Noise from second differences (6σ² for white noise), blind to a slow motion's trend:
    // a run that moves must not widen its own band.
    let noise = |v: &[f64]| {
        let d2: Vec<f64> = v.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
        super::stats::rmse(&d2) / 6f64.sqrt()
    };
    let band_x = (0.02 * range(phi))
        .max(3.0 * resolution)
        .max(5.0 * noise(&phi[a..b]));
    let band_tau = (0.02 * range(&r.tau)).max(5.0 * noise(&r.tau[a..b]));
    let still =
        |i: usize| (phi[i] - x_ref).abs() <= band_x && (r.tau[i] - tau_ref).abs() <= band_tau;
    if !(a..b).all(still) {
        return None;
    }
    let start = (0..a).rev().find(|&i| !still(i)).map_or(0, |i| i + 1);
    let moved = (b..n).find(|&i| !still(i)).unwrap_or(n);
    let t_end = r.t[moved - 1] - 0.1;
    let end = r.t.partition_point(|t| *t <= t_end);
    if end < start + 10 || t_end - r.t[start] < 0.5 {
        return None;
    }
    Some(Rest {
        start,
        end,
        window_s: r.t[end - 1] - r.t[start],
        // Medians: a motion that starts slowly (a smooth ramp) creeps a few encoder steps
        // while still inside the band, and the mean takes part of that creep as the zero
        // (a lever with a stop then read a torque step where the motion began).
        torque: median(&r.tau[start..end]),
        deflection: median(&phi[start..end]),
        noise: super::stats::std(&r.tau[start..end]),
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
                from_s: r.t[rest.start] - r.t[0],
                rest_shift_nm: 0.0,
                within_loop: false,
                loop_state: None,
                read_after: None,
                zero_not_taken: None,
                frame_at_rest: false,
                rest: (rest.start, rest.end),
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

/// How each run's rest compares with the first's. `rest_residual[k]` is the mean residual over
/// run k's rest of the declared model fitted untared; `reference` is the first run's
/// (deflection, residual) at every sample. Sets `rest_shift_nm` (what the tare corrects, in
/// torque) and `within_loop`: at its rest angle a spring with friction can sit anywhere
/// between its loading and unloading branches, and where the first run, passing within `near`
/// of run k's rest angle, shows residuals that span run k's rest residual (give or take three
/// times the noise at rest), run k's rest could be a load friction holds rather than a zero
/// that moved. The tare still applies (tests that end and start alike leave the spring in the
/// same state at rest); the report says where it may be load.
pub fn compare_rests(
    tares: &mut [Tare],
    rest_residual: &[f64],
    reference: &[(f64, f64)],
    near: f64,
) {
    let Some(first) = tares.first().cloned() else {
        return;
    };
    for (t, r) in tares.iter_mut().zip(rest_residual).skip(1) {
        t.rest_shift_nm = r - rest_residual[0];
        let noise = 3.0 * (t.torque_noise.powi(2) + first.torque_noise.powi(2)).sqrt();
        let (lo, hi) = reference
            .iter()
            .filter(|(x, _)| (x - t.deflection_zero).abs() <= near)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(_, e)| {
                (lo.min(e), hi.max(e))
            });
        t.within_loop = *r >= lo - noise && *r <= hi + noise;
    }
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
    /// The declared restoring model's envelope lines.
    pub envelope: Envelope,
    pub dead_band: f64,
    /// The restoring loop's direction dead band [rad]: one AS5048A count, at most a tenth of
    /// the fit data's swing, at least three of its counts (see [`Problem::new`]).
    pub loop_dead_band: f64,
    /// The restoring loop is fitted beside a torque constant (set by [`super::identify`]):
    /// its lines pass through zero, and on the data as given they could not reach a
    /// deflection read far from its zero (an encoder never re-zeroed), so the "before" holds
    /// an offset, as the linear spring's does.
    pub loop_offset: bool,
    /// Quantisation step of the angle [rad] (0 when not quantised).
    pub resolution: f64,
    /// Each run's angle white noise as measured, rms [rad] (see [`signals::white_noise_rms`]).
    pub noise: Vec<f64>,
    /// The median sampling step [s] (the smallest run's).
    pub step: f64,
    /// Each run's median sampling step [s].
    pub steps: Vec<f64>,
    /// Each run's half-window of [`Problem::denoise`]'s smoothing [s], the median of its
    /// samples' own (0: left as measured; empty: not denoised).
    pub smoothing: Vec<f64>,
    /// Each run's link angle read as the taut string through its counts
    /// ([`signals::taut_string`]).
    pub strung: Vec<bool>,
    pub rate_window: f64,
    /// Rate and acceleration of each run's angle (set with the window).
    pub rates: Vec<(Vec<f64>, Vec<f64>)>,
    /// In the weak form, each run's q̇ for the direction of motion: a local quadratic over
    /// ±[`WEAK_SIGN_WINDOW`] (the smoothed q̇ turns a wide smoother's half-support early).
    pub sign_rates: Vec<Vec<f64>>,
    pub restoring: Option<RestoringCurve>,
    /// Loops the declared model was fitted to from other starts, which fitted the fit rows
    /// less well with nothing added (set by [`super::identify`] where a second start replaced
    /// the first): an encoder slip is also settled from each.
    pub other_starts: Vec<RestoringCurve>,
    /// Half-widths of hysteresis's stop operators [rad].
    pub widths: Vec<f64>,
    /// How many runs are fit runs (the rest are held out).
    pub fit_runs: usize,
    /// Each run's rest (its samples, within the run), when the rests are read as states of
    /// the loop ([`super::states`]).
    pub loop_rests: Option<Vec<(usize, usize)>>,
    /// Each run's hysteresis start state (set by [`super::states::settle`]).
    pub states: Option<Vec<f64>>,
    /// Every run tared at its rest: each run's deflection and torque read zero there.
    pub tared: bool,
    /// Each run's torque zero under the loop-state rule: what the loop cannot hold at rest.
    pub shifts: Vec<f64>,
    /// Each held-out run's torque zero that its rest read but the rule did not take (0: none):
    /// the run as measured predicted it better ([`super::states::settle`]).
    pub untaken: Vec<f64>,
    /// Where each run takes the jumps it does not take at their fitted instant: per run,
    /// (the jump's fitted instant, the run's own [s in the run]; +∞: the run has none). A
    /// held-out run's own instant is read from it as a state ([`super::states::settle`]).
    pub jumps: Vec<Vec<(f64, f64)>>,
    /// What each run's deflection is read with, added to it [rad] (none listed: 0): a
    /// held-out run's frame, chosen by [`super::states::settle`] between the frame it was
    /// given and `other_frames`.
    pub frames: Vec<f64>,
    /// For each held-out run whose encoder frame was carried from the fit runs
    /// ([`super::states::continuity`]): the shift that reads it as measured instead (0: none).
    pub other_frames: Vec<f64>,
    /// For each held-out run: the shift that puts its rest where the first fit run's is (its
    /// zero moved between the tests; 0 for a fit run).
    pub rest_frames: Vec<f64>,
    /// Each run read with its rest where the first fit run's is (`rest_frames`, chosen by
    /// [`super::states::settle`]): it rests in that run's state, and what differs at rest is
    /// a torque zero. None listed: no run.
    pub at_rest: Vec<bool>,
}

/// When run `k` takes the jump fitted at `tj` [s in the run]: its own instant where `jumps`
/// (see [`Problem::jumps`]) holds one, else `tj`.
pub(crate) fn jump_in(jumps: &[Vec<(f64, f64)>], k: usize, tj: f64) -> f64 {
    jumps
        .get(k)
        .and_then(|js| js.iter().find(|(at, _)| *at == tj))
        .map_or(tj, |(_, own)| *own)
}

impl Problem {
    /// When run `k` takes the jump fitted at `tj` [s in the run] ([`Self::jumps`]).
    pub(crate) fn jump_instant(&self, k: usize, tj: f64) -> f64 {
        jump_in(&self.jumps, k, tj)
    }

    /// What run `k`'s deflection is read with ([`Self::frames`]) [rad].
    pub(crate) fn frame(&self, k: usize) -> f64 {
        self.frames.get(k).copied().unwrap_or(0.0)
    }

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
        // The link equation in weak form: each run's ends take no part, nor the ends of the
        // stretches between gaps in its recording (the smoother stops at a gap as at an end).
        if opts.model == Declared::Link {
            let edge = weak_edge(&runs);
            for (k, &(a, _)) in bounds.iter().enumerate() {
                let t = &runs[k].t;
                let gap = signals::GAP_STEPS * signals::median_step(t);
                for piece in signals::unbroken(t, gap) {
                    let (t0, t1) = (t[piece.start], t[piece.end - 1]);
                    for j in piece {
                        if t[j] - t0 < edge || t1 - t[j] < edge {
                            role[a + j] = Role::Edge;
                        }
                    }
                }
            }
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
        // The encoder's own noise, measured before it is averaged away below.
        let noise: Vec<f64> = runs
            .iter()
            .map(|r| signals::white_noise_rms_at(&r.t, &angle_of(r)))
            .collect();
        // The link angle's q̈ in the weak form: a quantised angle read as the taut string
        // through its counts, not as a staircase (see [`signals::taut_string`]) — where the
        // counts are the angle's only error: a white noise of at most 1.5 times the
        // quantisation's (a fast motion's counts read as white noise of a count/√12; an
        // encoder's own noise of a count more than doubles that). A noisier encoder moves
        // readings by more than half a count, and the weak form averages it.
        let mut strung = vec![false; runs.len()];
        if opts.model == Declared::Link && res.is_finite() {
            for ((r, &white), strung) in runs.iter_mut().zip(&noise).zip(&mut strung) {
                if let Some(q) = r.q.as_mut().filter(|q| {
                    white <= 1.5 * res / 12f64.sqrt() && signals::reads_in_counts(q, res)
                }) {
                    *q = signals::taut_string(&r.t, q, res);
                    *strung = true;
                }
            }
        }
        let steps: Vec<f64> = runs.iter().map(|r| signals::median_step(&r.t)).collect();
        let step = steps.iter().copied().fold(f64::INFINITY, f64::min);
        let mut p = Problem {
            runs,
            bounds,
            tau,
            role,
            model: opts.model,
            lever: opts.lever,
            envelope: opts.envelope,
            dead_band,
            loop_dead_band: 0.0,
            loop_offset: false,
            resolution: if res.is_finite() { res } else { 0.0 },
            noise,
            step,
            steps,
            smoothing: vec![],
            strung,
            rate_window: 0.0,
            rates: vec![],
            sign_rates: vec![],
            restoring: None,
            other_starts: vec![],
            widths: vec![],
            fit_runs: fit.len(),
            loop_rests: None,
            tared: false,
            states: None,
            shifts: vec![],
            untaken: vec![],
            jumps: vec![],
            frames: vec![],
            other_frames: vec![],
            rest_frames: vec![],
            at_rest: vec![],
        };
        p.set_rate_window(opts.rate_window.unwrap_or(0.02));
        let (lo, hi) = p.range_of_fit_angle();
        // The restoring loop's direction dead band: one count of the rig's AS5048A, the band
        // the live estimator runs the loop with — but at most a tenth of the fit data's swing,
        // and never under three of the data's own counts. A finer encoder on a stiff spring
        // swings less than a few AS5048A counts (measured spring 5 at 1 N·m: 0.73 mrad in
        // all, its AS5311 14 µrad a count), and a band of 0.38 mrad gave no sample a direction.
        p.loop_dead_band = opts
            .dead_band
            .unwrap_or_else(|| dead_band.max(AS5048A_COUNT_RAD.min(0.1 * (hi - lo))));
        // Hysteresis: stops from ten dead bands (narrower is Coulomb friction) to half the
        // fit data's range, sixteen per the span (on the measured springs the held-out error
        // falls by up to 10 % from eight). But the narrowest at most half the widest: a stop
        // slides only after twice its half-width of travel, and a swing under forty dead bands
        // would get stops that never slide, or none (measured spring 5 at 1 N·m swings
        // 0.73 mrad, 17 dead bands of its AS5311, and got none: its loop of ±0.02 N·m went
        // unnamed). The sign of a rate that slow is the encoder's noise, so Coulomb friction
        // cannot take a narrow stop's place there.
        let widest = 0.5 * (hi - lo);
        let narrowest = (10.0 * dead_band)
            .max((hi - lo) / 1000.0)
            .min((0.5 * widest).max(dead_band));
        p.widths = super::logspace(narrowest, widest, 16);
        p
    }

    /// Sets the half-window of the rates and computes them, run by run: local quadratics over
    /// ±`w` for the joint models (their rates only feed friction and lags); for the link
    /// equation, the weak form with a smoother of half-support `w` (see [`Problem::weak`]):
    /// the torque smoothed, q̇ and q̈ the smoothed rates of local quartics through seven
    /// samples, and the direction of motion from a local quadratic over ±20 ms.
    pub fn set_rate_window(&mut self, w: f64) {
        self.rate_window = w;
        if self.weak() {
            fn q(r: &Run) -> &[f64] {
                r.q.as_deref().unwrap_or(&[])
            }
            // Stretch by stretch between gaps in the recording, each on its whole uniform
            // grid ([`signals::weak_smooth_at`]).
            self.rates = self
                .runs
                .iter()
                .zip(&self.steps)
                .map(|(r, &dt)| signals::weak_rates_at(&r.t, q(r), w, dt))
                .collect();
            self.tau = self
                .runs
                .iter()
                .zip(&self.steps)
                .flat_map(|(r, &dt)| signals::weak_smooth_at(&r.t, &r.tau, w, dt))
                .collect();
            self.sign_rates = self
                .runs
                .iter()
                .map(|r| signals::local_rates(&r.t, q(r), WEAK_SIGN_WINDOW).0)
                .collect();
            return;
        }
        self.rates = self
            .runs
            .iter()
            .map(|r| signals::local_rates(&r.t, r.phi.as_deref().unwrap_or(&[]), w))
            .collect();
    }

    /// Averages the encoder's noise — its own, and its quantisation — out of the joint models'
    /// angle: each run's deflection becomes a local quadratic's value (zero-phase, exact on a
    /// quadratic) over the widest half-window up to the rate window that leaves the motion
    /// alone, and where the motion is slow enough to fill that, each sample's over the widest
    /// up to [`SMOOTHING_CAP`] that its neighbourhood allows ([`signals::smoothing_window`]);
    /// its rates computed again (over the rate window). The spring sees the
    /// true deflection; read raw, an encoder's noise makes every small retreat a reversal of the
    /// loop, and a lag "gains" by averaging the noise it interpolates.
    ///
    /// Where the white noise is over a third of the dead band (a count, by default), or where
    /// the counts themselves reach the torque: the quantisation's error q/√12 through the
    /// model's slope `torque_per_rad`, squared, at least 5 % of the torque sensor's own white
    /// noise `torque_noise` squared (a 14-bit encoder over ±0.06 rad on a linear spring: 12 %
    /// under 0.5 % torque noise, and a lag of the deflection, interpolating the counts,
    /// validated 5 % better than the viscous friction that was there, 3 of 5 seeds; the
    /// table's 16-bit encoder: under 1 %, left as measured). The noise the smoothing is judged
    /// against is at least the quantisation's (a slowly moving quantised angle reads less
    /// white noise than that: its error is a staircase). The link equation's angle is left as
    /// measured. Returns whether any run was smoothed.
    pub fn denoise(&mut self, torque_per_rad: f64, torque_noise: f64) -> bool {
        let quantisation = self.resolution / 12f64.sqrt();
        let noisy = self.angle_noise() > self.dead_band / 3.0;
        let counts_reach_torque =
            (torque_per_rad * quantisation).powi(2) >= 0.05 * torque_noise.powi(2);
        if !self.model.is_joint() || !(noisy || counts_reach_torque) {
            return false;
        }
        let w = self.rate_window;
        self.smoothing = self
            .runs
            .iter_mut()
            .zip(&self.noise)
            .map(|(r, &noise)| {
                let Some(phi) = r.phi.as_mut() else {
                    return 0.0;
                };
                let noise = noise.max(quantisation);
                match signals::smoothing_window(&r.t, phi, noise, w, SMOOTHING_CAP) {
                    Some((h, smoothed)) => {
                        *phi = smoothed;
                        h
                    }
                    None => 0.0,
                }
            })
            .collect();
        self.set_rate_window(w);
        self.smoothing.iter().any(|h| *h > 0.0)
    }

    /// The half-window of the rate whose sign is the direction of motion [s].
    fn sign_window(&self) -> f64 {
        if self.weak() {
            WEAK_SIGN_WINDOW
        } else {
            self.rate_window
        }
    }

    /// The angle's white noise as measured, rms [rad]: the noisiest run's.
    pub fn angle_noise(&self) -> f64 {
        self.noise.iter().copied().fold(0.0, f64::max)
    }

    /// The rate below which the direction of motion is not known [rad/s]: half a count over
    /// the rate window, or three times the rate's own noise where that is larger (a noisy
    /// encoder: a sign taken inside the noise puts the whole friction on the wrong side).
    pub fn still(&self) -> f64 {
        (0.5 * self.resolution / self.sign_window()).max(3.0 * self.rate_noise())
    }

    /// The rms noise of a rate from the angle's white noise [rad/s]: a local fit's slope over
    /// samples at t_j has variance σ² / Σ (t_j − t)² (uniform steps, at least two samples
    /// each side).
    pub fn rate_noise(&self) -> f64 {
        let h = self.sign_window();
        let dt = self.step.max(1e-12);
        let m = (h / dt).floor().max(2.0);
        let sum_sq = dt * dt * m * (m + 1.0) * (2.0 * m + 1.0) / 3.0;
        self.angle_noise() / sum_sq.sqrt()
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

    /// Run `k`'s rate for the direction of motion where it is not the angle's own rate: the
    /// weak form's, from a narrower window than its smoothed q̇ ([`Self::sign_rates`]).
    pub fn weak_sign_rate(&self, k: usize) -> Option<&Vec<f64>> {
        self.sign_rates.get(k).filter(|_| self.weak())
    }

    /// Each fit run's rate whose sign is the direction of motion [rad/s] (the weak form's own
    /// rates on the link equation).
    fn fit_sign_rates(&self) -> impl Iterator<Item = &Vec<f64>> {
        (0..self.fit_runs.min(self.rates.len()))
            .map(|k| self.weak_sign_rate(k).unwrap_or(&self.rates[k].0))
    }

    /// The rms of [`Self::fit_sign_rates`] over the fit runs [rad/s].
    pub fn fit_rate_rms(&self) -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for v in self.fit_sign_rates() {
            sum += v.iter().map(|v| v * v).sum::<f64>();
            n += v.len();
        }
        if n == 0 { 0.0 } else { (sum / n as f64).sqrt() }
    }

    /// The speeds |rate| of [`Self::fit_sign_rates`], sorted [rad/s].
    pub fn fit_speeds(&self) -> Vec<f64> {
        let mut speeds: Vec<f64> = (self.fit_sign_rates().flatten())
            .map(|v| v.abs())
            .filter(|v| v.is_finite())
            .collect();
        speeds.sort_by(f64::total_cmp);
        speeds
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

/// The longest run's duration [s].
pub(crate) fn longest_run(runs: &[Run]) -> f64 {
    runs.iter()
        .map(|r| r.t[r.t.len() - 1] - r.t[0])
        .fold(0.0f64, f64::max)
}

/// The weak form's widest smoother's half-support [s]: the samples this near a run's ends
/// take no part ([`Role::Edge`]; a tenth of the shortest run at most).
pub const WEAK_EDGE: f64 = 0.32;

/// The widest half-window over which [`Problem::denoise`] averages a sample's deflection [s],
/// a bound on the cost: where the motion bends it stops the widening well within this, and on
/// a hold or a straight ramp, where a quadratic is exact, half a second of a slow spring test
/// leaves a sixth of its encoder's noise (measured spring 2 at 1 N·m, 100 Hz: ±0.36 s at the
/// median; the rates' window there, two samples each side, leaves 70 %).
pub const SMOOTHING_CAP: f64 = 0.5;

/// The half-window of the local quadratic giving the weak form's direction of motion [s]
/// (the smoothed q̇ turns a wide smoother's half-support early).
pub const WEAK_SIGN_WINDOW: f64 = 0.02;

impl Problem {
    /// Whether the link equation is fitted in weak form (its `tau` is then the smoothed
    /// torque): it always is. The equation τ = I·q̈ + N·q̇ + Σ effects holds of any one
    /// linear smoother S applied to every term alike, S[τ] = I·S[q̈] + N·S[q̇] + Σ S[effect],
    /// with the same coefficients. So the torque, the rates and every effect's column go
    /// through one smoother of half-support
    /// `rate_window` ([`signals::weak_smooth`]), and q̈ is taken from only seven samples
    /// before it: nothing is flattened (a local quartic over ±80 ms took a 4 Hz motion's q̈
    /// 2 % short, which left 4× the torque noise and brought `gravity` on clean data), while
    /// the counts' noise in q̈ is averaged away as far as the smoother reaches (a lag's jerk
    /// term δ·I·q⃛ then stands above it on slow ramps). The report's RMSEs are of the
    /// smoothed torque.
    pub fn weak(&self) -> bool {
        self.model == Declared::Link
    }

    /// In the weak form, how far from each run's ends samples take no part [s].
    pub fn edge(&self) -> f64 {
        weak_edge(&self.runs)
    }
}

/// [`WEAK_EDGE`], or a tenth of the shortest run where that is less [s].
fn weak_edge(runs: &[Run]) -> f64 {
    runs.iter()
        .map(|r| 0.1 * (r.t[r.t.len() - 1] - r.t[0]))
        .fold(WEAK_EDGE, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn run(t: Vec<f64>, tau: Vec<f64>, phi: Vec<f64>) -> Run {
        Run {
            name: "r".into(),
            t,
            tau,
            phi: Some(phi),
            d: None,
            q: None,
        }
    }

    /// 500 Hz: a first torque sample read as 0, the torque settling to 0.1 N·m with a 0.06 s
    /// time constant, at rest until 3 s, then a ramp of the deflection and the torque.
    fn settling_run() -> Run {
        let t: Vec<f64> = (0..2500).map(|k| k as f64 / 500.0).collect();
        let tau = t
            .iter()
            .enumerate()
            .map(|(k, &t)| match k {
                0 => 0.0,
                _ => 0.1 * (1.0 - (-t / 0.06).exp()) + 2.0 * (t - 3.0).max(0.0),
            })
            .collect();
        let phi = t.iter().map(|&t| 0.01 * (t - 3.0).max(0.0)).collect();
        run(t, tau, phi)
    }

    #[test]
    fn the_loops_dead_band_is_one_as5048a_count_at_most_a_tenth_of_the_swing_and_at_least_three_of_the_datas_counts()
     {
        // 500 Hz swings read by a 14 µrad encoder (a measured spring's AS5311), torque 2500·φ.
        let res = 14e-6;
        let t: Vec<f64> = (0..10_000).map(|k| k as f64 / 500.0).collect();
        let band = |amplitude: f64, res: f64| {
            let phi: Vec<f64> = t
                .iter()
                .map(|&t| (amplitude * (0.5 * TAU * t).sin() / res).round() * res)
                .collect();
            let tau = phi.iter().map(|p| 2500.0 * p).collect();
            let opts = Options {
                model: Declared::Restoring,
                ..Options::default()
            };
            Problem::new(&[run(t.clone(), tau, phi)], &[], &Holdout::Blocks, &opts).loop_dead_band
        };
        // ±10 mrad: the rig's count, as the live estimator runs the loop.
        assert_eq!(band(10e-3, res), AS5048A_COUNT_RAD);
        // ±1 mrad: a tenth of the 2 mrad swing (its counts: within a tenth of one), under
        // the count.
        let b = band(1e-3, res);
        assert!((b - 0.2e-3).abs() < 0.1 * res, "{b} rad");
        // ±0.1 mrad: three of the data's counts, over a tenth of the swing (20 µrad).
        let b = band(0.1e-3, res);
        assert!((b - 3.0 * res).abs() < 1e-3 * res, "{b} rad");
        // Paper B's 14-bit encoder on a lever's ±60 mrad: three of its counts, over the one.
        let count = TAU / 16384.0;
        let b = band(60e-3, count);
        assert!((b - 3.0 * count).abs() < 1e-9, "{b} rad");
    }

    #[test]
    fn a_rest_is_found_past_a_start_up_sample_and_a_settling_transient() {
        let r = settling_run();
        let rest = find_rest(&r, 0.0).expect("the run rests from about 0.2 s to 3 s");
        // Within the band (2 % of the 4.1 N·m range) once 0.1·e^(−t/0.06) < 0.082 N·m.
        let from = r.t[rest.start];
        assert!(from > 0.0 && from < 0.05, "rest starts at {from} s");
        assert!(
            (rest.torque - 0.1).abs() < 2e-3,
            "torque zero {}",
            rest.torque
        );
        // It ends 0.1 s before the ramp leaves the band (0.082 N·m at 2 N·m/s: 41 ms in).
        let end = r.t[rest.end - 1];
        assert!((end - 2.94).abs() < 0.01, "rest ends at {end} s");
    }

    #[test]
    fn a_run_that_moves_from_its_start_has_no_rest() {
        let t: Vec<f64> = (0..3000).map(|k| k as f64 / 100.0).collect();
        let phi: Vec<f64> = t.iter().map(|&t| 0.02 * (0.7 * t + 0.3).sin()).collect();
        let tau = phi.iter().map(|p| 50.0 * p).collect();
        assert_eq!(find_rest(&run(t, tau, phi), 1e-5), None);
    }

    #[test]
    fn a_rest_within_the_loop_the_first_run_traced_there_is_flagged_and_one_outside_is_not() {
        let tare = |noise: f64| Tare {
            run: "r".into(),
            from_s: 0.0,
            window_s: 1.0,
            torque_zero: 0.0,
            deflection_zero: 0.0,
            torque_noise: noise,
            rest_shift_nm: 0.0,
            within_loop: false,
            loop_state: None,
            read_after: None,
            zero_not_taken: None,
            frame_at_rest: false,
            rest: (0, 10),
        };
        // The first run passes the angle 0 on branches 0.5 N·m either side of the model.
        let reference = [(-0.001, 0.5), (0.0, -0.5), (0.002, 0.4), (0.5, 3.0)];
        let mut tares = vec![tare(0.01), tare(0.01), tare(0.01)];
        compare_rests(&mut tares, &[0.1, 0.45, 0.7], &reference, 0.003);
        assert!(!tares[0].within_loop && tares[0].rest_shift_nm == 0.0);
        assert!(tares[1].within_loop);
        assert!((tares[1].rest_shift_nm - 0.35).abs() < 1e-12);
        // 0.7 is above the highest branch (0.5) by more than 3·√2·0.01.
        assert!(!tares[2].within_loop);
        assert!((tares[2].rest_shift_nm - 0.6).abs() < 1e-12);
    }
}
