//! Display decimation, pure: a trailing window of points and a rate gate.

use std::collections::VecDeque;

/// The last `window_ns` of (x, y) points, at most one point per `min_dt_ns`: what a
/// hysteresis loop shows (Rerun has no x–y plot, so the loop is a line strip of these).
#[derive(Debug, Clone)]
pub struct Trail {
    window_ns: u64,
    min_dt_ns: u64,
    points: VecDeque<(u64, [f32; 2])>,
}

impl Trail {
    pub fn new(window_ns: u64, min_dt_ns: u64) -> Self {
        Self {
            window_ns,
            min_dt_ns,
            points: VecDeque::new(),
        }
    }

    /// Adds a point at time `t_ns` unless it comes sooner than `min_dt` after the last one
    /// (non-finite points are dropped); forgets points older than the window. A point earlier
    /// than the last one (a restarted source) starts the trail over.
    pub fn push(&mut self, t_ns: u64, x: f64, y: f64) -> bool {
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        if let Some(&(last, _)) = self.points.back() {
            if t_ns < last {
                self.points.clear();
            } else if t_ns - last < self.min_dt_ns {
                return false;
            }
        }
        self.points.push_back((t_ns, [x as f32, y as f32]));
        while let Some(&(t0, _)) = self.points.front() {
            if t_ns.saturating_sub(t0) > self.window_ns {
                self.points.pop_front();
            } else {
                break;
            }
        }
        true
    }

    pub fn points(&self) -> Vec<[f32; 2]> {
        self.points.iter().map(|(_, p)| *p).collect()
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// The least-squares line y = a + k·x through `points`, as (a, k); `None` for fewer than two
/// points or no spread in x.
pub fn best_line(points: &[[f32; 2]]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let (sx, sy) = points.iter().fold((0.0, 0.0), |(sx, sy), p| {
        (sx + f64::from(p[0]), sy + f64::from(p[1]))
    });
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = points.iter().fold((0.0, 0.0), |(sxx, sxy), p| {
        let dx = f64::from(p[0]) - mx;
        (sxx + dx * dx, sxy + dx * (f64::from(p[1]) - my))
    });
    // No spread in x (or NaN): no line.
    if sxx.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let k = sxy / sxx;
    Some((my - k * mx, k))
}

/// `points` with the line (a, k) taken off their y: a hysteresis loop a few per cent of the
/// torque range, drawn raw, is a straight line; its distance from the spring's best line is
/// the loop itself.
pub fn minus_line(points: &[[f32; 2]], (a, k): (f64, f64)) -> Vec<[f32; 2]> {
    points
        .iter()
        .map(|p| {
            let x = f64::from(p[0]);
            [p[0], (f64::from(p[1]) - a - k * x) as f32]
        })
        .collect()
}

/// The box `points` span: (x centre, x half-width, y half-height about 0), each at least
/// `f32::EPSILON`; `None` without points.
pub fn extent(points: &[[f32; 2]]) -> Option<(f32, f32, f32)> {
    let first = points.first()?;
    let (mut lo, mut hi, mut y) = (first[0], first[0], 0.0f32);
    for p in points {
        lo = lo.min(p[0]);
        hi = hi.max(p[0]);
        y = y.max(p[1].abs());
    }
    Some((
        0.5 * (lo + hi),
        (0.5 * (hi - lo)).max(f32::EPSILON),
        y.max(f32::EPSILON),
    ))
}

/// `points` mapped into ±1 on both axes by the box `(x centre, x half-width, y half-height)`:
/// a view with equal axes (Rerun's 2D views) shows a loop whose height is a few mN·m against
/// a deflection of degrees as a line otherwise.
pub fn to_unit_box(points: &[[f32; 2]], (xc, xh, yh): (f32, f32, f32)) -> Vec<[f32; 2]> {
    points
        .iter()
        .map(|p| [(p[0] - xc) / xh, p[1] / yh])
        .collect()
}

/// A hysteresis loop as the view draws it: both curves minus the reference's best line (the
/// measured curve's, or the model's when nothing is measured), then into ±1 by the
/// reference's box.
pub fn loop_view(measured: &[[f32; 2]], model: &[[f32; 2]]) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let by_model = measured.is_empty();
    let line = best_line(if by_model { model } else { measured }).unwrap_or((0.0, 0.0));
    let (measured, model) = (minus_line(measured, line), minus_line(model, line));
    let unit = extent(if by_model { &model } else { &measured }).unwrap_or((0.0, 1.0, 1.0));
    (to_unit_box(&measured, unit), to_unit_box(&model, unit))
}

/// Lets one event through per `period_ns` of the message clock.
#[derive(Debug, Clone, Copy)]
pub struct Gate {
    period_ns: u64,
    next_ns: Option<u64>,
}

impl Gate {
    pub fn every(period_ns: u64) -> Self {
        Self {
            period_ns,
            next_ns: None,
        }
    }

    /// True when `t_ns` has reached the next slot (or went back in time: a restart).
    pub fn pass(&mut self, t_ns: u64) -> bool {
        match self.next_ns {
            Some(next) if t_ns < next && next - t_ns <= self.period_ns => false,
            _ => {
                self.next_ns = Some(t_ns + self.period_ns);
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trail_keeps_its_window_at_its_rate() {
        // 1 kHz input, 5 ms spacing, 100 ms window: 20 or 21 points whatever the length.
        let mut t = Trail::new(100_000_000, 5_000_000);
        for k in 0..1000u64 {
            t.push(k * 1_000_000, k as f64, -(k as f64));
        }
        assert!((20..=21).contains(&t.len()), "{}", t.len());
        let p = t.points();
        assert_eq!(p[p.len() - 1], [995.0, -995.0]);
        assert_eq!(p[1][0] - p[0][0], 5.0);
        assert!(!t.push(999_000_000, f64::NAN, 0.0));
        // A source that restarts (time goes back) starts the trail over.
        assert!(t.push(3, 1.0, 1.0));
        assert_eq!(t.len(), 1);
    }

    #[test]
    fn a_loop_minus_its_best_line_keeps_only_the_loop() {
        // A loop on a steep line: y = 2 + 30·x ± 0.1 (loading above unloading), x swept
        // up then down over the same points. By symmetry the best line is the backbone
        // itself, and what is left is ±0.1: the loop's half-width, 0.3 % of the range.
        let xs: Vec<f32> = (0..=100).map(|i| i as f32 / 100.0).collect();
        let mut pts: Vec<[f32; 2]> = xs.iter().map(|&x| [x, 2.0 + 30.0 * x + 0.1]).collect();
        pts.extend(xs.iter().rev().map(|&x| [x, 2.0 + 30.0 * x - 0.1]));
        let (a, k) = best_line(&pts).unwrap();
        assert!((a - 2.0).abs() < 1e-4 && (k - 30.0).abs() < 1e-4, "{a} {k}");
        let d = minus_line(&pts, (a, k));
        assert!((d[10][1] - 0.1).abs() < 1e-4, "{:?}", d[10]);
        assert!((d[150][1] + 0.1).abs() < 1e-4, "{:?}", d[150]);
        assert_eq!(d[37][0], pts[37][0], "x is kept");
        assert_eq!(best_line(&pts[..1]), None);
        assert_eq!(best_line(&[[1.0, 0.0], [1.0, 5.0]]), None, "no spread in x");
        // Into the unit box: x from 0..1 to −1..1, the ±0.1 loop to ±1.
        let b = extent(&d).unwrap();
        assert!((b.0 - 0.5).abs() < 1e-6 && (b.1 - 0.5).abs() < 1e-6 && (b.2 - 0.1).abs() < 1e-4);
        let u = to_unit_box(&d, b);
        assert!((u[0][0] + 1.0).abs() < 1e-6 && (u[100][0] - 1.0).abs() < 1e-6);
        assert!((u[10][1] - 1.0).abs() < 1e-3 && (u[150][1] + 1.0).abs() < 1e-3);
        assert_eq!(extent(&[]), None);
        // The view: the measured curve sets line and box; the model is drawn in the same
        // frame, or sets them itself when nothing is measured.
        assert_eq!(loop_view(&pts, &pts), (u.clone(), u.clone()));
        let (m, d) = loop_view(&[], &pts);
        assert!(m.is_empty() && d == u);
    }

    #[test]
    fn a_gate_passes_once_per_period_and_after_a_restart() {
        let mut g = Gate::every(10);
        let passed: Vec<u64> = (0..50).filter(|&t| g.pass(t)).collect();
        assert_eq!(passed, vec![0, 10, 20, 30, 40]);
        assert!(g.pass(5), "time went back beyond a period: a restart");
    }
}
