//! Error measures, least squares, and the residual's correlations.

use nalgebra::{DMatrix, DVector};

/// Root-mean-square of `e`.
pub fn rmse(e: &[f64]) -> f64 {
    if e.is_empty() {
        return f64::NAN;
    }
    (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
}

/// Mean absolute value of `e`.
pub fn mae(e: &[f64]) -> f64 {
    if e.is_empty() {
        return f64::NAN;
    }
    e.iter().map(|v| v.abs()).sum::<f64>() / e.len() as f64
}

/// Mean of `e`.
pub fn mean(e: &[f64]) -> f64 {
    if e.is_empty() {
        return f64::NAN;
    }
    e.iter().sum::<f64>() / e.len() as f64
}

/// Least squares `y ≈ Σ c_j·cols[j]` over the rows in `rows`. Columns are scaled to unit RMS
/// first, so features in rad and in N·m sit side by side; the solve is by SVD, so collinear
/// columns give the minimum-norm answer instead of failing. `None` when nothing is finite.
pub fn least_squares(cols: &[&[f64]], y: &[f64], rows: &[usize]) -> Option<Vec<f64>> {
    let p = cols.len();
    if p == 0 || rows.is_empty() {
        return Some(vec![0.0; p]);
    }
    let scale: Vec<f64> = cols
        .iter()
        .map(|c| {
            let s = (rows.iter().map(|&i| c[i] * c[i]).sum::<f64>() / rows.len() as f64).sqrt();
            if s > 0.0 && s.is_finite() { s } else { 1.0 }
        })
        .collect();
    let a = DMatrix::from_fn(rows.len(), p, |r, c| cols[c][rows[r]] / scale[c]);
    let b = DVector::from_iterator(rows.len(), rows.iter().map(|&i| y[i]));
    let svd = a.svd(true, true);
    let x = svd.solve(&b, 1e-10).ok()?;
    let out: Vec<f64> = x.iter().zip(&scale).map(|(x, s)| x / s).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// `Σ c_j·cols[j][i]` for every row.
pub fn combine(cols: &[&[f64]], coefs: &[f64], n: usize) -> Vec<f64> {
    let mut out = vec![0.0; n];
    for (c, k) in cols.iter().zip(coefs) {
        for (o, v) in out.iter_mut().zip(c.iter()) {
            *o += k * v;
        }
    }
    out
}

/// Normalised autocorrelation of each segment pooled, at lags 1..=`max_lag`.
pub fn autocorrelation(segments: &[Vec<f64>], max_lag: usize) -> Vec<f64> {
    cross_correlation(segments, segments, 1, max_lag as i64)
        .into_iter()
        .map(|(_, r)| r)
        .collect()
}

/// Normalised cross-correlation of `a` (the residual) with `b` (an input), pooled over
/// segments, at lags `lo..=hi` samples: ρ(k) = Σ a[i]·b[i−k] / (‖a‖·‖b‖) with means removed.
/// A positive lag means the residual follows the input late by k samples.
pub fn cross_correlation(a: &[Vec<f64>], b: &[Vec<f64>], lo: i64, hi: i64) -> Vec<(i64, f64)> {
    let centred = |s: &[Vec<f64>]| -> Vec<Vec<f64>> {
        let all: Vec<f64> = s.iter().flatten().copied().collect();
        let m = mean(&all);
        s.iter()
            .map(|v| v.iter().map(|x| x - m).collect())
            .collect()
    };
    let (a, b) = (centred(a), centred(b));
    let na: f64 = a.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
    let nb: f64 = b.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
    (lo..=hi)
        .map(|k| {
            let mut s = 0.0;
            for (sa, sb) in a.iter().zip(&b) {
                let n = sa.len().min(sb.len()) as i64;
                for i in k.max(0)..n.min(n + k) {
                    s += sa[i as usize] * sb[(i - k) as usize];
                }
            }
            let r = if na > 0.0 && nb > 0.0 {
                s / (na * nb)
            } else {
                0.0
            };
            (k, r)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_recovers_exact_coefficients_with_collinear_spare_column() {
        let x: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let one = vec![1.0; 50];
        let y: Vec<f64> = x.iter().map(|x| 2.5 * x - 1.0).collect();
        let rows: Vec<usize> = (0..50).collect();
        let c = least_squares(&[&x, &one], &y, &rows).unwrap();
        assert!(
            (c[0] - 2.5).abs() < 1e-10 && (c[1] + 1.0).abs() < 1e-10,
            "{c:?}"
        );
        let twice: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
        let c = least_squares(&[&x, &twice, &one], &y, &rows).unwrap();
        let fit = combine(&[&x, &twice, &one], &c, 50);
        assert!(fit.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9));
    }

    #[test]
    fn correlations_match_closed_forms() {
        // An alternating sequence has ρ(1) = −1 (exactly −(n−1)/n here, means are zero).
        let alt: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let r = autocorrelation(std::slice::from_ref(&alt), 2);
        assert!(
            (r[0] + 0.99).abs() < 1e-12 && (r[1] - 0.98).abs() < 1e-12,
            "{r:?}"
        );
        // b delayed by 3 samples relative to a: the peak is at lag −3 (a leads b).
        let a: Vec<f64> = (0..200).map(|i| ((i * 37 % 101) as f64).sin()).collect();
        let b: Vec<f64> = (0..200)
            .map(|i| if i >= 3 { a[i - 3] } else { 0.0 })
            .collect();
        let x = cross_correlation(&[a], &[b], -5, 5);
        let best = x.iter().max_by(|p, q| p.1.total_cmp(&q.1)).unwrap();
        assert_eq!(best.0, -3);
        assert!(best.1 > 0.95);
        assert_eq!(rmse(&[3.0, -4.0]), (12.5f64).sqrt());
        assert_eq!(mae(&[3.0, -4.0]), 3.5);
    }
}
