//! Paper B's restoring-torque model, driven by deflection alone (paper B eq. 7, MODEL.md §2).
//!
//! The loop is made of four segments:
//!
//! ```text
//! loading line     (φ increasing, settled)    τ = k·φ + h
//! unloading line   (φ decreasing, settled)    τ = k·φ − h
//! transition ↑     (after a reversal to ↑)    τ = b + A_s·|φ − a|^n
//! transition ↓     (after a reversal to ↓)    τ = b − A_s·|φ − a|^n
//! ```
//!
//! (a, b) is the vertex of the current power curve: the point where the deflection last
//! reversed. A transition is followed until it meets the envelope line of its direction,
//! then that line is followed until the next reversal — so the loop is continuous.
//! Direction comes from deflection increments with a dead band (at least one encoder count),
//! never from a differentiated velocity. The four parameters (k, h, A_s, n) depend on the
//! pivot position d through a [`RestoringCurve`].
//!
//! **The envelope's shape.** Paper B draws the envelopes as straight lines, `k·φ ± h`. A lever
//! joint's spring torque is not straight in φ: τ = G(φ)·k_α·α(φ) bends (MODEL.md §1), and at
//! the stiff end of the travel its slope at 0.05 rad is half its slope at rest. A line fitted
//! over a bench stroke then reports a secant, not the joint's stiffness. With
//! [`Envelope::Lever`] the lines follow the lever's own curve, `k·s(φ, d) ± h` with
//! `s = τ_lever(φ, d) / k_lever(0, d)` (unit slope at rest): k is then the stiffness at zero
//! deflection and [`RestoringTorqueModel::stiffness`] the slope of the loop's centre line at
//! the current deflection, `k·s′(φ, d)`. Only the lever's geometry (p, d0) enters s; the
//! magnitude stays the calibrated k(d).

use crate::lever::LeverVsa;
use crate::pchip::{InterpError, Pchip};

/// The shape of the envelope lines: `τ = k·s(φ, d) ± h`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Envelope {
    /// Paper B's straight lines, s(φ) = φ.
    #[default]
    Linear,
    /// The lever's static curve, s(φ, d) = G(φ, d)·α(φ, d) / G(0, d)² (MODEL.md §1).
    Lever(LeverVsa),
    /// A joint that softens toward its ends, its geometry not given: s(φ) = φ/√(1 + c·φ²),
    /// c ≥ 0 [1/rad²], slope (1 + c·φ²)^(−3/2). Paper B's lever at a 9 mm pivot over
    /// ±0.2 rad is this curve at c ≈ 13 to 3 % of its secant.
    Softening(f64),
}

impl Envelope {
    /// s(φ, d): the envelope's centre line per unit of k.
    #[inline]
    pub fn s(&self, phi: f64, d: f64) -> f64 {
        match self {
            Self::Linear => phi,
            Self::Lever(v) => v.torque(phi, d) / v.stiffness_at_rest(d),
            Self::Softening(c) => phi / (1.0 + c * phi * phi).sqrt(),
        }
    }

    /// ds/dφ: the centre line's slope per unit of k (1 at φ = 0 for both shapes).
    #[inline]
    pub fn slope(&self, phi: f64, d: f64) -> f64 {
        match self {
            Self::Linear => 1.0,
            Self::Lever(v) => v.stiffness_exact(phi, d) / v.stiffness_at_rest(d),
            Self::Softening(c) => (1.0 + c * phi * phi).powf(-1.5),
        }
    }
}

/// AS5048A, 14 bit: one count is 2π/16384 rad.
pub const AS5048A_COUNT_RAD: f64 = 2.0 * std::f64::consts::PI / 16384.0;

/// The restoring-torque parameters at one pivot position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestoringParams {
    /// Slope of both envelope lines at zero deflection [N·m/rad]: the joint's stiffness at
    /// rest (with [`Envelope::Linear`], everywhere).
    pub k: f64,
    /// Half the gap between the loading and unloading lines [N·m].
    pub h: f64,
    /// Scale of the transition power curves A_s [N·m/rad^n].
    pub a_s: f64,
    /// Exponent of the transition curves n [-].
    pub n: f64,
}

impl RestoringParams {
    /// Whether every value is finite, k, A_s, n positive and h non-negative.
    pub fn is_valid(&self) -> bool {
        [self.k, self.h, self.a_s, self.n]
            .iter()
            .all(|v| v.is_finite())
            && self.k > 0.0
            && self.h >= 0.0
            && self.a_s > 0.0
            && self.n > 0.0
    }
}

/// Parameters as smooth (C¹, monotone-preserving) functions of the pivot position d [m].
///
/// k and A_s span decades over the pivot travel (the lever's k ∝ (d_a/(p − d_a))²), so they
/// are interpolated in log space, which is nearly linear in d for the lever; h and n are
/// interpolated as they are. Between two nodes every value stays within its neighbours'.
#[derive(Debug, Clone, PartialEq)]
pub struct RestoringCurve {
    ln_k: Pchip,
    h: Pchip,
    ln_a_s: Pchip,
    n: Pchip,
    envelope: Envelope,
}

impl RestoringCurve {
    /// Builds the curve from a table of `(d [m], params)` with strictly increasing d and
    /// positive k and A_s.
    pub fn new(table: &[(f64, RestoringParams)]) -> Result<Self, InterpError> {
        let d: Vec<f64> = table.iter().map(|(d, _)| *d).collect();
        let col = |f: fn(&RestoringParams) -> f64| table.iter().map(|(_, p)| f(p)).collect();
        Ok(Self {
            ln_k: Pchip::new(d.clone(), col(|p| p.k.ln()))?,
            h: Pchip::new(d.clone(), col(|p| p.h))?,
            ln_a_s: Pchip::new(d.clone(), col(|p| p.a_s.ln()))?,
            n: Pchip::new(d, col(|p| p.n))?,
            envelope: Envelope::Linear,
        })
    }

    /// The same curve with envelope lines of shape `envelope`.
    #[must_use]
    pub fn with_envelope(mut self, envelope: Envelope) -> Self {
        self.envelope = envelope;
        self
    }

    /// The shape of the envelope lines.
    pub fn envelope(&self) -> Envelope {
        self.envelope
    }

    /// One set of parameters for every pivot position.
    pub fn constant(params: RestoringParams) -> Self {
        // A single node cannot fail to build.
        Self::new(&[(0.0, params)]).unwrap_or_else(|_| unreachable!("one finite node"))
    }

    /// The parameters at pivot position `d` (end values held outside the table).
    pub fn at(&self, d: f64) -> RestoringParams {
        RestoringParams {
            k: self.ln_k.eval(d).exp(),
            h: self.h.eval(d),
            a_s: self.ln_a_s.eval(d).exp(),
            n: self.n.eval(d),
        }
    }

    /// The stiffness at rest the table reaches over the travel [d_lo, d_hi], (lowest, highest)
    /// of its ends (k(d) is monotone there, as a calibrated VSA's is).
    pub fn stiffness_range(&self, d_lo: f64, d_hi: f64) -> (f64, f64) {
        let (a, b) = (self.at(d_lo).k, self.at(d_hi).k);
        (a.min(b), a.max(b))
    }

    /// The pivot position in [d_lo, d_hi] where the stiffness at rest k(d) equals `k`, by
    /// bisection (k(d) must be monotone there, as a calibrated VSA's is). `None` outside.
    pub fn pivot_for_stiffness(&self, k: f64, d_lo: f64, d_hi: f64) -> Option<f64> {
        let rising = self.at(d_hi).k >= self.at(d_lo).k;
        let (lo_k, hi_k) = self.stiffness_range(d_lo, d_hi);
        if !k.is_finite() || k < lo_k || k > hi_k {
            return None;
        }
        let (mut a, mut b) = (d_lo, d_hi);
        for _ in 0..100 {
            let m = 0.5 * (a + b);
            if (self.at(m).k < k) == rising {
                a = m;
            } else {
                b = m;
            }
        }
        Some(0.5 * (a + b))
    }

    /// The table the curve was built from.
    pub fn table(&self) -> Vec<(f64, RestoringParams)> {
        self.ln_k
            .nodes()
            .iter()
            .enumerate()
            .map(|(i, &d)| {
                (
                    d,
                    RestoringParams {
                        k: self.ln_k.values()[i].exp(),
                        h: self.h.values()[i],
                        a_s: self.ln_a_s.values()[i].exp(),
                        n: self.n.values()[i],
                    },
                )
            })
            .collect()
    }
}

/// A reversal of the deflection direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reversal {
    /// The deflection where the motion turned (the extreme reached) [rad].
    pub phi: f64,
    /// The new direction, +1 or −1.
    pub direction: i8,
}

/// Finds reversals of the deflection direction from samples, with a dead band.
///
/// The motion must go back by more than the dead band from the extreme it reached before a
/// reversal is declared; encoder jitter of one count never flips the direction.
#[derive(Debug, Clone, PartialEq)]
pub struct ReversalDetector {
    dead_band: f64,
    direction: i8,
    extreme: f64,
    origin: f64,
}

impl ReversalDetector {
    /// A detector starting at `phi0` with unknown direction. `dead_band` [rad] is clamped to
    /// at least one AS5048A count.
    pub fn new(dead_band: f64, phi0: f64) -> Self {
        let dead_band = if dead_band.is_finite() {
            dead_band.max(AS5048A_COUNT_RAD)
        } else {
            AS5048A_COUNT_RAD
        };
        Self {
            dead_band,
            direction: 0,
            extreme: phi0,
            origin: phi0,
        }
    }

    /// The current direction: +1, −1, or 0 before the first move beyond the dead band.
    pub fn direction(&self) -> i8 {
        self.direction
    }

    /// The extreme deflection reached in the current direction.
    pub fn extreme(&self) -> f64 {
        self.extreme
    }

    /// Feeds a sample. Returns `Some` when the direction reversed (not on the first move).
    /// Also reports whether `phi` set a new extreme.
    pub fn update(&mut self, phi: f64) -> (Option<Reversal>, bool) {
        if self.direction == 0 {
            if (phi - self.origin).abs() > self.dead_band {
                self.direction = if phi > self.origin { 1 } else { -1 };
                self.extreme = phi;
                return (None, true);
            }
            return (None, false);
        }
        let s = f64::from(self.direction);
        if s * (phi - self.extreme) > 0.0 {
            self.extreme = phi;
            (None, true)
        } else if s * (self.extreme - phi) > self.dead_band {
            let rev = Reversal {
                phi: self.extreme,
                direction: -self.direction,
            };
            self.direction = -self.direction;
            self.extreme = phi;
            (Some(rev), true)
        } else {
            (None, false)
        }
    }
}

/// Which of the four segments the model is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Segment {
    /// A power-curve transition after a reversal (or the virgin curve).
    Transition,
    /// The envelope line of the current direction.
    Line,
}

/// The restoring-torque estimator of one joint: feed (φ, d), get τ̂.
#[derive(Debug, Clone)]
pub struct RestoringTorqueModel {
    curve: RestoringCurve,
    detector: Option<ReversalDetector>,
    dead_band: f64,
    segment: Segment,
    vertex: (f64, f64),
    tau_at_extreme: f64,
    tau: f64,
    /// The parameters at the last pivot position seen.
    params_at: Option<(f64, RestoringParams)>,
    /// The last deflection fed [rad].
    phi: f64,
}

impl RestoringTorqueModel {
    /// A model with the given parameter curve and direction dead band [rad].
    pub fn new(curve: RestoringCurve, dead_band: f64) -> Self {
        Self {
            curve,
            detector: None,
            dead_band,
            segment: Segment::Transition,
            vertex: (0.0, 0.0),
            tau_at_extreme: 0.0,
            tau: 0.0,
            params_at: None,
            phi: 0.0,
        }
    }

    /// The parameter curve.
    pub fn curve(&self) -> &RestoringCurve {
        &self.curve
    }

    /// Forgets the loop state (the next sample starts a virgin curve).
    pub fn reset(&mut self) {
        self.detector = None;
        self.segment = Segment::Transition;
    }

    /// The segment the model is on.
    pub fn segment(&self) -> Segment {
        self.segment
    }

    /// The current direction (+1, −1, 0 before the first move).
    pub fn direction(&self) -> i8 {
        self.detector
            .as_ref()
            .map_or(0, ReversalDetector::direction)
    }

    /// The vertex (a, b) of the current power curve.
    pub fn vertex(&self) -> (f64, f64) {
        self.vertex
    }

    /// The last estimate [N·m].
    pub fn torque(&self) -> f64 {
        self.tau
    }

    /// The joint's stiffness at the current state [N·m/rad]: the slope of the loop's centre
    /// line (midway between the envelopes) at the last deflection and pivot fed, k(d)·s′(φ, d).
    /// The transitions' steeper slope after a reversal is the friction sticking, not the
    /// spring, so it is not counted. Before the first sample: k at the first table node.
    pub fn stiffness(&self) -> f64 {
        match self.params_at {
            Some((d, p)) => p.k * self.curve.envelope.slope(self.phi, d),
            None => self.curve.at(self.curve.ln_k.nodes()[0]).k,
        }
    }

    /// Feeds a deflection `phi` [rad] at pivot position `d` [m]; returns the torque [N·m].
    /// Non-finite input leaves the state as it was and returns the last estimate.
    pub fn update(&mut self, phi: f64, d: f64) -> f64 {
        self.update_on(phi, d, self.curve.envelope.s(phi, d))
    }

    /// [`update`](Self::update) with the envelope's centre line per unit of k at this sample,
    /// `s` = `self.curve().envelope().s(phi, d)`, evaluated by the caller. A fit replays the same
    /// samples hundreds of times with other parameters, and a lever's s(φ, d) (an atan2, a
    /// hypot and three cosines) is then most of the replay's cost: it evaluates s once per
    /// sample and feeds it here. Given any other `s`, the loop follows other envelope lines.
    pub fn update_on(&mut self, phi: f64, d: f64, s: f64) -> f64 {
        if !phi.is_finite() || !d.is_finite() {
            return self.tau;
        }
        // The pivot moves slowly, often not at all: evaluate the curve (two exponentials and
        // four interpolations) only when d changes.
        let p = match self.params_at {
            Some((at, p)) if at == d => p,
            _ => {
                let p = self.curve.at(d);
                self.params_at = Some((d, p));
                p
            }
        };
        self.phi = phi;
        let Some(det) = self.detector.as_mut() else {
            // Virgin state: start on the centre line between the envelopes.
            self.detector = Some(ReversalDetector::new(self.dead_band, phi));
            self.segment = Segment::Transition;
            self.vertex = (phi, p.k * s);
            self.tau = self.vertex.1;
            self.tau_at_extreme = self.tau;
            return self.tau;
        };
        let (reversal, new_extreme) = det.update(phi);
        if let Some(rev) = reversal {
            self.vertex = (rev.phi, self.tau_at_extreme);
            self.segment = Segment::Transition;
        }
        let direction = det.direction();
        let centre = p.k * s;
        self.tau = self.evaluate(phi, centre, direction, &p);
        if new_extreme {
            self.tau_at_extreme = self.tau;
        }
        self.tau
    }

    /// The torque at `phi`, given the centre line's torque there, `centre` = k·s(φ, d).
    fn evaluate(&mut self, phi: f64, centre: f64, direction: i8, p: &RestoringParams) -> f64 {
        if direction == 0 {
            // Inside the first dead band: on the centre line, where the virgin state started.
            return centre;
        }
        let (a, b) = self.vertex;
        let s = f64::from(direction);
        let line = centre + s * p.h;
        match self.segment {
            Segment::Line => line,
            Segment::Transition => {
                let u = (s * (phi - a)).max(0.0);
                let curve = b + s * p.a_s * u.powf(p.n);
                if s * (curve - line) >= 0.0 {
                    self.segment = Segment::Line;
                    line
                } else {
                    curve
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> RestoringParams {
        RestoringParams {
            k: 10.0,
            h: 0.2,
            a_s: 8.0,
            n: 0.5,
        }
    }

    fn model() -> RestoringTorqueModel {
        RestoringTorqueModel::new(RestoringCurve::constant(params()), AS5048A_COUNT_RAD)
    }

    #[test]
    fn detector_ignores_jitter_inside_the_dead_band() {
        let mut det = ReversalDetector::new(0.0, 0.0);
        let c = AS5048A_COUNT_RAD;
        det.update(10.0 * c);
        assert_eq!(det.direction(), 1);
        // One count back and forth: no reversal.
        for _ in 0..10 {
            assert_eq!(det.update(9.0 * c).0, None);
            assert_eq!(det.update(10.0 * c).0, None);
        }
        let (rev, _) = det.update(8.0 * c);
        assert_eq!(
            rev,
            Some(Reversal {
                phi: 10.0 * c,
                direction: -1
            })
        );
    }

    #[test]
    fn follows_the_closed_form_segments_of_a_loop() {
        let p = params();
        let mut m = model();
        let step = 1e-4;
        // Rise from 0 to 0.1: the virgin curve τ = A_s·φ^n meets the loading line kφ + h
        // where 8√φ = 10φ + 0.2 (φ ≈ 6.4e-4); beyond it τ = kφ + h exactly.
        let mut phi = 0.0;
        m.update(phi, 0.0);
        while phi < 0.1 - 1e-12 {
            phi += step;
            let tau = m.update(phi, 0.0);
            if phi > 0.01 {
                assert_eq!(m.segment(), Segment::Line);
                assert!((tau - (p.k * phi + p.h)).abs() < 1e-12);
            }
        }
        // Reverse: vertex (0.1, k·0.1 + h); transition τ = b − A_s·(0.1 − φ)^n until it meets
        // the unloading line.
        let b = p.k * 0.1 + p.h;
        let u_meet = {
            // Solve A_s·u^n = 2h + k·u... (curve meets kφ − h) by bisection on [0, 0.05].
            let f = |u: f64| p.a_s * u.powf(p.n) - (2.0 * p.h + p.k * u);
            let (mut lo, mut hi) = (1e-12, 0.05);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if f(mid) < 0.0 { lo = mid } else { hi = mid }
            }
            hi
        };
        let mut saw_transition = false;
        while phi > 0.0 + 1e-12 {
            phi -= step;
            let tau = m.update(phi, 0.0);
            let u = 0.1 - phi;
            if u > AS5048A_COUNT_RAD && u < u_meet - 2.0 * step {
                saw_transition = true;
                assert_eq!(m.segment(), Segment::Transition, "u={u}");
                assert!((tau - (b - p.a_s * u.powf(p.n))).abs() < 1e-12);
            }
            if u > u_meet + 2.0 * step {
                assert_eq!(m.segment(), Segment::Line);
                assert!((tau - (p.k * phi - p.h)).abs() < 1e-12);
            }
        }
        assert!(saw_transition);
        assert!((m.vertex().0 - 0.1).abs() < 1e-9);
    }

    #[test]
    fn loop_is_continuous_at_the_switch_and_the_gap_is_2h() {
        let mut m = model();
        let mut prev: Option<f64> = None;
        let mut max_jump: f64 = 0.0;
        for i in 0..4000 {
            let phi = 0.1 * (i as f64 * 2.0 * std::f64::consts::PI / 1000.0).sin();
            let tau = m.update(phi, 0.0);
            if let Some(p) = prev {
                max_jump = max_jump.max((tau - p).abs());
            }
            prev = Some(tau);
        }
        // The largest step per sample is bounded by the steepest part of a transition, with
        // no jumps from re-anchoring: 8·√(6.3e-4 − 0) ≈ 0.2 N·m worst case.
        assert!(max_jump < 0.25, "jump {max_jump}");
        // At φ = 0 on the way up and down the torque differs by 2h.
        let mut m = model();
        for i in 0..=1000 {
            m.update(
                0.1 * (i as f64 * 2.0 * std::f64::consts::PI / 1000.0).sin(),
                0.0,
            );
        }
        let up = m.torque(); // at φ = 0 going up after a full cycle: on the loading line
        assert!((up - params().h).abs() < 1e-9, "{up}");
    }

    #[test]
    fn curve_interpolates_over_d_and_holds_ends() {
        let p0 = RestoringParams {
            k: 0.25,
            h: 0.01,
            a_s: 1.0,
            n: 0.5,
        };
        let p1 = RestoringParams {
            k: 65.0,
            h: 0.3,
            a_s: 30.0,
            n: 0.7,
        };
        let c = RestoringCurve::new(&[(0.0, p0), (0.018, p1)]).unwrap();
        // Ends held (k and A_s round-trip through ln/exp: equal to rounding).
        let close = |a: RestoringParams, b: RestoringParams| {
            (a.k - b.k).abs() < 1e-12 * b.k
                && a.h == b.h
                && (a.a_s - b.a_s).abs() < 1e-12 * b.a_s
                && a.n == b.n
        };
        assert!(close(c.at(-1.0), p0));
        assert!(close(c.at(1.0), p1));
        // Two nodes: geometric interpolation of k (linear in ln k), arithmetic of h.
        let mid = c.at(0.009);
        assert!((mid.k - (0.25f64 * 65.0).sqrt()).abs() < 1e-9);
        assert!((mid.h - 0.155).abs() < 1e-12);
        assert_eq!(c.table().len(), 2);
        assert!((c.table()[1].1.k - 65.0).abs() < 1e-12);
        let d = c
            .pivot_for_stiffness((0.25f64 * 65.0).sqrt(), 0.0, 0.018)
            .unwrap();
        assert!((d - 0.009).abs() < 1e-12);
        assert!(c.pivot_for_stiffness(70.0, 0.0, 0.018).is_none());
        assert!(RestoringCurve::new(&[(0.01, p0), (0.0, p1)]).is_err());
    }

    #[test]
    fn with_a_lever_envelope_the_lines_follow_the_lever_and_the_stiffness_is_the_centre_lines_slope()
     {
        let vsa = crate::lever::LeverVsa::paper_b();
        let d = 0.014;
        let p = RestoringParams {
            k: 0.95 * vsa.stiffness_at_rest(d),
            h: 0.05,
            a_s: 60.0,
            n: 0.6,
        };
        let mut m = RestoringTorqueModel::new(
            RestoringCurve::constant(p).with_envelope(Envelope::Lever(vsa)),
            AS5048A_COUNT_RAD,
        );
        let s = |phi: f64| vsa.torque(phi, d) / vsa.stiffness_at_rest(d);
        let mut phi = 0.0;
        m.update(phi, d);
        while phi < 0.06 {
            phi += 1e-4;
            let tau = m.update(phi, d);
            if phi > 0.02 {
                assert_eq!(m.segment(), Segment::Line, "phi {phi}");
                assert!((tau - (p.k * s(phi) + p.h)).abs() < 1e-12);
                // The slope of the centre line k·s(φ), by central differences.
                let fd = p.k * (s(phi + 1e-6) - s(phi - 1e-6)) / 2e-6;
                assert!(
                    (m.stiffness() - fd).abs() < 1e-6 * fd,
                    "{} vs {fd}",
                    m.stiffness()
                );
            }
        }
        // At 0.06 rad the lever has softened: the slope is well below k.
        assert!(m.stiffness() < 0.85 * p.k);
        // Straight lines: the slope is k everywhere.
        let mut lin = RestoringTorqueModel::new(RestoringCurve::constant(p), AS5048A_COUNT_RAD);
        lin.update(0.0, d);
        lin.update(0.06, d);
        assert!((lin.stiffness() - p.k).abs() < 1e-12 * p.k);
    }

    #[test]
    fn nan_input_keeps_state() {
        let mut m = model();
        m.update(0.0, 0.0);
        let t = m.update(0.05, 0.0);
        assert_eq!(m.update(f64::NAN, 0.0), t);
        assert_eq!(m.update(0.05, f64::INFINITY), t);
    }
}
