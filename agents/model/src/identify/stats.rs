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

/// Median of `v` (the upper one of an even count; NaN when empty).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// Largest less smallest value of `v` (−∞ when empty).
pub fn span(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - v.iter().copied().fold(f64::INFINITY, f64::min)
}

/// Standard deviation of `e` about its mean (population).
pub fn std(e: &[f64]) -> f64 {
    let m = mean(e);
    rmse(&e.iter().map(|v| v - m).collect::<Vec<_>>())
}

/// Each column's RMS over `rows` (1 where it is 0 or not finite): the scale that puts
/// features in rad and in N·m side by side.
fn column_scales(cols: &[&[f64]], rows: &[usize]) -> Vec<f64> {
    cols.iter()
        .map(|c| {
            let s = (rows.iter().map(|&i| c[i] * c[i]).sum::<f64>() / rows.len() as f64).sqrt();
            if s > 0.0 && s.is_finite() { s } else { 1.0 }
        })
        .collect()
}

/// Least squares `y ≈ Σ c_j·cols[j]` over the rows in `rows`. Columns are scaled to unit RMS
/// first, so features in rad and in N·m sit side by side; the solve is by SVD, so collinear
/// columns give the minimum-norm answer instead of failing. `None` when nothing is finite.
pub fn least_squares(cols: &[&[f64]], y: &[f64], rows: &[usize]) -> Option<Vec<f64>> {
    let p = cols.len();
    if p == 0 || rows.is_empty() {
        return Some(vec![0.0; p]);
    }
    let scale = column_scales(cols, rows);
    let a = DMatrix::from_fn(rows.len(), p, |r, c| cols[c][rows[r]] / scale[c]);
    let b = DVector::from_iterator(rows.len(), rows.iter().map(|&i| y[i]));
    let svd = a.svd(true, true);
    let x = svd.solve(&b, 1e-10).ok()?;
    let out: Vec<f64> = x.iter().zip(&scale).map(|(x, s)| x / s).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// A sign a coefficient must keep (friction resists, a stop stiffens, hysteresis dissipates).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bound {
    Free,
    NonNegative,
    NonPositive,
}

/// Least squares `y ≈ Σ c_j·cols[j]` over `rows` with sign bounds on some coefficients
/// (Lawson & Hanson's active-set method, with free variables). Columns are scaled to unit
/// RMS; each sub-problem is solved on the normal equations by SVD, so collinear columns give
/// the minimum-norm answer. A bounded coefficient that would take the wrong sign is held at 0.
/// `None` when nothing is finite.
pub fn bounded_least_squares(
    cols: &[&[f64]],
    bounds: &[Bound],
    y: &[f64],
    rows: &[usize],
) -> Option<Vec<f64>> {
    let p = cols.len();
    if p == 0 || rows.is_empty() {
        return Some(vec![0.0; p]);
    }
    // Scaled columns; a NonPositive column is negated so that every bound reads c ≥ 0.
    let flip: Vec<f64> = (0..p)
        .map(|j| match bounds.get(j) {
            Some(Bound::NonPositive) => -1.0,
            _ => 1.0,
        })
        .collect();
    let scale = column_scales(cols, rows);
    let mut g = DMatrix::<f64>::zeros(p, p);
    let mut b = DVector::<f64>::zeros(p);
    let mut row = vec![0.0; p];
    for &i in rows {
        for j in 0..p {
            row[j] = cols[j][i] * flip[j] / scale[j];
        }
        for j in 0..p {
            b[j] += row[j] * y[i];
            for k in j..p {
                g[(j, k)] += row[j] * row[k];
            }
        }
    }
    for j in 0..p {
        for k in 0..j {
            g[(j, k)] = g[(k, j)];
        }
    }
    if !(g.iter().all(|v| v.is_finite()) && b.iter().all(|v| v.is_finite())) {
        return None;
    }
    let bounded: Vec<bool> = (0..p)
        .map(|j| !matches!(bounds.get(j), None | Some(Bound::Free)))
        .collect();
    // Least squares on the passive set (the others held at 0).
    let solve = |passive: &[bool]| -> Option<Vec<f64>> {
        let idx: Vec<usize> = (0..p).filter(|&j| passive[j]).collect();
        let mut out = vec![0.0; p];
        if idx.is_empty() {
            return Some(out);
        }
        let gs = DMatrix::from_fn(idx.len(), idx.len(), |r, c| g[(idx[r], idx[c])]);
        let bs = DVector::from_iterator(idx.len(), idx.iter().map(|&j| b[j]));
        let tol = 1e-12 * gs.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        let z = gs.svd(true, true).solve(&bs, tol).ok()?;
        for (k, &j) in idx.iter().enumerate() {
            out[j] = z[k];
        }
        Some(out)
    };
    let mut passive: Vec<bool> = bounded.iter().map(|b| !b).collect();
    let mut x = solve(&passive)?;
    // The free variables alone may already leave a bounded one with a wrong-sign gradient.
    for _ in 0..(3 * p + 3) {
        // Feasible: move in the bounded variable whose gradient most wants to grow.
        let w: Vec<f64> = (0..p)
            .map(|j| b[j] - (0..p).map(|k| g[(j, k)] * x[k]).sum::<f64>())
            .collect();
        let gmax = w.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let next = (0..p)
            .filter(|&j| bounded[j] && !passive[j] && w[j] > 1e-10 * gmax.max(1e-300))
            .max_by(|&a, &c| w[a].total_cmp(&w[c]));
        let Some(j) = next else { break };
        passive[j] = true;
        // Inner loop: keep the bounded passive variables positive.
        for _ in 0..(3 * p + 3) {
            let z = solve(&passive)?;
            let bad: Vec<usize> = (0..p)
                .filter(|&k| bounded[k] && passive[k] && z[k] <= 0.0)
                .collect();
            if bad.is_empty() {
                x = z;
                break;
            }
            let alpha = bad
                .iter()
                .map(|&k| x[k] / (x[k] - z[k]).max(1e-300))
                .fold(1.0f64, f64::min);
            for k in 0..p {
                x[k] += alpha * (z[k] - x[k]);
            }
            for k in 0..p {
                if bounded[k] && passive[k] && x[k] <= 1e-14 {
                    passive[k] = false;
                    x[k] = 0.0;
                }
            }
        }
    }
    let out: Vec<f64> = (0..p).map(|j| x[j] * flip[j] / scale[j]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The effective number of independent samples in a residual pooled over contiguous
/// segments: N / τ, with τ = 1 + 2·Σ_k ρ(k) its integrated autocorrelation time. ρ is
/// computed at lags 1, 2, 3, 4, 6, 8, 12, … (integrated between them by the trapezoid rule)
/// until it falls below 0.05. An autocorrelated residual (a real plant's, or a model's
/// mismatch) carries far fewer independent samples than it has rows; a test of a fit's gain
/// that counted rows would admit effects that only follow that slow structure.
pub fn effective_samples(segments: &[&[f64]]) -> f64 {
    let n: usize = segments.iter().map(|s| s.len()).sum();
    if n < 3 {
        return n as f64;
    }
    let m = segments.iter().flat_map(|s| s.iter()).sum::<f64>() / n as f64;
    let var: f64 = segments
        .iter()
        .flat_map(|s| s.iter())
        .map(|v| (v - m) * (v - m))
        .sum();
    if var <= 0.0 || !var.is_finite() {
        return n as f64;
    }
    let rho = |k: usize| -> f64 {
        let mut s = 0.0;
        for seg in segments {
            for i in k..seg.len() {
                s += (seg[i] - m) * (seg[i - k] - m);
            }
        }
        s / var
    };
    let longest = segments.iter().map(|s| s.len()).max().unwrap_or(0);
    let mut tau = 1.0;
    let (mut k_prev, mut r_prev) = (0usize, 1.0f64);
    let mut k = 1usize;
    while k < longest / 2 {
        let r = rho(k).max(0.0);
        // Σ over the integer lags in (k_prev, k], trapezoid between the two samples of ρ.
        // (ρ linear in between: Σ_{j=1..span} = span·(r + r_prev)/2 + (r − r_prev)/2).
        let span = (k - k_prev) as f64;
        tau += span * (r + r_prev) + (r - r_prev);
        if r < 0.05 {
            break;
        }
        (k_prev, r_prev) = (k, r);
        k = if k < 4 { k + 1 } else { k + k / 2 };
    }
    (n as f64 / tau.max(1.0)).clamp(1.0, n as f64)
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

    #[test]
    fn bounded_least_squares_holds_a_wrong_signed_coefficient_at_zero() {
        // y = 2·a − 0.5·b + 1: with b bounded non-negative, the best is b = 0 and the rest
        // refitted: the least squares of y − 0 on (a, 1), which is exact for a orthogonal to b.
        let a: Vec<f64> = (0..40).map(|i| (i as f64 * 0.3).sin()).collect();
        let b: Vec<f64> = (0..40).map(|i| (i as f64 * 0.7).cos()).collect();
        let one = vec![1.0; 40];
        let y: Vec<f64> = (0..40).map(|i| 2.0 * a[i] - 0.5 * b[i] + 1.0).collect();
        let rows: Vec<usize> = (0..40).collect();
        let free = least_squares(&[&a, &b, &one], &y, &rows).unwrap();
        let c = bounded_least_squares(
            &[&a, &b, &one],
            &[Bound::Free, Bound::Free, Bound::Free],
            &y,
            &rows,
        )
        .unwrap();
        for (u, v) in free.iter().zip(&c) {
            assert!((u - v).abs() < 1e-9, "{free:?} vs {c:?}");
        }
        let c = bounded_least_squares(
            &[&a, &b, &one],
            &[Bound::Free, Bound::NonNegative, Bound::Free],
            &y,
            &rows,
        )
        .unwrap();
        assert_eq!(c[1], 0.0);
        let y2: Vec<f64> = y.iter().zip(&b).map(|(y, b)| y + 0.5 * b).collect();
        let want = least_squares(&[&a, &one], &y2, &rows).unwrap();
        // y − (−0.5·b) is what (a, 1) must now fit: compare the fit of y itself on (a, 1).
        let direct = least_squares(&[&a, &one], &y, &rows).unwrap();
        assert!((c[0] - direct[0]).abs() < 1e-9 && (c[2] - direct[1]).abs() < 1e-9);
        assert!((want[0] - 2.0).abs() < 1e-9);
        // A coefficient that wants its sign keeps it, bounded or not.
        let c = bounded_least_squares(
            &[&a, &b, &one],
            &[Bound::NonNegative, Bound::NonPositive, Bound::Free],
            &y,
            &rows,
        )
        .unwrap();
        assert!(
            (c[0] - 2.0).abs() < 1e-9 && (c[1] + 0.5).abs() < 1e-9,
            "{c:?}"
        );
    }

    #[test]
    fn effective_samples_match_the_ar1_closed_form() {
        // White noise: about N. An AR(1) process with coefficient a: N·(1 − a)/(1 + a).
        let mut state = 12345u64;
        let mut gauss = || {
            // Sum of 12 uniforms − 6: unit variance, near Gaussian; a tiny LCG keeps it pure.
            let mut s = 0.0;
            for _ in 0..12 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            s - 6.0
        };
        let n = 40_000;
        let white: Vec<f64> = (0..n).map(|_| gauss()).collect();
        let ne = effective_samples(&[&white]);
        assert!((ne / n as f64 - 1.0).abs() < 0.1, "{ne}");
        for a in [0.5, 0.9, 0.98] {
            let mut v = 0.0;
            let ar: Vec<f64> = (0..n)
                .map(|_| {
                    v = a * v + gauss();
                    v
                })
                .collect();
            let ne = effective_samples(&[&ar]);
            let want = n as f64 * (1.0 - a) / (1.0 + a);
            assert!((ne / want - 1.0).abs() < 0.3, "a = {a}: {ne} vs {want}");
        }
    }
}
