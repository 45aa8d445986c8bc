//! Deterministic noise and sensor imperfections: seeded Gaussian noise, quantisation, delay.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Seeded Gaussian noise: the same seed gives the same sequence on every machine.
#[derive(Debug, Clone)]
pub struct Noise {
    rng: ChaCha8Rng,
}

impl Noise {
    pub fn new(seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// A sample of N(0, σ²); σ = 0 gives exactly 0 without drawing.
    pub fn gaussian(&mut self, sigma: f64) -> f64 {
        if sigma == 0.0 {
            return 0.0;
        }
        let z: f64 = StandardNormal.sample(&mut self.rng);
        sigma * z
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        let z: f64 = rand_distr::StandardUniform.sample(&mut self.rng);
        z
    }
}

/// Rounds to the nearest multiple of `resolution` (no-op for resolution ≤ 0).
pub fn quantize(x: f64, resolution: f64) -> f64 {
    if resolution > 0.0 {
        (x / resolution).round() * resolution
    } else {
        x
    }
}

/// A fixed delay of whole samples.
#[derive(Debug, Clone)]
pub struct DelayLine {
    buf: std::collections::VecDeque<f64>,
    samples: usize,
}

impl DelayLine {
    pub fn new(samples: usize) -> Self {
        Self {
            buf: std::collections::VecDeque::with_capacity(samples + 1),
            samples,
        }
    }

    /// Pushes the current value, returns the one from `samples` ago (the oldest while filling).
    pub fn push(&mut self, x: f64) -> f64 {
        self.buf.push_back(x);
        if self.buf.len() > self.samples + 1 {
            self.buf.pop_front();
        }
        self.buf.front().copied().unwrap_or(x)
    }
}

/// Backlash: a gap of total width `width` in series with the spring. The deflection measured
/// across gap and spring is `x`; the spring sees sgn x·max(|x| − width/2, 0): inside the gap
/// it is unloaded (it relaxes to rest), so there is no memory. (A play operator, which holds
/// its output inside the band, would make the spring's loop run the other way round and give
/// energy back: no passive gap does that.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backlash {
    half: f64,
}

impl Backlash {
    pub fn new(width: f64) -> Self {
        Self {
            half: 0.5 * width.max(0.0),
        }
    }

    /// What the spring sees of the deflection `x`.
    pub fn update(&mut self, x: f64) -> f64 {
        (x.abs() - self.half).max(0.0) * x.signum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_deterministic_and_has_the_right_spread() {
        let mut a = Noise::new(7);
        let mut b = Noise::new(7);
        let xs: Vec<f64> = (0..20_000).map(|_| a.gaussian(0.5)).collect();
        let ys: Vec<f64> = (0..20_000).map(|_| b.gaussian(0.5)).collect();
        assert_eq!(xs, ys);
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64).sqrt();
        assert!(mean.abs() < 0.02 && (sd - 0.5).abs() < 0.01, "{mean} {sd}");
        assert_eq!(a.gaussian(0.0), 0.0);
    }

    #[test]
    fn quantize_delay_and_backlash() {
        assert_eq!(quantize(0.26, 0.1), 0.30000000000000004);
        assert_eq!(quantize(0.26, 0.0), 0.26);
        let mut d = DelayLine::new(2);
        let out: Vec<f64> = (1..=5).map(|i| d.push(i as f64)).collect();
        assert_eq!(out, vec![1.0, 1.0, 1.0, 2.0, 3.0]);
        let mut bl = Backlash::new(0.2);
        assert_eq!(bl.update(0.0), 0.0);
        assert_eq!(bl.update(0.05), 0.0); // inside the gap: the spring is unloaded
        assert!((bl.update(0.3) - 0.2).abs() < 1e-15); // beyond it by 0.2
        assert!((bl.update(0.25) - 0.15).abs() < 1e-15); // no memory: the same on the way back
        assert_eq!(bl.update(-0.08), 0.0);
        assert!((bl.update(-0.35) + 0.25).abs() < 1e-15);
    }
}
