//! The online residual monitor: where a joint has a torque sensor, the estimator host feeds
//! it the residual (measured − modelled torque) sample by sample. Over a sliding window it
//! regresses the residual on what the cheapest effects of the library would add — a constant
//! (`offset`), the direction of motion (`coulomb_friction`: the loop is off), the deflection
//! rate (`viscous_friction`; `sensor_delay` when its sign gives energy back), the deflection
//! itself (`stiffness_drift`: the spring rate moved since the model was fitted) — and reports a
//! diagnosis when those explain most of the residual: structure has appeared. `rig identify`
//! then does the full job offline.

use crate::identify::Effect;
use crate::identify::signals::rate_sign;
use crate::identify::stats::{combine, least_squares};

/// What the monitor says about one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosis {
    /// Whether structure is present (false: it has gone).
    pub present: bool,
    /// The effect that explains the most of the residual.
    pub effect: Effect,
    /// Fraction of the residual's variance (about zero) the regression explains.
    pub explained: f64,
    /// RMS of the residual over the window [N·m].
    pub rms: f64,
    /// The effect's coefficient over the window (N·m; N·m per rad/s; N·m/rad by effect): a
    /// window average, so a step shows part of its height when first seen.
    pub size: f64,
    /// Window length [s].
    pub window_s: f64,
}

impl Diagnosis {
    /// One line for a status message.
    pub fn text(&self) -> String {
        if !self.present {
            return format!(
                "diagnosis: residual structure gone (rms {:.3} N·m over {:.1} s)",
                self.rms, self.window_s
            );
        }
        let size = match self.effect {
            Effect::Offset => format!("{:+.3} N·m", self.size),
            Effect::CoulombFriction => format!("±{:.3} N·m", self.size),
            Effect::ViscousFriction => format!("{:.3} N·m·s/rad", self.size),
            Effect::SensorDelay => format!(
                "{:.3} N·m·s/rad against the rate: the torque reading lags the deflection",
                self.size
            ),
            _ => format!("{:+.3} N·m/rad", self.size),
        };
        format!(
            "diagnosis: residual structure — {} ({size}) explains {:.0} % of it (rms {:.3} N·m over {:.1} s); run `rig identify` on a recording",
            self.effect.name(),
            100.0 * self.explained,
            self.rms,
            self.window_s
        )
    }
}

/// A sliding-window residual monitor for one joint.
#[derive(Debug, Clone)]
pub struct ResidualMonitor {
    window: usize,
    every: usize,
    t: Vec<f64>,
    x: Vec<f64>,
    r: Vec<f64>,
    head: usize,
    filled: usize,
    since: usize,
    /// Samples after the window fills at which it is first evaluated ([`Self::staggered`]).
    phase: usize,
    /// The last reported state: (present, effect).
    state: Option<(bool, Effect)>,
    /// A different state seen in the last evaluations, and how many times in a row.
    pending: Option<((bool, Effect), usize)>,
    /// Evaluations in a row a new state must hold before it is reported.
    pub confirm: usize,
    /// Fraction explained above which structure appears, and below which it goes.
    pub appear: f64,
    pub vanish: f64,
}

impl ResidualMonitor {
    /// A monitor over the last `window` samples, evaluated every `every` samples.
    pub fn new(window: usize, every: usize) -> Self {
        let window = window.max(50);
        Self {
            window,
            every: every.max(1),
            t: vec![0.0; window],
            x: vec![0.0; window],
            r: vec![0.0; window],
            head: 0,
            filled: 0,
            since: 0,
            phase: 0,
            state: None,
            pending: None,
            confirm: 4,
            appear: 0.5,
            vanish: 0.3,
        }
    }

    /// The `k`-th of `of` monitors fed on the same ticks, its evaluations shifted by k/of of
    /// the period: each evaluation is a least-squares fit over the window, and a host of many
    /// joints would otherwise fit them all on one tick (256 joints: a 35 ms stall every
    /// 0.25 s), holding up every sample behind it.
    pub fn staggered(mut self, k: usize, of: usize) -> Self {
        self.phase = (k % of.max(1)) * self.every / of.max(1);
        self
    }

    /// Feeds one sample: time [s], deflection [rad], residual [N·m]. Returns a diagnosis when
    /// structure appears, changes its leading effect, or goes (once the change has held for
    /// [`Self::confirm`] evaluations). Non-finite input is ignored.
    pub fn push(&mut self, t: f64, x: f64, residual: f64) -> Option<Diagnosis> {
        if !(t.is_finite() && x.is_finite() && residual.is_finite()) {
            return None;
        }
        self.t[self.head] = t;
        self.x[self.head] = x;
        self.r[self.head] = residual;
        self.head = (self.head + 1) % self.window;
        self.filled = (self.filled + 1).min(self.window);
        self.since += 1;
        if self.filled < self.window {
            // The first evaluation comes `phase` samples after the window fills.
            self.since = self.every - 1 - self.phase;
            return None;
        }
        if self.since < self.every {
            return None;
        }
        self.since = 0;
        let d = self.evaluate()?;
        let was = self.state;
        let present = match was {
            Some((true, _)) => d.explained >= self.vanish,
            _ => d.explained >= self.appear,
        };
        let now = (present, d.effect);
        let changed = match was {
            None => present,
            Some((p, e)) => p != present || (present && e != d.effect),
        };
        if !changed {
            self.pending = None;
            return None;
        }
        // Report a change only once it has held for `confirm` evaluations in a row: a step
        // entering the window looks, for a moment, like whatever correlates with it.
        let count = match self.pending {
            Some((p, c)) if p == now => c + 1,
            _ => 1,
        };
        self.pending = Some((now, count));
        if count < self.confirm {
            return None;
        }
        self.pending = None;
        self.state = Some(now);
        Some(Diagnosis { present, ..d })
    }

    /// The regression over the window, in time order.
    fn evaluate(&self) -> Option<Diagnosis> {
        let n = self.window;
        let idx = |k: usize| (self.head + k) % n;
        let t: Vec<f64> = (0..n).map(|k| self.t[idx(k)]).collect();
        let x: Vec<f64> = (0..n).map(|k| self.x[idx(k)]).collect();
        let r: Vec<f64> = (0..n).map(|k| self.r[idx(k)]).collect();
        let span = t[n - 1] - t[0];
        if span <= 0.0 {
            return None;
        }
        // Rate by a centred difference over ±h samples (about 10 ms at 1 kHz).
        let h = 10usize.min(n / 4).max(1);
        let rate: Vec<f64> = (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(h), (i + h).min(n - 1));
                if t[b] > t[a] {
                    (x[b] - x[a]) / (t[b] - t[a])
                } else {
                    0.0
                }
            })
            .collect();
        let still = rate.iter().map(|v| v.abs()).fold(0.0f64, f64::max) * 0.02;
        let dir = rate_sign(&rate, still);
        let one = vec![1.0; n];
        let cols: [(Effect, &[f64]); 4] = [
            (Effect::Offset, &one),
            (Effect::CoulombFriction, &dir),
            (Effect::ViscousFriction, &rate),
            (Effect::StiffnessDrift, &x),
        ];
        let rows: Vec<usize> = (0..n).collect();
        let total: f64 = r.iter().map(|v| v * v).sum();
        if total <= 0.0 {
            return None;
        }
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.1).collect();
        let coefs = least_squares(&refs, &r, &rows)?;
        // Residual sum of squares of the fit, with one regressor's share left out or none.
        let rss_without = |left_out: Option<usize>| -> f64 {
            let mut k = coefs.clone();
            if let Some(j) = left_out {
                k[j] = 0.0;
            }
            let fitted = combine(&refs, &k, n);
            r.iter().zip(&fitted).map(|(a, b)| (a - b) * (a - b)).sum()
        };
        let full = rss_without(None);
        // The leading effect: the one whose removal loses the most.
        let (k, _) = (0..4)
            .map(|k| (k, rss_without(Some(k)) - full))
            .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        // Against the rate with a negative sign the residual's loop gives energy back: no
        // friction does that; a torque reading late behind the deflection (τ(t − δ) ≈ τ − δ·k·φ̇)
        // does.
        let effect = match cols[k].0 {
            Effect::ViscousFriction if coefs[k] < 0.0 => Effect::SensorDelay,
            e => e,
        };
        Some(Diagnosis {
            present: false,
            effect,
            explained: 1.0 - full / total,
            rms: (total / n as f64).sqrt(),
            size: coefs[k],
            window_s: span,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(
        m: &mut ResidualMonitor,
        from: usize,
        to: usize,
        f: impl Fn(f64, f64) -> f64,
    ) -> Vec<Diagnosis> {
        let mut out = Vec::new();
        for i in from..to {
            let t = i as f64 * 1e-3;
            let x = 0.05 * (std::f64::consts::TAU * 0.7 * t).sin();
            // Deterministic, white-ish noise.
            let noise = 0.002 * (((i * 7919) % 1000) as f64 / 1000.0 - 0.5);
            if let Some(d) = m.push(t, x, f(t, x) + noise) {
                out.push(d);
            }
        }
        out
    }

    #[test]
    fn staggered_monitors_fit_on_their_own_ticks_a_fraction_of_the_period_apart() {
        // An offset from the start: each monitor names it at its fourth evaluation (confirm).
        let named_at = |m: ResidualMonitor| -> Option<usize> {
            let mut m = m;
            (0..4000).find(|&i| {
                let t = i as f64 * 1e-3;
                let x = 0.05 * (std::f64::consts::TAU * 0.7 * t).sin();
                m.push(t, x, 0.02).is_some()
            })
        };
        let first = named_at(ResidualMonitor::new(2000, 250));
        // The window fills at sample 1999; evaluations every 250 from there.
        assert_eq!(first, Some(1999 + 3 * 250));
        assert_eq!(
            named_at(ResidualMonitor::new(2000, 250).staggered(0, 4)),
            first
        );
        assert_eq!(
            named_at(ResidualMonitor::new(2000, 250).staggered(1, 4)),
            first.map(|i| i + 62)
        );
        assert_eq!(
            named_at(ResidualMonitor::new(2000, 250).staggered(3, 4)),
            first.map(|i| i + 187)
        );
    }

    #[test]
    fn an_offset_appears_is_named_and_goes() {
        let mut m = ResidualMonitor::new(2000, 250);
        assert!(
            run(&mut m, 0, 4000, |_, _| 0.0).is_empty(),
            "noise alone is no structure"
        );
        let d = run(&mut m, 4000, 8000, |_, _| 0.02);
        assert_eq!(d.len(), 1, "{d:?}");
        assert!(d[0].present && d[0].effect == Effect::Offset, "{d:?}");
        // Seen as soon as it explains half the window: a step shows part of its height.
        assert!(d[0].size > 0.004 && d[0].size < 0.022, "{}", d[0].size);
        assert!(d[0].text().contains("offset"), "{}", d[0].text());
        // As the step leaves the window it may first look like another effect; then it goes.
        let d = run(&mut m, 8000, 12000, |_, _| 0.0);
        assert!(!d.is_empty() && d.len() <= 2, "{d:?}");
        assert!(!d[d.len() - 1].present, "{d:?}");
    }

    #[test]
    fn friction_and_a_stiffness_change_are_told_apart() {
        let mut m = ResidualMonitor::new(2000, 250);
        let tau = std::f64::consts::TAU;
        let d = run(&mut m, 0, 4000, |t, _| {
            0.03 * (0.7 * tau * t).cos().signum()
        });
        assert_eq!(
            d.first().map(|d| d.effect),
            Some(Effect::CoulombFriction),
            "{d:?}"
        );
        let mut m = ResidualMonitor::new(2000, 250);
        let d = run(&mut m, 0, 4000, |_, x| 0.5 * x);
        assert_eq!(
            d.first().map(|d| d.effect),
            Some(Effect::StiffnessDrift),
            "{d:?}"
        );
        assert!((d[0].size - 0.5).abs() < 0.05);
    }

    #[test]
    fn a_residual_against_the_rate_is_friction_with_it_and_a_lag_with_its_sign_reversed() {
        // x = 0.05·sin(2π·0.7·t): friction b·ẋ dissipates; a late torque reading, −δ·k·ẋ,
        // gives energy back.
        let w = std::f64::consts::TAU * 0.7;
        for (b, want) in [(0.2, Effect::ViscousFriction), (-0.2, Effect::SensorDelay)] {
            let mut m = ResidualMonitor::new(2000, 250);
            let d = run(&mut m, 0, 4000, |t, _| b * 0.05 * w * (w * t).cos());
            assert_eq!(d.first().map(|d| d.effect), Some(want), "b {b}: {d:?}");
            assert!((d[0].size - b).abs() < 0.05 * b.abs(), "{}", d[0].size);
            assert!(d[0].text().contains(want.name()), "{}", d[0].text());
        }
    }
}
