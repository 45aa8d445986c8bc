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
    fn a_gate_passes_once_per_period_and_after_a_restart() {
        let mut g = Gate::every(10);
        let passed: Vec<u64> = (0..50).filter(|&t| g.pass(t)).collect();
        assert_eq!(passed, vec![0, 10, 20, 30, 40]);
        assert!(g.pass(5), "time went back beyond a period: a restart");
    }
}
