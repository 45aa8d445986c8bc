//! Monotone piecewise-cubic Hermite interpolation (Fritsch–Carlson, "PCHIP").
//!
//! Used where a parameter must be smooth (C¹) over the pivot position without overshoot:
//! between two nodes the interpolant stays within their values, so a positive table stays
//! positive. Outside the nodes the end values are held (no extrapolation).

use thiserror::Error;

/// Errors building an interpolant.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum InterpError {
    #[error("an interpolation table needs at least one node")]
    Empty,
    #[error("x and y have different lengths ({0} and {1})")]
    LengthMismatch(usize, usize),
    #[error("interpolation nodes must be finite and strictly increasing in x (node {0})")]
    NotIncreasing(usize),
}

/// A C¹ monotone cubic through the nodes `(x[i], y[i])`.
#[derive(Debug, Clone, PartialEq)]
pub struct Pchip {
    x: Vec<f64>,
    y: Vec<f64>,
    m: Vec<f64>,
}

impl Pchip {
    /// Builds the interpolant. Nodes must be finite and strictly increasing in `x`.
    pub fn new(x: Vec<f64>, y: Vec<f64>) -> Result<Self, InterpError> {
        if x.is_empty() {
            return Err(InterpError::Empty);
        }
        if x.len() != y.len() {
            return Err(InterpError::LengthMismatch(x.len(), y.len()));
        }
        for i in 0..x.len() {
            if !x[i].is_finite() || !y[i].is_finite() || (i > 0 && x[i] <= x[i - 1]) {
                return Err(InterpError::NotIncreasing(i));
            }
        }
        let n = x.len();
        let mut m = vec![0.0; n];
        if n >= 2 {
            let h: Vec<f64> = (0..n - 1).map(|i| x[i + 1] - x[i]).collect();
            let delta: Vec<f64> = (0..n - 1).map(|i| (y[i + 1] - y[i]) / h[i]).collect();
            if n == 2 {
                m[0] = delta[0];
                m[1] = delta[0];
            } else {
                for i in 1..n - 1 {
                    if delta[i - 1] * delta[i] > 0.0 {
                        // Weighted harmonic mean (Fritsch–Butland / SciPy's choice).
                        let w1 = 2.0 * h[i] + h[i - 1];
                        let w2 = h[i] + 2.0 * h[i - 1];
                        m[i] = (w1 + w2) / (w1 / delta[i - 1] + w2 / delta[i]);
                    }
                }
                m[0] = end_slope(h[0], h[1], delta[0], delta[1]);
                m[n - 1] = end_slope(h[n - 2], h[n - 3], delta[n - 2], delta[n - 3]);
            }
        }
        Ok(Self { x, y, m })
    }

    /// The nodes' abscissae.
    pub fn nodes(&self) -> &[f64] {
        &self.x
    }

    /// The nodes' values.
    pub fn values(&self) -> &[f64] {
        &self.y
    }

    /// Value at `t`; the end values are held outside the nodes.
    pub fn eval(&self, t: f64) -> f64 {
        let n = self.x.len();
        if n == 1 || t <= self.x[0] {
            return self.y[0];
        }
        if t >= self.x[n - 1] {
            return self.y[n - 1];
        }
        // Index of the interval [x[i], x[i+1]) holding t.
        let i = self.x.partition_point(|&xi| xi <= t) - 1;
        let h = self.x[i + 1] - self.x[i];
        let s = (t - self.x[i]) / h;
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        h00 * self.y[i] + h10 * h * self.m[i] + h01 * self.y[i + 1] + h11 * h * self.m[i + 1]
    }
}

/// Three-point end slope, limited so that the end stays monotone (SciPy's rule).
fn end_slope(h0: f64, h1: f64, d0: f64, d1: f64) -> f64 {
    let m = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
    if m.signum() != d0.signum() || d0 == 0.0 {
        0.0
    } else if d0.signum() != d1.signum() && m.abs() > 3.0 * d0.abs() {
        3.0 * d0
    } else {
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_through_nodes_and_holds_ends() {
        let p = Pchip::new(vec![0.0, 1.0, 3.0, 4.0], vec![1.0, 2.0, 2.5, 10.0]).unwrap();
        for (x, y) in [(0.0, 1.0), (1.0, 2.0), (3.0, 2.5), (4.0, 10.0)] {
            assert!((p.eval(x) - y).abs() < 1e-12);
        }
        assert_eq!(p.eval(-5.0), 1.0);
        assert_eq!(p.eval(9.0), 10.0);
    }

    #[test]
    fn reproduces_a_line_exactly() {
        let x: Vec<f64> = vec![0.0, 0.5, 2.0, 2.5, 7.0];
        let y: Vec<f64> = x.iter().map(|v| 3.0 * v - 1.0).collect();
        let p = Pchip::new(x, y).unwrap();
        for i in 0..=70 {
            let t = i as f64 * 0.1;
            assert!((p.eval(t) - (3.0 * t - 1.0)).abs() < 1e-12);
        }
    }

    #[test]
    fn is_monotone_and_c1_on_monotone_data() {
        let p = Pchip::new(vec![0.0, 1.0, 2.0, 3.0], vec![0.0, 0.1, 5.0, 5.1]).unwrap();
        let mut prev = p.eval(0.0);
        for i in 1..=3000 {
            let v = p.eval(i as f64 * 1e-3);
            assert!(v >= prev - 1e-12, "not monotone at {i}");
            prev = v;
        }
        // C¹ at an interior node: left and right difference quotients agree.
        let e = 1e-6;
        let left = (p.eval(2.0) - p.eval(2.0 - e)) / e;
        let right = (p.eval(2.0 + e) - p.eval(2.0)) / e;
        assert!((left - right).abs() < 1e-4 * (1.0 + left.abs()));
    }

    #[test]
    fn rejects_bad_tables() {
        assert_eq!(Pchip::new(vec![], vec![]), Err(InterpError::Empty));
        assert!(Pchip::new(vec![0.0, 0.0], vec![1.0, 2.0]).is_err());
        assert!(Pchip::new(vec![0.0, f64::NAN], vec![1.0, 2.0]).is_err());
        assert!(Pchip::new(vec![0.0], vec![1.0, 2.0]).is_err());
    }
}
