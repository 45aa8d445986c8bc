//! Signals derived from measured series: rates from local polynomial fits (irregular sampling
//! welcome), the direction of motion with a dead band, the stop and play operators of
//! rate-independent hysteresis and backlash, time shifts, and uniform resampling.

/// Rate and acceleration of `x` over time `t` by a local quadratic least-squares fit over the
/// samples within `half_window` seconds of each one (at least two on each side where the
/// series allows). Works on irregular sampling; quantised signals come out smooth.
pub fn local_rates(t: &[f64], x: &[f64], half_window: f64) -> (Vec<f64>, Vec<f64>) {
    local_rates_of_degree(t, x, half_window, 2)
}

/// As [`local_rates`] with a local polynomial of `degree` (2 to 6). Over a centred half-window
/// h a quadratic flattens the acceleration of a sine of angular frequency ω by a share growing
/// as (ωh)², a quartic as (ωh)⁴, at the price of more noise for the same window.
pub fn local_rates_of_degree(
    t: &[f64],
    x: &[f64],
    half_window: f64,
    degree: usize,
) -> (Vec<f64>, Vec<f64>) {
    let (_, v, a) = local_fit_of_degree(t, x, half_window, degree);
    (v, a)
}

/// As [`local_rates_of_degree`], with the local polynomial's value at each sample first: `x`
/// with its white noise averaged over the window (zero-phase; exact on a polynomial of
/// `degree`). Samples the fit cannot reach (fewer than `degree + 1`) keep `x`.
pub fn local_fit_of_degree(
    t: &[f64],
    x: &[f64],
    half_window: f64,
    degree: usize,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let n = t.len();
    let degree = degree.clamp(2, 6);
    let m = degree + 1;
    let (mut v, mut a) = (vec![0.0; n], vec![0.0; n]);
    let side = m.div_ceil(2);
    let mut value = x.to_vec();
    if n < m {
        return (value, v, a);
    }
    let (mut lo, mut hi) = (0usize, 0usize);
    let h = half_window.max(1e-12);
    let mut normal = nalgebra::DMatrix::<f64>::zeros(m, m);
    let mut rhs = nalgebra::DVector::<f64>::zeros(m);
    let mut p = vec![0.0; m];
    for i in 0..n {
        while lo < i.saturating_sub(side) && t[i] - t[lo] > half_window {
            lo += 1;
        }
        while hi + 1 < n && (t[hi + 1] - t[i] <= half_window || hi < i + side) {
            hi += 1;
        }
        // Near the ends, as many samples as the polynomial has coefficients (else the normal
        // equations are singular and the first samples' rates are garbage).
        while hi + 1 - lo < m && hi + 1 < n {
            hi += 1;
        }
        while hi + 1 - lo < m && lo > 0 {
            lo -= 1;
        }
        // Normal equations of x ≈ Σ c_k·s^k, s = (t_j − t_i)/h.
        normal.fill(0.0);
        rhs.fill(0.0);
        for j in lo..=hi {
            let s = (t[j] - t[i]) / h;
            p[0] = 1.0;
            for k in 1..m {
                p[k] = p[k - 1] * s;
            }
            for r in 0..m {
                for c in 0..m {
                    normal[(r, c)] += p[r] * p[c];
                }
                rhs[r] += p[r] * x[j];
            }
        }
        if let Some(c) = normal.clone().lu().solve(&rhs) {
            value[i] = c[0];
            v[i] = c[1] / h;
            a[i] = 2.0 * c[2] / (h * h);
        }
    }
    (value, v, a)
}

/// The weak form's smoother: three centred moving averages of 2m + 1 samples in cascade (a
/// quadratic B-spline of half-support 3m samples, zero-phase), m = h / (3·dt) rounded, at
/// least 1. Near a run's ends each average is over the samples it has (so a constant stays
/// itself). It is one linear operator: applied to the torque and to every column of a linear
/// model alike, τ = Σ cₖ·colₖ stays true of the smoothed series, with the same cₖ.
pub fn weak_smooth(x: &[f64], half_support: f64, dt: f64) -> Vec<f64> {
    let m = weak_m(half_support, dt);
    let mut y = x.to_vec();
    for _ in 0..3 {
        y = moving_average(&y, m);
    }
    y
}

/// The weak form's moving averages' half-width m [samples]: h / (3·dt) rounded, at least 1.
fn weak_m(half_support: f64, dt: f64) -> usize {
    ((half_support / (3.0 * dt.max(1e-12))).round() as usize).max(1)
}

/// A unit impulse, and its sampling instants every `dt`, in the middle of a series long
/// enough that its ends, where the averages are short, see none of the weak form's response.
fn weak_impulse(half_support: f64, dt: f64) -> (Vec<f64>, Vec<f64>) {
    let n = 12 * weak_m(half_support, dt) + 21;
    let mut unit = vec![0.0; n];
    unit[n / 2] = 1.0;
    ((0..n).map(|k| k as f64 * dt).collect(), unit)
}

/// Centred moving average of 2m + 1 samples, over the samples there are near the ends.
fn moving_average(x: &[f64], m: usize) -> Vec<f64> {
    let n = x.len();
    let mut cum = Vec::with_capacity(n + 1);
    cum.push(0.0);
    for v in x {
        cum.push(cum[cum.len() - 1] + v);
    }
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(m), (i + m + 1).min(n));
            (cum[b] - cum[a]) / (b - a) as f64
        })
        .collect()
}

/// Rate and acceleration of `x` at times `t` from the local quartic through its nearest
/// seven samples (the sampling instants as they are: a jitter of a tenth of a step, read as
/// uniform, is a noise proportional to the speed), then [`weak_smooth`]ed with the step `dt`:
/// the weak form's q̇ and q̈, which carry the smoother's response exactly as the smoothed
/// torque does, so a wide smoother averages the counts' noise without flattening the
/// inertia's share.
pub fn weak_rates(t: &[f64], x: &[f64], half_support: f64, dt: f64) -> (Vec<f64>, Vec<f64>) {
    let (v, a) = local_rates_of_degree(t, x, 3.5 * dt, 4);
    (
        weak_smooth(&v, half_support, dt),
        weak_smooth(&a, half_support, dt),
    )
}

/// The white-noise gains of the weak form at half-support `h` and step `dt`: the rms of the
/// smoothed series per unit rms of white noise in it (Σ w²)^½, and of its q̇ and q̈ per unit
/// rms of white noise in the angle. From the impulse responses ([`weak_impulse`]).
pub fn weak_noise_gains(h: f64, dt: f64) -> (f64, f64, f64) {
    let (t, unit) = weak_impulse(h, dt);
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let (v, a) = weak_rates(&t, &unit, h, dt);
    (norm(&weak_smooth(&unit, h, dt)), norm(&v), norm(&a))
}

/// The white-noise gain of the weak form's q̈ with a sensor's first-order filter of time
/// constant `tc` undone on the angle — q̈ + tc·q⃛, the jerk the smoothed q̈'s centred
/// difference, as the model takes it (`Transform::lagged`) — per unit rms of white noise in
/// the angle. At `tc` = 0 it is [`weak_noise_gains`]' own. The jerk's gain is about the
/// acceleration's over the smoother's half-support, so a filter of a tenth of it or more
/// carries the counts' noise through many times (34 ms at 80 ms: 5.5 times).
pub fn weak_acc_gain_undone(h: f64, dt: f64, tc: f64) -> f64 {
    let (t, unit) = weak_impulse(h, dt);
    let (_, a) = weak_rates(&t, &unit, h, dt);
    let jerk = centred_rate(&t, &a);
    (low_pass_undone(&a, &jerk, tc).iter())
        .map(|a| a * a)
        .sum::<f64>()
        .sqrt()
}

/// The autocorrelation ρ(0), ρ(1), … (to where it ends) of white noise through
/// [`weak_smooth`] at half-support `h` and step `dt`: what a weak-form residual that is
/// only noise shows.
pub fn weak_autocorrelation(h: f64, dt: f64) -> Vec<f64> {
    let k = weak_smooth(&weak_impulse(h, dt).1, h, dt);
    let energy: f64 = k.iter().map(|a| a * a).sum();
    (0..=6 * weak_m(h, dt))
        .map(|j| k.iter().zip(&k[j..]).map(|(a, b)| a * b).sum::<f64>() / energy)
        .collect()
}

/// Direction of motion from a centred (zero-lag) rate: sgn(ẋ) where |ẋ| exceeds `still`,
/// 0 where the signal stands still. Offline only: the centred window looks ahead.
pub fn rate_sign(xdot: &[f64], still: f64) -> Vec<f64> {
    xdot.iter()
        .map(|v| if v.abs() > still { v.signum() } else { 0.0 })
        .collect()
}

/// The shortest standstill [s]: a still stretch between opposite motions that lasts this long
/// is a hold, not a reversal passing through the dead band (which lasts 2·still/|ẍ|: under
/// 0.1 s at the slowest turns of the tables' motions; a test machine holds for seconds).
pub const HOLD_S: f64 = 0.2;

/// The direction a stuck contact's friction keeps: [`rate_sign`]'s `dir` with each still stretch
/// (0) given the direction of the motion that entered it, so that dry friction holds its force
/// where the motion stops (a bristle or elastoplastic contact: nothing slides to release it)
/// instead of dropping to 0. Where the motion leaves a hold ([`HOLD_S`] or longer) the other way,
/// the direction turns where the motion out of it starts: where the centred `rate` takes the new
/// sign for good, or earlier, where the torque `tau` steps that way before it ([`torque_turn`]). A
/// motion that starts from rest moves less than a count for a while: the counted angle's rate is
/// exactly 0 there, but the contact has turned and the torque shows it. (Only before the rate's
/// turn: after it, the motion's own torque — the spring's, the inertia's — would be taken for the
/// step.) A reversal through the dead band (a shorter stretch between opposite motions) stays 0 as
/// in `dir`: where in it the rate crossed zero is not known better than the band. A stretch before
/// any motion stays 0 (the contact's state is unknown). `t` [s] increases; an empty `tau` places
/// the turns by the rate alone, and so does a NaN in a hold's torque (a sample not to be used).
pub fn held_sign(t: &[f64], rate: &[f64], dir: &[f64], tau: &[f64]) -> Vec<f64> {
    let mut out = dir.to_vec();
    let n = dir.len().min(rate.len()).min(t.len());
    let mut i = 0;
    while i < n {
        if dir[i] != 0.0 || i == 0 {
            i += 1;
            continue;
        }
        let (a, into) = (i, dir[i - 1]);
        while i < n && dir[i] == 0.0 {
            i += 1;
        }
        if into == 0.0 {
            continue;
        }
        let out_of = if i < n { dir[i] } else { into };
        if out_of == into {
            out[a..i].fill(into);
            continue;
        }
        if t[i - 1] - t[a] < HOLD_S {
            continue;
        }
        let mut turn = i;
        while turn > a && rate[turn - 1] * out_of > 0.0 {
            turn -= 1;
        }
        if tau.len() >= turn {
            turn = torque_turn(&tau[a..turn], out_of).map_or(turn, |k| a + k);
        }
        out[a..turn].fill(into);
        out[turn..i].fill(out_of);
    }
    out
}

/// How many standard errors a torque step within a hold must reach to place a turn
/// ([`torque_turn`]). White noise reaches 6 at one split point with probability 2·10⁻⁹, so at
/// any of a 5000-sample hold's with less than 10⁻⁵ (the union bound).
pub const TURN_STEP_SE: f64 = 6.0;

/// Where in a hold's torque `tau` it steps the way `sign` (±1): the index k that splits it
/// into two constant levels best (the largest between-level sum of squares), when the level
/// after minus the level before has the sign `sign` and reaches [`TURN_STEP_SE`] of its
/// standard error (from the scatter about the two levels). `None` where it does not, or where
/// `tau` holds a NaN (a sample it may not use).
pub fn torque_turn(tau: &[f64], sign: f64) -> Option<usize> {
    let n = tau.len();
    if n < 4 || tau.iter().any(|v| v.is_nan()) {
        return None;
    }
    let mean = tau.iter().sum::<f64>() / n as f64;
    let total: f64 = tau.iter().map(|v| (v - mean).powi(2)).sum();
    let (mut best, mut best_k, mut before) = (0.0, 0, 0.0);
    for (k, v) in tau.iter().enumerate().take(n - 1) {
        before += v - mean;
        let k = k + 1;
        // Between-level sum of squares of the split at k: n·S_k² / (k·(n − k)), S_k the
        // centred sum of the first k.
        let between = n as f64 * before * before / (k * (n - k)) as f64;
        if -before * sign > 0.0 && between > best {
            (best, best_k) = (between, k);
        }
    }
    if best_k == 0 {
        return None;
    }
    let scatter = (total - best).max(0.0) / (n - 2) as f64;
    (best > TURN_STEP_SE * TURN_STEP_SE * scatter).then_some(best_k)
}

/// The stop operator of half-width `r` (an elastic–perfectly-plastic element, a Jenkins
/// element): it follows increments of `x` but stays within ±r, starting at 0. The play
/// operator (backlash of total width 2r) is `x − stop`.
pub fn stop_operator(x: &[f64], r: f64) -> Vec<f64> {
    stop_operator_from(x, r, 0.0)
}

/// The stop operator of half-width `r` starting at `s0` (clamped to ±r): the state a run
/// begins in after the motion that came before it (s0 = +r: it arrived loading from below).
pub fn stop_operator_from(x: &[f64], r: f64, s0: f64) -> Vec<f64> {
    let mut s = s0.clamp(-r.abs(), r.abs());
    let mut prev = x.first().copied().unwrap_or(0.0);
    x.iter()
        .map(|&xi| {
            s = (s + xi - prev).clamp(-r, r);
            prev = xi;
            s
        })
        .collect()
}

pub use crate::live::dead_zone;

/// `x` through a sensor's first-order low-pass of time constant `tc` [s] (T·ẏ = x − y),
/// discretised exactly for an `x` linear between samples (the ramp-invariant form, right at
/// any sampling step). The sensor ran before the first sample: it starts where a ramp of
/// `x`'s slope over its first `tc` would have brought it, x₀ − T·ẋ₀ (from rest, x₀). Started
/// at x₀ mid-motion, the first few time constants carried a transient no sensor has: a 25 ms
/// filter on a linear spring's sines at 1 kHz left 1.43× the noise's rms held out; so
/// started, 1.04×.
pub fn low_passed(t: &[f64], x: &[f64], tc: f64) -> Vec<f64> {
    let n = t.len().min(x.len());
    let mut out = Vec::with_capacity(n);
    let Some(&x0) = x.first() else {
        return out;
    };
    let head = t.partition_point(|&s| s - t[0] <= tc).clamp(2.min(n), n);
    let slope = if tc > 0.0 && head >= 2 {
        line_slope(&t[..head], &x[..head])
    } else {
        0.0
    };
    out.push(x0 - tc * slope);
    for k in 1..n {
        let h = t[k] - t[k - 1];
        let y0 = out[k - 1];
        if !(h > 0.0 && tc > 0.0) {
            out.push(x[k]);
            continue;
        }
        // 1 − a by exp_m1: exact to the last digit at steps much shorter than tc.
        let (a, one_less) = ((-h / tc).exp(), -(-h / tc).exp_m1());
        out.push(a * y0 + x[k] - a * x[k - 1] - tc / h * one_less * (x[k] - x[k - 1]));
    }
    out
}

/// The least-squares slope of `x` over `t` (0 where `t` does not spread).
fn line_slope(t: &[f64], x: &[f64]) -> f64 {
    let n = t.len().min(x.len()) as f64;
    let (mt, mx) = (t.iter().sum::<f64>() / n, x.iter().sum::<f64>() / n);
    let (sxy, sxx) = t.iter().zip(x).fold((0.0, 0.0), |(a, b), (t, x)| {
        (a + (t - mt) * (x - mx), b + (t - mt) * (t - mt))
    });
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

/// The reading of a first-order low-pass of time constant `tc` undone: x + tc·ẋ, with `rate`
/// the reading's rate (the true signal of a sensor that filtered it, F⁻¹·x).
pub fn low_pass_undone(x: &[f64], rate: &[f64], tc: f64) -> Vec<f64> {
    x.iter().zip(rate).map(|(x, v)| x + tc * v).collect()
}

/// The centred difference of `x` over `t` (one-sided at the ends).
pub fn centred_rate(t: &[f64], x: &[f64]) -> Vec<f64> {
    let n = t.len().min(x.len());
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            if b > a && t[b] > t[a] {
                (x[b] - x[a]) / (t[b] - t[a])
            } else {
                0.0
            }
        })
        .collect()
}

/// `x` at times `t − delay` by linear interpolation (held at the ends).
pub fn shifted(t: &[f64], x: &[f64], delay: f64) -> Vec<f64> {
    if delay == 0.0 {
        return x.to_vec();
    }
    // The times t − delay increase with t: walk one index along instead of searching.
    let mut k = 0usize;
    t.iter()
        .map(|&ti| interp_walk(t, x, ti - delay, &mut k))
        .collect()
}

/// Linear interpolation of (t, x) at `at`, held at the ends, starting the search for the
/// segment at `k` and leaving `k` there for the next, later `at`.
fn interp_walk(t: &[f64], x: &[f64], at: f64, k: &mut usize) -> f64 {
    let n = t.len().min(x.len());
    if n == 0 {
        return f64::NAN;
    }
    if at <= t[0] {
        return x[0];
    }
    if at >= t[n - 1] {
        return x[n - 1];
    }
    while *k + 1 < n && t[*k + 1] <= at {
        *k += 1;
    }
    let (t0, t1) = (t[*k], t[*k + 1]);
    let w = if t1 > t0 { (at - t0) / (t1 - t0) } else { 0.0 };
    x[*k] + w * (x[*k + 1] - x[*k])
}

/// Linear interpolation of (t, x) at `at`; `t` increasing; held at the ends.
pub fn interp(t: &[f64], x: &[f64], at: f64) -> f64 {
    let mut k = t.partition_point(|&v| v <= at).saturating_sub(1);
    interp_walk(t, x, at, &mut k)
}

/// A step longer than this many median steps is a gap in the recording (dropped packets, a
/// paused logger): no sample was taken there.
pub const GAP_STEPS: f64 = 5.0;

/// The stretches of `t` sampled without a break: index ranges between the steps longer than
/// `max_gap` (one range, the whole series, where there is none).
pub fn unbroken(t: &[f64], max_gap: f64) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=t.len() {
        if i == t.len() || t[i] - t[i - 1] > max_gap {
            out.push(start..i);
            start = i;
        }
    }
    out
}

/// `f` applied to each stretch of `t` sampled without a break ([`unbroken`] at
/// [`GAP_STEPS`] steps `dt`), the results concatenated: a smoother or a rate does not reach
/// across a gap in the recording as if its two sides were neighbours.
pub fn by_stretch(
    t: &[f64],
    dt: f64,
    mut f: impl FnMut(std::ops::Range<usize>) -> Vec<f64>,
) -> Vec<f64> {
    unbroken(t, GAP_STEPS * dt)
        .into_iter()
        .flat_map(&mut f)
        .collect()
}

/// One unbroken stretch of samples and the uniform grid of step `dt` over it, from its first
/// instant to its last (within a step before it, never past it: a value there would be held,
/// not read between samples): the weak form's smoother is a sum over evenly
/// spaced values, so a stretch sampled unevenly — jittered instants, dropped samples — is read
/// onto the grid, smoothed there, and read back at its own instants.
struct Grid<'a> {
    at: &'a [f64],
    t: Vec<f64>,
}

impl<'a> Grid<'a> {
    fn of(at: &'a [f64], dt: f64) -> Self {
        let span = at.last().zip(at.first()).map_or(0.0, |(b, a)| b - a);
        let n = (span / dt + 1e-9).floor() as usize + 1;
        let t0 = at.first().copied().unwrap_or(0.0);
        Grid {
            at,
            t: (0..n).map(|k| t0 + k as f64 * dt).collect(),
        }
    }

    /// `x` (one value a sample) on the grid, linear between the samples either side.
    fn fill(&self, x: &[f64]) -> Vec<f64> {
        resampled(self.at, x, &self.t)
    }

    /// `y` (one value a grid instant) at the samples' instants, linear between grid instants.
    fn pick(&self, y: &[f64]) -> Vec<f64> {
        resampled(&self.t, y, self.at)
    }
}

/// (t, x) read at the increasing instants `at` by linear interpolation, held at the ends.
fn resampled(t: &[f64], x: &[f64], at: &[f64]) -> Vec<f64> {
    let mut k = 0;
    at.iter().map(|&a| interp_walk(t, x, a, &mut k)).collect()
}

/// Whether `t` is its own uniform grid of step `dt` (every step `dt` to rounding): then the
/// smoother runs on the samples as they are. So it does where `dt` is no step (not positive
/// and finite): no grid can be laid.
fn on_its_grid(t: &[f64], dt: f64) -> bool {
    !(dt > 0.0 && dt.is_finite()) || t.windows(2).all(|w| (w[1] - w[0] - dt).abs() <= 1e-6 * dt)
}

/// [`weak_smooth`] of `x` sampled at the instants `t` with the step `dt`: stretch by stretch
/// between gaps ([`by_stretch`]), each read onto its uniform grid ([`Grid`]: linear between
/// samples, over a dropped one too), smoothed there and read back at the samples' instants. The
/// smoother is a sum over evenly spaced values; the weak form needs that, not only the same
/// operator on both sides: the angle's q̈ (a counted angle read as the taut string, whose q̈ is
/// its bends) is a derivative, and its weighted sum sums by parts into the angle only where the
/// values are evenly spaced. Summed over jittered samples it does not: a jitter of ±0.45 of a
/// step at 1 kHz left a clean link 46 times its floor on even samples, ±0.24 nine times (and a
/// tenth of a 14-bit link's samples dropped, 4 times its held-out error). Reading back is the
/// same linear operator for the torque and every column, so the weak form still holds term by
/// term; a value read onto the grid errs by at most h²·ẍ/8, which a second difference's
/// weights (summing to 0) cancel once smoothed.
pub fn weak_smooth_at(t: &[f64], x: &[f64], half_support: f64, dt: f64) -> Vec<f64> {
    if on_its_grid(t, dt) {
        return weak_smooth(x, half_support, dt);
    }
    by_stretch(t, dt, |s| {
        let g = Grid::of(&t[s.clone()], dt);
        g.pick(&weak_smooth(&g.fill(&x[s]), half_support, dt))
    })
}

/// [`weak_rates`] of `x` sampled at the instants `t`, as [`weak_smooth_at`] smooths: stretch by
/// stretch, each read onto its uniform grid, its rates taken and smoothed there, and read back.
pub fn weak_rates_at(t: &[f64], x: &[f64], half_support: f64, dt: f64) -> (Vec<f64>, Vec<f64>) {
    if on_its_grid(t, dt) {
        return weak_rates(t, x, half_support, dt);
    }
    let mut a = Vec::with_capacity(t.len());
    let v = by_stretch(t, dt, |s| {
        let g = Grid::of(&t[s.clone()], dt);
        let (v, acc) = weak_rates(&g.t, &g.fill(&x[s]), half_support, dt);
        a.extend(g.pick(&acc));
        g.pick(&v)
    });
    (v, a)
}

/// Resamples (t, x) onto a uniform grid of step `dt`, splitting at gaps longer than
/// `max_gap`: returns the uniform segments.
pub fn uniform_segments(t: &[f64], x: &[f64], dt: f64, max_gap: f64) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    for piece in unbroken(t, max_gap) {
        let (ts, xs) = (&t[piece.clone()], &x[piece]);
        if ts.len() >= 2 && dt > 0.0 {
            let n = ((ts[ts.len() - 1] - ts[0]) / dt).floor() as usize + 1;
            out.push(
                (0..n)
                    .map(|k| interp(ts, xs, ts[0] + k as f64 * dt))
                    .collect(),
            );
        }
    }
    out
}

/// The rms of a signal's white noise (an encoder's own noise, or its quantisation where the
/// signal moves counts per sample), from the mean absolute fourth difference: for white noise
/// of rms σ, x[i−2] − 4x[i−1] + 6x[i] − 4x[i+1] + x[i+2] has rms σ·√70 and mean absolute
/// value σ·√70·√(2/π). It is 35/3 of the residual of a five-sample local quadratic, so a
/// motion's cubics cancel and only its fourth derivative (x⁗·dt⁴) remains: a fast motion
/// sampled slowly is not read as noise. A slowly moving quantised signal (a step every few
/// samples) reads as a fraction of a count. Assumes near-uniform sampling (where the instants
/// are known, [`white_noise_rms_at`]).
pub fn white_noise_rms(x: &[f64]) -> f64 {
    fourth_difference_rms(x.windows(5))
}

/// [`white_noise_rms`] of `x` sampled at the instants `t`: on each five samples the fourth
/// divided difference on their own instants, which cancels a cubic at any spacing, over its
/// gain for white noise (on even steps exactly the fourth difference over √70). By index a
/// jittered sampling reads the motion's ẋ·(jitter) as noise, and across a dropped sample the
/// motion's cubic does not cancel (a 250 Hz multi-sine with a tenth of its samples dropped read
/// 1.5 times its noise, and its counted angle was no longer read as the taut string through its
/// counts). Five samples that span a gap in the recording ([`GAP_STEPS`]) are left out.
pub fn white_noise_rms_at(t: &[f64], x: &[f64]) -> f64 {
    let gap = GAP_STEPS * median_step(t);
    let n = x.len().min(t.len());
    let d: Vec<f64> = (0..n.saturating_sub(4))
        .filter_map(|k| {
            let (t, x) = (&t[k..k + 5], &x[k..k + 5]);
            if t.windows(2).any(|s| !(s[1] > s[0] && s[1] - s[0] <= gap)) {
                return None;
            }
            let w: [f64; 5] = std::array::from_fn(|i| {
                1.0 / (0..5)
                    .filter(|&j| j != i)
                    .map(|j| t[i] - t[j])
                    .product::<f64>()
            });
            let gain = w.iter().map(|w| w * w).sum::<f64>().sqrt();
            Some(w.iter().zip(x).map(|(w, x)| w * x).sum::<f64>().abs() / gain)
        })
        .collect();
    if d.is_empty() {
        return white_noise_rms(x);
    }
    super::stats::mean(&d) / (2.0 / std::f64::consts::PI).sqrt()
}

/// σ from the mean absolute fourth difference of the windows (see [`white_noise_rms`]).
fn fourth_difference_rms<'a>(windows: impl Iterator<Item = &'a [f64]>) -> f64 {
    let d: Vec<f64> = windows
        .map(|w| (w[0] - 4.0 * w[1] + 6.0 * w[2] - 4.0 * w[3] + w[4]).abs())
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    super::stats::mean(&d) / (70f64.sqrt() * (2.0 / std::f64::consts::PI).sqrt())
}

/// The widest half-window, up to `widest`, over which a local quadratic averages white noise of
/// rms `noise` out of `x` without taking the motion with it, with `x` so smoothed; `None` where
/// even two samples each side take the motion. Half-windows of m samples each side (m = 2, 3,
/// 4, 6, 9, …) are widened while the residual x − x̂ stays within 10 % of the noise's own share
/// of it, σ·√(1 − c₀) (c₀ = 3(3m² + 3m − 1)/((2m − 1)(2m + 1)(2m + 3)), the weight of the
/// centre sample): beyond that the fit flattens the motion (a smoothing bias of half the
/// noise's rms lifts the residual by 10 %). A fast multi-sine at 1 kHz stops at a few
/// milliseconds where a slow spring test takes a wide window.
///
/// Where the whole run's check reaches `local_from` (the rates' window), each sample's window
/// is then widened on its own, up to `widest`, by the intersection of confidence intervals
/// (Katkovnik's ICI rule): the value of each wider quadratic, ± 1.5 of its own noise σ·√c₀,
/// must share a point with those of all the narrower ones; at the first that does not, the
/// sample keeps the last window that did. On a ramp or a hold a quadratic is exact and the
/// intervals nest as they shrink, so the noise is averaged over the motion's own scale; near
/// a corner — a reversal, a slip, the end of a ramp — the wider values walk off by their
/// bias, so the corner keeps a narrow window. Over the whole run alone a few rounded corners
/// hide among thousands of samples a quadratic fits exactly, and a corner is where a loop
/// or a stop shows. The half-window returned is then the median of the samples' own.
pub fn smoothing_window(
    t: &[f64],
    x: &[f64],
    noise: f64,
    local_from: f64,
    widest: f64,
) -> Option<(f64, Vec<f64>)> {
    let dt = median_step(t);
    if !(dt > 0.0 && noise > 0.0) || x.len() < 5 {
        return None;
    }
    let centre = |m: usize| {
        let mf = m as f64;
        3.0 * (3.0 * mf * mf + 3.0 * mf - 1.0)
            / ((2.0 * mf - 1.0) * (2.0 * mf + 1.0) * (2.0 * mf + 3.0))
    };
    let next = |m: usize| (m * 3 / 2).max(m + 1);
    // How far the whole run's check reaches: the rates' window, or `widest` if narrower.
    let whole_run = local_from.min(widest);
    let mut best: Option<(usize, f64, Vec<f64>)> = None;
    let mut m = 2usize;
    loop {
        let h = (m as f64 + 0.5) * dt;
        if h > whole_run && m > 2 {
            break;
        }
        let (fit, _, _) = local_fit_of_degree(t, x, h, 2);
        let r: Vec<f64> = x.iter().zip(&fit).map(|(a, b)| a - b).collect();
        if super::stats::rmse(&r) > 1.1 * noise * (1.0 - centre(m)).sqrt() {
            break;
        }
        best = Some((m, h.min(whole_run.max(2.5 * dt)), fit));
        m = next(m);
    }
    let (base, h, mut value) = best?;
    // Stopped by the motion, not by the rates' window: no wider window.
    if (next(base) as f64 + 0.5) * dt <= whole_run || widest <= local_from {
        return Some((h, value));
    }
    // One and a half of each value's own noise: a corner keeps a bias under the noise (a 10 s
    // triangle under 0.2 mrad: 0.93 σ at its reversals, against 4.1 σ at the whole run's
    // ±211 ms; at two, 1.3 σ, and a generator's hysteresis under two counts of noise left twice
    // its clean twin's error, 1.2× at 1.5).
    let sd = |m: usize| 1.5 * noise * centre(m).sqrt();
    let mut lo: Vec<f64> = value.iter().map(|v| v - sd(base)).collect();
    let mut hi: Vec<f64> = value.iter().map(|v| v + sd(base)).collect();
    let mut own = vec![h; x.len()];
    let mut open = vec![true; x.len()];
    let mut m = next(base);
    while (m as f64 + 0.5) * dt <= widest && 2 * m < x.len() && open.iter().any(|o| *o) {
        let w = (m as f64 + 0.5) * dt;
        let (fit, _, _) = local_fit_of_degree(t, x, w, 2);
        for (i, f) in fit.iter().enumerate() {
            if !open[i] {
                continue;
            }
            let (l, u) = (lo[i].max(f - sd(m)), hi[i].min(f + sd(m)));
            if l > u {
                open[i] = false;
            } else {
                (lo[i], hi[i], value[i], own[i]) = (l, u, *f, w);
            }
        }
        m = next(m);
    }
    own.sort_by(f64::total_cmp);
    Some((own[own.len() / 2], value))
}

/// Whether `x` reads in whole counts of `count` (from some zero): 95 % of its changes
/// within 1 % of a whole number of counts.
pub fn reads_in_counts(x: &[f64], count: f64) -> bool {
    if count.is_nan() || count <= 0.0 {
        return false;
    }
    let changes: Vec<f64> = x
        .windows(2)
        .map(|w| (w[1] - w[0]) / count)
        .filter(|d| d.abs() > 1e-9)
        .collect();
    !changes.is_empty()
        && changes
            .iter()
            .filter(|d| (*d - d.round()).abs() < 0.01)
            .count()
            * 20
            >= changes.len() * 19
}

/// A quantised angle read as the taut string through its counts: the shortest path that
/// stays within half a count of every reading (at each sample, between the readings' bounds;
/// straight between samples). A quantised reading's error is not white: where the angle moves
/// less than a count per sample it is a staircase, and where it moves near a whole number of
/// counts per sample it is a sawtooth of a count's height whose period, a count over the
/// speed's distance to that whole number, sweeps through any smoother's pass band as the
/// motion speeds up and slows down — through q̈, jumps of a count. What the readings know is
/// that the angle was within half a count of each; the taut string is the straightest path
/// they allow: it bends only where the counts make it, it crosses from one count to the next
/// between the samples where the reading changed, and it never jumps. (The funnel of slopes
/// from the last bend: the path bends at the bound that closes it.) `t` must increase
/// strictly, as [`super::identify`] checks of every run.
pub fn taut_string(t: &[f64], x: &[f64], count: f64) -> Vec<f64> {
    let n = x.len();
    if n < 3 || count.is_nan() || count <= 0.0 {
        return x.to_vec();
    }
    // Neither end is pinned to its reading (a reading is half a count from the angle): each
    // pass starts on its first reading and runs free at its last, and the first half comes
    // from the pass run backwards in time. Away from the ends the two are the same string.
    let forward = string_free_at_the_end(t, x, count);
    let (tr, xr): (Vec<f64>, Vec<f64>) = t.iter().rev().map(|t| -t).zip(x.iter().rev()).unzip();
    let backward = string_free_at_the_end(&tr, &xr, count);
    (0..n)
        .map(|i| {
            if i < n / 2 {
                backward[n - 1 - i]
            } else {
                forward[i]
            }
        })
        .collect()
}

/// The taut string from the first reading, its last segment as flat as the funnel lets it
/// run (see [`taut_string`]).
fn string_free_at_the_end(t: &[f64], x: &[f64], count: f64) -> Vec<f64> {
    let n = x.len();
    let half = 0.5 * count;
    let mut out = x.to_vec();
    let (mut a, mut va) = (0usize, x[0]);
    while a + 1 < n {
        // The funnel from the apex (t[a], va): the least slope to an upper bound and the
        // greatest to a lower one, with where each was reached.
        let (mut up, mut iu) = (f64::INFINITY, a);
        let (mut lo, mut il) = (f64::NEG_INFINITY, a);
        let mut bend = None;
        for k in a + 1..n {
            let dt = t[k] - t[a];
            let (su, sl) = ((x[k] + half - va) / dt, (x[k] - half - va) / dt);
            if sl > up {
                // The lower bound rises above every line under the upper ones: bend down at
                // the upper bound that set the least slope.
                bend = Some((iu, x[iu] + half));
                break;
            }
            if su < lo {
                bend = Some((il, x[il] - half));
                break;
            }
            if su < up {
                (up, iu) = (su, k);
            }
            if sl > lo {
                (lo, il) = (sl, k);
            }
        }
        let (b, vb) = match bend {
            Some((b, vb)) if b > a => (b, vb),
            _ => {
                // Open to the end: as flat as the funnel allows (a run ends at rest, or
                // moving, where the next bend is a few samples away).
                let s = if lo <= up { 0.0f64.clamp(lo, up) } else { 0.0 };
                let b = n - 1;
                (b, va + s * (t[b] - t[a]))
            }
        };
        for k in a + 1..=b {
            out[k] = va + (vb - va) * (t[k] - t[a]) / (t[b] - t[a]);
        }
        (a, va) = (b, vb);
    }
    out
}

/// The median of the positive steps of `t`.
pub fn median_step(t: &[f64]) -> f64 {
    let d: Vec<f64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    super::stats::median(&d)
}

/// Sudden steps of a signal: sample-to-sample changes over ten times the 90th percentile of
/// all changes, counted once per burst (within 3 samples). In a slow, smooth test these are
/// stick-slip events (the spring sticks, then slips) or sensor glitches.
pub fn steps(x: &[f64]) -> usize {
    let d: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    if d.len() < 20 {
        return 0;
    }
    let mut sorted = d.clone();
    sorted.sort_by(f64::total_cmp);
    let p90 = sorted[sorted.len() * 9 / 10];
    if p90 <= 0.0 {
        return 0;
    }
    let mut count = 0;
    let mut last: Option<usize> = None;
    for (i, v) in d.iter().enumerate() {
        if *v > 10.0 * p90 {
            if last.is_none_or(|l| i > l + 3) {
                count += 1;
            }
            last = Some(i);
        }
    }
    count
}

/// The speeds a test moves at: over runs given as (time [s], deflection [rad]), the rate as
/// a difference over `span_s` (long enough that a count of the encoder is a small part of it),
/// and, over the samples that move (a rate over a fifth of the 95th percentile of |rate|), the
/// 20th and 80th percentiles of |rate| [rad/s]. `None` where fewer than 20 samples move.
///
/// A triangle wave moves at one speed (the two nearly equal): there a torque in proportion to
/// the rate, viscous friction or a lag, is a constant height on each stroke, the shape of dry
/// friction or of the loop, and the fit cannot tell them apart. A sine's are 0.46 and 0.96 of
/// its peak rate.
pub fn speeds<'a>(
    runs: impl IntoIterator<Item = (&'a [f64], &'a [f64])>,
    span_s: f64,
) -> Option<(f64, f64)> {
    let mut rates = Vec::new();
    for (t, x) in runs {
        let mut j = 0;
        for i in 0..t.len() {
            j = j.max(i + 1);
            while j < t.len() && t[j] - t[i] < span_s {
                j += 1;
            }
            if j == t.len() {
                break;
            }
            let r = (x[j] - x[i]) / (t[j] - t[i]);
            if r.is_finite() {
                rates.push(r.abs());
            }
        }
    }
    if rates.len() < 20 {
        return None;
    }
    rates.sort_by(f64::total_cmp);
    let p95 = rates[rates.len() * 95 / 100];
    let moving: Vec<f64> = rates.into_iter().filter(|r| *r > 0.2 * p95).collect();
    if moving.len() < 20 {
        return None;
    }
    Some((moving[moving.len() / 5], moving[moving.len() * 4 / 5]))
}

/// Uniform numbers in [0, 1) from a tiny LCG: the identify tests' own, reproducible noise.
#[cfg(test)]
pub(crate) fn uniforms(mut state: u64) -> impl FnMut() -> f64 {
    move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of x(t) at `rate_hz` over `secs`.
    fn sampled(x: impl Fn(f64) -> f64, rate_hz: f64, secs: f64) -> (Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..(rate_hz * secs) as usize)
            .map(|k| k as f64 / rate_hz)
            .collect();
        let v = t.iter().map(|&t| x(t)).collect();
        (t, v)
    }

    #[test]
    fn a_triangle_wave_moves_at_one_speed_and_a_sine_over_the_spread_its_cosine_gives() {
        use std::f64::consts::PI;
        // A 0.3 Hz triangle of ±0.1 rad at 500 Hz: 4·0.1·0.3 = 0.12 rad/s on every stroke.
        let tri = sampled(
            |t| 0.1 * (2.0 / PI) * (2.0 * PI * 0.3 * t).sin().asin(),
            500.0,
            30.0,
        );
        let (lo, hi) = speeds([(&tri.0[..], &tri.1[..])], 0.05).unwrap();
        assert!(
            (lo / 0.12 - 1.0).abs() < 0.01 && (hi / 0.12 - 1.0).abs() < 0.01,
            "{lo} {hi}"
        );
        // A sine's |rate| is its peak times |cos θ|, θ uniform: P(|cos θ| < c) = 1 − (2/π)·acos c.
        // The moving samples are those over a fifth of the 95th percentile, cos(0.05·π/2).
        let quantile = |p: f64| (PI / 2.0 * (1.0 - p)).cos();
        let cut = 0.2 * quantile(0.95);
        let below = 1.0 - 2.0 / PI * cut.acos();
        let (want_lo, want_hi) = (
            quantile(below + 0.2 * (1.0 - below)),
            quantile(below + 0.8 * (1.0 - below)),
        );
        let w = 2.0 * PI * 0.5;
        let sine = sampled(|t| 0.1 * (w * t).sin(), 1000.0, 40.0);
        let (lo, hi) = speeds([(&sine.0[..], &sine.1[..])], 0.01).unwrap();
        // The difference over 10 ms reads the peak rate 0.1·ω low by sinc(ω·5 ms) ≈ 0.99996.
        assert!(
            (lo / (0.1 * w) - want_lo).abs() < 0.005,
            "{lo} against {}",
            want_lo * 0.1 * w
        );
        assert!(
            (hi / (0.1 * w) - want_hi).abs() < 0.005,
            "{hi} against {}",
            want_hi * 0.1 * w
        );
        assert!(hi / lo > 1.9);
        // Too short to tell: no answer, not a guess.
        assert_eq!(speeds([(&sine.0[..10], &sine.1[..10])], 0.01), None);
    }

    #[test]
    fn local_rates_are_exact_on_a_parabola_with_irregular_steps() {
        // x = 3 + 2t − 5t²: ẋ = 2 − 10t, ẍ = −10, at irregular times.
        let t: Vec<f64> = (0..200)
            .map(|k| k as f64 * 0.01 + 0.003 * ((k * 7 % 5) as f64))
            .collect();
        let x: Vec<f64> = t.iter().map(|t| 3.0 + 2.0 * t - 5.0 * t * t).collect();
        let (value, v, a) = local_fit_of_degree(&t, &x, 0.03, 2);
        for i in 0..t.len() {
            assert!((value[i] - x[i]).abs() < 1e-9, "{i}: {}", value[i]);
            assert!((v[i] - (2.0 - 10.0 * t[i])).abs() < 1e-8, "{i}: {}", v[i]);
            assert!((a[i] + 10.0).abs() < 1e-6, "{i}: {}", a[i]);
        }
        assert_eq!(local_rates(&t, &x, 0.03), (v, a));
    }

    /// Gaussian samples from a fixed seed (xorshift and Box–Muller), to need no crate.
    fn gauss(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed.max(1);
        let mut uniform = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| {
                let (u, w) = (uniform(), uniform());
                (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * w).cos()
            })
            .collect()
    }

    #[test]
    fn the_smoothing_window_widens_on_a_slow_motion_and_stays_narrow_on_a_fast_one() {
        // 0.2 mrad of noise at 1 kHz. On a 1 Hz swing of 0.1 rad a ±20 ms quadratic flattens
        // the motion by well under a µrad: the whole window. On a 15 Hz swing of 0.1 rad the ±20 ms
        // quadratic would lose a tenth of the amplitude (its residual ≫ the noise's share):
        // the window stops where the flattening is still under half the noise's rms.
        let n = 20_000;
        let noise = gauss(n, 11);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let swing = |f: f64| -> Vec<f64> {
            (0..n)
                .map(|k| 0.1 * (std::f64::consts::TAU * f * t[k]).sin() + 2e-4 * noise[k])
                .collect()
        };
        let slow = swing(1.0);
        let (h, _) = smoothing_window(&t, &slow, white_noise_rms(&slow), 0.02, 0.02).unwrap();
        // m = 2, 3, 4, 6, 9, 13, 19 samples each side: 19.5 ms, the widest within 20 ms.
        assert!((h - 0.0195).abs() < 1e-9, "{h}");
        let fast = swing(15.0);
        let (h, smooth) = smoothing_window(&t, &fast, white_noise_rms(&fast), 0.02, 0.02).unwrap();
        assert!(h > 0.0 && h < 0.012, "{h}");
        assert_eq!(smooth, local_fit_of_degree(&t, &fast, h, 2).0);
        let bias: Vec<f64> = (100..n - 100)
            .map(|k| smooth[k] - 0.1 * (std::f64::consts::TAU * 15.0 * t[k]).sin())
            .collect();
        // Still less than the noise it started with, flattening included.
        assert!(crate::identify::stats::rmse(&bias) < 0.8 * 2e-4);
        // No noise: nothing to average out.
        assert!(smoothing_window(&t, &slow, 0.0, 0.02, 0.02).is_none());
    }

    #[test]
    fn past_the_rate_window_each_sample_is_smoothed_as_wide_as_its_motion_allows_and_corners_stay_sharp()
     {
        // A 10 s triangle of ±0.05 rad (0.02 rad/s, reversing by Δv = 0.04 rad/s) under
        // σ = 0.2 mrad of noise at 1 kHz, over 30 s: five corners. On its straight ramps a
        // quadratic is exact, so over the whole run the residual stays near the noise's share
        // far out; at a corner a quadratic over ±h misses the kink by Δv·3h/32 (the projection
        // of max(s, 0) on 1, s, s² − h²/3 at s = 0), past 2σ beyond ±107 ms.
        let (n, sigma) = (30_000, 2e-4);
        let noise = gauss(n, 5);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let triangle = |t: f64| {
            let u = (t / 10.0).rem_euclid(1.0);
            0.05 * if u < 0.5 {
                4.0 * u - 1.0
            } else {
                3.0 - 4.0 * u
            }
        };
        let x: Vec<f64> = (0..n).map(|k| triangle(t[k]) + sigma * noise[k]).collect();
        let error = |smooth: &[f64], k: usize| (smooth[k] - triangle(t[k])).abs();
        let corners: Vec<usize> = (1..6).map(|c| c * 5_000).collect();
        let worst_corner = |smooth: &[f64]| {
            corners
                .iter()
                .map(|&k| error(smooth, k))
                .fold(0.0, f64::max)
        };
        // Mid-ramp, a second from any corner.
        let ramps: Vec<usize> = (0..n)
            .filter(|k| (k % 5_000).abs_diff(2_500) < 1_500)
            .collect();
        let ramp_rms = |smooth: &[f64]| {
            (ramps.iter().map(|&k| error(smooth, k).powi(2)).sum::<f64>() / ramps.len() as f64)
                .sqrt()
        };
        // The whole run's check alone (no sample widened on its own): one wide window, the
        // corners rounded by the closed form's bias.
        let (whole, smooth) = smoothing_window(&t, &x, sigma, 0.5, 0.5).unwrap();
        let kink = 0.04 * 3.0 * whole / 32.0;
        assert!(whole > 0.107 && kink > 2.0 * sigma, "{whole}");
        assert!(
            (worst_corner(&smooth) / kink - 1.0).abs() < 0.25,
            "{}",
            worst_corner(&smooth)
        );
        // Sample by sample past ±20 ms: the ramps as wide (their noise averaged to under a
        // tenth), the corners within the noise.
        let (median, own) = smoothing_window(&t, &x, sigma, 0.02, 0.5).unwrap();
        assert!(median > 0.107, "{median}");
        assert!(ramp_rms(&own) < 0.1 * sigma, "{}", ramp_rms(&own));
        assert!(worst_corner(&own) < sigma, "{}", worst_corner(&own));
        // Capped at the rates' window: sharp corners, but the ramps keep more of the noise.
        let (narrow, capped) = smoothing_window(&t, &x, sigma, 0.02, 0.02).unwrap();
        assert!(
            narrow <= 0.02 && ramp_rms(&capped) > 2.0 * ramp_rms(&own),
            "{narrow}"
        );
    }

    #[test]
    fn white_noise_is_read_through_a_motion_and_a_slow_quantised_ramp_reads_as_almost_none() {
        // σ = 0.2 mrad on a 1 Hz swing of 0.1 rad sampled at 1 kHz (curvature ẍ·dt² = 4 µrad).
        let n = 20_000;
        let noise = gauss(n, 7);
        let x: Vec<f64> = (0..n)
            .map(|k| 0.1 * (std::f64::consts::TAU * k as f64 * 1e-3).sin() + 2e-4 * noise[k])
            .collect();
        let est = white_noise_rms(&x);
        assert!((est / 2e-4 - 1.0).abs() < 0.05, "{est}");
        // The noise averaged out by a ±20 ms local quadratic (41 samples): its value at the
        // centre has variance 2.25·σ²/41 (closed form of the centred fit, to a few %).
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let (smooth, _, _) = local_fit_of_degree(&t, &x, 0.02, 2);
        let left: Vec<f64> = (100..n - 100)
            .map(|k| smooth[k] - 0.1 * (std::f64::consts::TAU * t[k]).sin())
            .collect();
        let ratio = crate::identify::stats::std(&left) / 2e-4;
        assert!((ratio - (2.25f64 / 41.0).sqrt()).abs() < 0.03, "{ratio}");
        // A quantised ramp moving a tenth of a count per sample: a step every ten samples.
        let res = 1e-4;
        let ramp: Vec<f64> = (0..n)
            .map(|k| (k as f64 * 0.1 + 0.5).floor() * res)
            .collect();
        assert!(
            white_noise_rms(&ramp) < 0.15 * res,
            "{}",
            white_noise_rms(&ramp)
        );
        // A 5 Hz swing of 0.05 rad at 100 Hz, quantised at 0.1 mrad: its second difference
        // (ẍ·dt², up to 5 mrad) would read as 16 counts of noise; its fourth difference
        // (x⁗·dt⁴, up to 0.5 mrad) reads as half a count.
        let fast: Vec<f64> = (0..2000)
            .map(|k| {
                let x = 0.05 * (std::f64::consts::TAU * 5.0 * k as f64 * 0.01).sin();
                (x / res).round() * res
            })
            .collect();
        assert!(white_noise_rms(&fast) < res, "{}", white_noise_rms(&fast));
    }

    #[test]
    fn a_local_quartic_is_exact_on_a_quartic_and_flattens_a_fast_sine_far_less_than_a_quadratic() {
        let t: Vec<f64> = (0..400)
            .map(|k| k as f64 * 0.005 + 0.001 * ((k * 7 % 5) as f64))
            .collect();
        let x: Vec<f64> = t
            .iter()
            .map(|t| 1.0 - t + 2.0 * t.powi(3) - 3.0 * t.powi(4))
            .collect();
        let (v, a) = local_rates_of_degree(&t, &x, 0.03, 4);
        for i in 0..t.len() {
            let (vt, at) = (
                -1.0 + 6.0 * t[i].powi(2) - 12.0 * t[i].powi(3),
                12.0 * t[i] - 36.0 * t[i].powi(2),
            );
            assert!((v[i] - vt).abs() < 1e-7, "{i}: {} against {vt}", v[i]);
            assert!((a[i] - at).abs() < 1e-5, "{i}: {} against {at}", a[i]);
        }
        // 9 Hz with ±40 ms (ωh = 2.3): the quadratic's ẍ is a fraction of the truth's.
        let w = std::f64::consts::TAU * 9.0;
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 0.001).collect();
        let x: Vec<f64> = t.iter().map(|t| (w * t).sin()).collect();
        let err = |deg: usize| {
            let (_, a) = local_rates_of_degree(&t, &x, 0.04, deg);
            (100..1900)
                .map(|i| (a[i] + w * w * (w * t[i]).sin()).abs())
                .fold(0.0f64, f64::max)
                / (w * w)
        };
        let (e2, e4) = (err(2), err(4));
        assert!(e2 > 0.3, "quadratic: {e2}");
        assert!(e4 < 0.5 * e2, "quartic {e4} against quadratic {e2}");
        assert_eq!(
            local_rates(&t, &x, 0.04).1,
            local_rates_of_degree(&t, &x, 0.04, 2).1
        );
    }

    #[test]
    fn held_sign_keeps_the_entering_direction_through_a_hold_and_turns_where_the_motion_out_starts()
    {
        // At 10 Hz: rest, a push up, a hold of 0.7 s (its rate exactly 0, then noise), the
        // motion out of it down, a reversal up through the dead band in two samples, and a hold at
        // the run's end.
        let rate = [
            0.0, 0.0, 1.0, 1.0, 0.0, 0.01, -0.01, 0.01, -0.02, -0.03, -1.0, -0.02, 0.02, 1.0, 0.0,
            0.0,
        ];
        let t: Vec<f64> = (0..rate.len()).map(|k| 0.1 * k as f64).collect();
        let dir = rate_sign(&rate, 0.05);
        assert_eq!(
            held_sign(&t, &rate, &dir, &[]),
            vec![
                0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0, -1.0, 0.0, 0.0, 1.0, 1.0, 1.0
            ]
        );
    }

    #[test]
    fn a_hold_turns_where_its_torque_steps_before_the_counted_rate_moves() {
        // At 100 Hz: a push up, a hold of 1 s whose counted rate is exactly 0, the motion out
        // of it down counted from sample 80 on. The contact turned at sample 60: the torque
        // steps down by 0.2 there under noise of ±0.01 (a fixed pattern).
        let n = 100;
        let rate: Vec<f64> = (0..n)
            .map(|k| match k {
                0..10 => 1.0,
                10..80 => 0.0,
                _ => -1.0,
            })
            .collect();
        let t: Vec<f64> = (0..n).map(|k| 0.01 * k as f64).collect();
        let noise = |k: usize| 0.01 * [1.0, -1.0, 0.5, -0.5, 0.0][k % 5];
        let tau: Vec<f64> = (0..n)
            .map(|k| if k < 60 { 1.0 } else { 0.8 } + noise(k))
            .collect();
        let dir = rate_sign(&rate, 0.05);
        let held = held_sign(&t, &rate, &dir, &tau);
        assert_eq!(held[..60], vec![1.0; 60][..]);
        assert_eq!(held[60..], vec![-1.0; 40][..]);
        // By the rate alone the turn is where the count moves.
        assert_eq!(held_sign(&t, &rate, &dir, &[])[..80], vec![1.0; 80][..]);
        // A step the other way (the torque rising into a motion down) is not the contact's
        // turn, nor is a step within the noise.
        let up: Vec<f64> = tau.iter().map(|v| 2.0 - v).collect();
        assert_eq!(held_sign(&t, &rate, &dir, &up)[..80], vec![1.0; 80][..]);
        let small: Vec<f64> = (0..n)
            .map(|k| if k < 60 { 1.0 } else { 0.995 } + noise(k))
            .collect();
        assert_eq!(held_sign(&t, &rate, &dir, &small)[..80], vec![1.0; 80][..]);
        // Nor is a hold whose torque may not be used (a held-out row in it: NaN).
        let mut masked = tau.clone();
        masked[30] = f64::NAN;
        assert_eq!(held_sign(&t, &rate, &dir, &masked)[..80], vec![1.0; 80][..]);
        assert_eq!(torque_turn(&tau[10..80], -1.0), Some(50));
    }

    #[test]
    fn rate_sign_is_zero_when_still() {
        assert_eq!(
            rate_sign(&[0.5, 0.01, -0.2, 0.0], 0.05),
            [1.0, 0.0, -1.0, 0.0]
        );
    }

    #[test]
    fn play_is_the_backlash_of_the_simulator() {
        // Backlash of total width 0.2: output lags the input by 0.1 once the play is taken up.
        let x = [0.0, 0.05, 0.3, 0.25, 0.1, -0.2];
        let s = stop_operator(&x, 0.1);
        let play: Vec<f64> = x.iter().zip(&s).map(|(x, s)| x - s).collect();
        let want = [0.0, 0.0, 0.2, 0.2, 0.2, -0.1];
        for (p, w) in play.iter().zip(want) {
            assert!((p - w).abs() < 1e-12, "{play:?}");
        }
    }

    #[test]
    fn shift_and_resample_interpolate_linearly() {
        let t = [0.0, 1.0, 3.0];
        let x = [0.0, 2.0, 6.0];
        assert_eq!(shifted(&t, &x, 0.5), vec![0.0, 1.0, 5.0]);
        let seg = uniform_segments(&t, &x, 0.5, 10.0);
        assert_eq!(seg, vec![vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]]);
        assert_eq!(uniform_segments(&t, &x, 0.5, 1.5).len(), 1);
        assert!((median_step(&[0.0, 0.1, 0.3, 0.4]) - 0.1).abs() < 1e-15);
    }

    #[test]
    fn steps_count_bursts_of_sudden_change() {
        let mut x: Vec<f64> = (0..200).map(|i| i as f64 * 0.01).collect();
        for v in &mut x[50..] {
            *v += 1.0;
        }
        for v in &mut x[120..] {
            *v -= 0.5;
        }
        for v in &mut x[121..] {
            *v -= 0.5;
        }
        assert_eq!(steps(&x), 2);
        let smooth: Vec<f64> = (0..200).map(|i| (i as f64 * 0.05).sin()).collect();
        assert_eq!(steps(&smooth), 0);
    }

    #[test]
    fn the_weak_forms_rates_carry_the_smoothers_response_exactly_as_the_smoothed_signal_does() {
        // A 4 Hz sine sampled at 500 Hz with a jitter of a tenth of a step: the weak form's
        // q̈ is the smoothed true q̈ (what the smoothed torque of I·q̈ is, divided by I), at a
        // narrow and at a wide smoother alike, within the quartic's (ωdt)⁴ error.
        let (w, dt) = (std::f64::consts::TAU * 4.0, 0.002);
        let mut uniform = uniforms(7);
        let t: Vec<f64> = (0..5000)
            .map(|i| (i as f64 + 0.1 * uniform()) * dt)
            .collect();
        let x: Vec<f64> = t.iter().map(|t| 0.3 * (w * t).sin()).collect();
        let (xd, xdd): (Vec<f64>, Vec<f64>) = t
            .iter()
            .map(|t| (0.3 * w * (w * t).cos(), -0.3 * w * w * (w * t).sin()))
            .unzip();
        for h in [0.02, 0.32] {
            let (v, a) = weak_rates(&t, &x, h, dt);
            let (v0, a0) = (weak_smooth(&xd, h, dt), weak_smooth(&xdd, h, dt));
            let err_a = a
                .iter()
                .zip(&a0)
                .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
            let err_v = v
                .iter()
                .zip(&v0)
                .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
            assert!(err_a < 1e-3 * 0.3 * w * w, "h {h}: q̈ off by {err_a}");
            assert!(err_v < 1e-3 * 0.3 * w, "h {h}: q̇ off by {err_v}");
        }
    }

    #[test]
    fn a_quantised_angle_read_as_the_taut_string_gives_the_weak_forms_q̈_where_the_staircase_does_not()
     {
        // A 14-bit encoder at 1 kHz (a tenth of a step's jitter) on quintic ramps out and back,
        // a hold between, the run starting and ending mid-ramp: the staircase's sawtooth passes
        // q̈ jumps of a count wherever the speed is near a whole number of counts per sample,
        // or under one. The taut string stays within half a count of every reading and within
        // a count of the truth, and its q̈ through the weak form's smoother is the true one's
        // to a fraction of the staircase's error, up to the run's ends.
        let (count, dt) = (std::f64::consts::TAU / 16384.0, 0.001);
        let quintic = |t: f64, t0: f64, dur: f64, from: f64, to: f64| -> f64 {
            let s = ((t - t0) / dur).clamp(0.0, 1.0);
            from + (to - from) * s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
        };
        let truth = |t: f64| quintic(t, 1.0, 1.5, 0.0, 0.6) + quintic(t, 4.0, 4.0, 0.0, -0.9);
        let mut uniform = uniforms(5);
        let t: Vec<f64> = (1200..6500)
            .map(|i| (i as f64 + 0.1 * uniform()) * dt)
            .collect();
        let q: Vec<f64> = t.iter().map(|&t| truth(t)).collect();
        let read: Vec<f64> = q.iter().map(|q| (q / count).round() * count).collect();
        assert!(reads_in_counts(&read, count) && !reads_in_counts(&q, count));
        let string = taut_string(&t, &read, count);
        for i in 0..t.len() {
            assert!(
                (string[i] - read[i]).abs() <= 0.5 * count * (1.0 + 1e-9),
                "{i}"
            );
            assert!((string[i] - q[i]).abs() <= count, "{i}");
        }
        let h = 0.08;
        let acc = |x: &[f64]| weak_rates(&t, x, h, dt).1;
        let a0 = acc(&q);
        let err = |x: &[f64], inner: std::ops::Range<usize>| {
            let a = acc(x);
            let n = inner.len() as f64;
            (inner.map(|i| (a[i] - a0[i]).powi(2)).sum::<f64>() / n).sqrt()
        };
        let n = t.len();
        // A run that starts at rest 0.4 counts above a reading, then moves 800 counts up: its
        // q̈ from the first sample on within 5 % of the peak.
        let rest: Vec<f64> = (0..2000)
            .map(|i| (i as f64 + 0.1 * uniform()) * dt)
            .collect();
        let q_rest: Vec<f64> = rest
            .iter()
            .map(|&t| (100.4 + 800.0 * quintic(t, 0.5, 1.5, 0.0, 1.0)) * count)
            .collect();
        let read_rest: Vec<f64> = q_rest.iter().map(|q| (q / count).round() * count).collect();
        let strung = taut_string(&rest, &read_rest, count);
        let (a_true, a_strung) = (
            weak_rates(&rest, &q_rest, h, dt).1,
            weak_rates(&rest, &strung, h, dt).1,
        );
        let worst = (0..600).fold(0.0f64, |m, i| m.max((a_strung[i] - a_true[i]).abs()));
        let peak = a_true.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        assert!(
            worst < 0.05 * peak,
            "q̈ off by {worst} at the start, peak {peak}"
        );
        for (part, inner) in [
            ("inside", 400..n - 400),
            ("ends", 0..400),
            ("ends", n - 400..n),
        ] {
            let (staircase, strung) = (err(&read, inner.clone()), err(&string, inner));
            assert!(
                strung < 0.2 * staircase,
                "{part}: q̈ error rms {strung} against the staircase's {staircase} rad/s²"
            );
        }
    }

    #[test]
    fn the_weak_forms_noise_gains_are_what_white_noise_comes_out_with() {
        // Monte Carlo peer of the impulse responses: 200 000 samples of unit white noise
        // through the smoother and through the rates, rms within 3 % of the gains.
        let dt = 0.002;
        let mut uniform = uniforms(11);
        let noise: Vec<f64> = (0..200_000)
            .map(|_| (uniform() - 0.5) * 12f64.sqrt())
            .collect();
        let t: Vec<f64> = (0..noise.len()).map(|k| k as f64 * dt).collect();
        let rms = |v: &[f64]| {
            let inner = &v[1000..v.len() - 1000];
            (inner.iter().map(|a| a * a).sum::<f64>() / inner.len() as f64).sqrt()
        };
        for h in [0.02, 0.16] {
            let (g_tau, g_rate, g_acc) = weak_noise_gains(h, dt);
            let (v, a) = weak_rates(&t, &noise, h, dt);
            for (what, measured, gain) in [
                ("smoothed", rms(&weak_smooth(&noise, h, dt)), g_tau),
                ("rate", rms(&v), g_rate),
                ("acceleration", rms(&a), g_acc),
            ] {
                assert!(
                    (measured / gain - 1.0).abs() < 0.03,
                    "h {h}: {what} noise {measured}, gain {gain}"
                );
            }
        }
    }

    #[test]
    fn a_first_order_low_pass_follows_a_ramp_exactly_at_any_steps_and_undoing_it_gives_the_ramp_back()
     {
        // x = 0 until t = 0.1 s, then 2·(t − 0.1): from rest, T·ẏ = x − y gives
        // y = 2·(u − T·(1 − e^(−u/T))), u = t − 0.1, and ẏ = 2·(1 − e^(−u/T)); irregular
        // steps of 1–9 ms, one corner at a sample.
        let tc = 0.03;
        let mut t = vec![0.0];
        let mut uniform = uniforms(5);
        while *t.last().unwrap() < 0.6 {
            t.push(t.last().unwrap() + 0.001 + 0.008 * uniform());
        }
        t.push(0.1);
        t.sort_by(f64::total_cmp);
        let x: Vec<f64> = t.iter().map(|t| 2.0 * (t - 0.1).max(0.0)).collect();
        let y = low_passed(&t, &x, tc);
        let (mut rates, mut worst) = (vec![], 0.0f64);
        for (t, y) in t.iter().zip(&y) {
            let u = (t - 0.1).max(0.0);
            let want = 2.0 * (u - tc * (1.0 - (-u / tc).exp()));
            worst = worst.max((y - want).abs());
            rates.push(2.0 * (1.0 - (-u / tc).exp()));
        }
        assert!(worst < 1e-12, "off the closed form by {worst}");
        let back = low_pass_undone(&y, &rates, tc);
        for (b, x) in back.iter().zip(&x) {
            assert!((b - x).abs() < 1e-12, "{b} against {x}");
        }
        // A sensor that ran before the recording: a line already moving at the first sample
        // reads x − T·ẋ throughout, no transient at the start.
        let line: Vec<f64> = t.iter().map(|t| 4.0 - 3.0 * t).collect();
        for (y, x) in low_passed(&t, &line, tc).iter().zip(&line) {
            assert!((y - (x + 3.0 * tc)).abs() < 1e-12, "{y} against {x} + 3·T");
        }
        // The centred difference of a straight line is its slope, at the ends too.
        assert!(
            centred_rate(&t, &line)
                .iter()
                .all(|v| (v + 3.0).abs() < 1e-9)
        );
    }

    /// 1 kHz with a jitter of up to `jitter` of a step either way, two samples dropped at
    /// 25–26 and a gap over 80–99: the instants kept, with their indices on the grid.
    fn holed_instants(jitter: f64) -> (Vec<f64>, Vec<usize>) {
        let (h, mut uniform) = (0.001, uniforms(11));
        let kept: Vec<usize> = (0..200)
            .filter(|j| !(25..27).contains(j) && !(80..100).contains(j))
            .collect();
        let t = kept
            .iter()
            .map(|&j| 5.0 + j as f64 * h + 2.0 * jitter * h * (uniform() - 0.5))
            .collect();
        (t, kept)
    }

    #[test]
    fn with_no_step_to_lay_a_grid_the_weak_smoother_keeps_one_value_a_sample() {
        let (t, _) = holed_instants(0.45);
        let x: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let s = weak_smooth_at(&t, &x, 0.02, dt);
            let (v, a) = weak_rates_at(&t, &x, 0.02, dt);
            assert_eq!((s.len(), v.len(), a.len()), (t.len(), t.len(), t.len()));
            assert!(s.iter().all(|s| s.is_finite()), "dt {dt}: {s:?}");
        }
    }

    #[test]
    fn a_filter_undone_on_the_angle_carries_its_white_noise_through_at_the_gain_computed_for_it() {
        // White noise of 0.1 mrad in an angle standing still at 1 kHz, through the weak form's
        // q̈ at an 80 ms smoother and a 34 ms filter undone (q̈ + T·q⃛, the jerk the smoothed
        // q̈'s centred difference): the rms over the series against σ times the gain from the
        // impulse response; and several times the q̈'s own.
        let (h, dt, tc, sigma) = (0.08, 0.001, 0.034, 1e-4);
        let mut uniform = uniforms(9);
        let t: Vec<f64> = (0..40_000).map(|j| j as f64 * dt).collect();
        let x: Vec<f64> = (t.iter())
            .map(|_| sigma * 12f64.sqrt() * (uniform() - 0.5))
            .collect();
        let (_, a) = weak_rates(&t, &x, h, dt);
        let undone = low_pass_undone(&a, &centred_rate(&t, &a), tc);
        let rms = crate::identify::stats::rmse(&undone[1000..39_000]);
        let gain = weak_acc_gain_undone(h, dt, tc);
        assert!(
            (rms / (sigma * gain) - 1.0).abs() < 0.05,
            "{rms} against {}",
            sigma * gain
        );
        let own = weak_acc_gain_undone(h, dt, 0.0);
        assert!((own / weak_noise_gains(h, dt).2 - 1.0).abs() < 1e-12);
        assert!(gain > 3.0 * own, "{gain} against {own}");
    }

    #[test]
    fn a_gap_splits_a_recording_into_stretches_and_a_dropped_sample_does_not() {
        let (t, _) = holed_instants(0.45);
        assert_eq!(unbroken(&t, GAP_STEPS * 0.001), [0..78, 78..178]);
    }

    #[test]
    fn on_jittered_instants_an_angles_white_noise_reaches_the_weak_acceleration_as_on_even_ones() {
        // White noise of 0.1 mrad in an angle standing still, sampled at 1 kHz with a jitter of
        // up to 0.45 of a step: read onto the grid, its smoothed q̈ has the rms the weak form's
        // gain gives for even samples (a little less: reading onto the grid averages
        // neighbours). Differentiated on the jittered instants and smoothed by index, the
        // quartics' weights no longer sum by parts and the noise comes through many times.
        let (h, dt, sigma) = (0.02, 0.001, 1e-4);
        let mut uniform = uniforms(5);
        let t: Vec<f64> = (0..4000)
            .map(|j| j as f64 * dt + 0.9 * dt * (uniform() - 0.5))
            .collect();
        let x: Vec<f64> = t
            .iter()
            .map(|_| sigma * 12f64.sqrt() * (uniform() - 0.5))
            .collect();
        let rms_inside = |a: &[f64]| crate::identify::stats::rmse(&a[200..3800]);
        let expected = sigma * weak_noise_gains(h, dt).2;
        let on_the_grid = rms_inside(&weak_rates_at(&t, &x, h, dt).1);
        assert!(
            (0.6..1.05).contains(&(on_the_grid / expected)),
            "{on_the_grid} against {expected}"
        );
        let on_the_instants = rms_inside(&weak_rates(&t, &x, h, dt).1);
        assert!(
            on_the_instants > 3.0 * expected,
            "{on_the_instants} against {expected}"
        );
    }

    #[test]
    fn through_jitter_dropped_samples_and_a_gap_the_weak_smoother_leaves_a_straight_line_straight()
    {
        // Summed over the samples there are, a moving average of a line sampled unevenly is
        // off the line (more samples on one side of a dropped one, or across a gap); read onto
        // the grid, smoothed and read back, it is not. Away from each stretch's ends by the
        // smoother's support (12 steps) and the grid's own offset (under a step each), where
        // its averages are one-sided.
        let (t, kept) = holed_instants(0.45);
        let line: Vec<f64> = t.iter().map(|t| 2.0 - 3.0 * t).collect();
        let inside = |j: usize| (14..66).contains(&j) || (114..186).contains(&j);
        let off = |smooth: &[f64]| {
            (smooth.iter().zip(&line).zip(&kept))
                .filter(|(_, j)| inside(**j))
                .map(|((s, x), _)| (s - x).abs())
                .fold(0.0, f64::max)
        };
        let on_the_grid = off(&weak_smooth_at(&t, &line, 0.012, 0.001));
        assert!(on_the_grid < 1e-12, "moved by {on_the_grid}");
        let by_index = off(&weak_smooth(&line, 0.012, 0.001));
        assert!(
            by_index > 1e-4,
            "by index the line moved by {by_index} only"
        );
        // Its rate is the slope and its acceleration 0, at the gap's edges too.
        let (v, a) = weak_rates_at(&t, &line, 0.012, 0.001);
        assert!(v.iter().all(|v| (v + 3.0).abs() < 1e-6), "{v:?}");
        assert!(a.iter().all(|a| a.abs() < 1e-3), "{a:?}");
    }

    #[test]
    fn an_encoders_noise_is_read_through_jittered_instants_and_dropped_samples() {
        // A 2 Hz swing of 0.5 rad at 250 Hz with white noise of 1 mrad rms, a tenth of the
        // samples dropped and each instant up to 0.45 of a step off its slot: by index, the
        // swing's cubic does not cancel across a dropped sample, nor its rate times the jitter.
        let mut uniform = uniforms(3);
        let (mut t, mut x) = (vec![], vec![]);
        for j in 0..5000 {
            let tj = (j as f64 + 0.9 * (uniform() - 0.5)) / 250.0;
            let noise = 1e-3 * 12f64.sqrt() * (uniform() - 0.5);
            if uniform() > 0.1 {
                t.push(tj);
                x.push(0.5 * (std::f64::consts::TAU * 2.0 * tj).sin() + noise);
            }
        }
        let (at, blind) = (white_noise_rms_at(&t, &x), white_noise_rms(&x));
        assert!((at / 1e-3 - 1.0).abs() < 0.1, "read {at} of 1e-3");
        assert!(blind > 1.3e-3, "read blind {blind}");
    }
}
