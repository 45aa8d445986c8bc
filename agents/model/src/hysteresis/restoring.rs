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
//! **A transition that never meets its line.** With n < 1 the power curve is steepest at its
//! vertex and flattens; if its slope falls to the line's before it has closed the gap, it
//! never meets the line, and read literally it would run on, ever flatter, away from the loop
//! for the rest of the swing. Which of the two happens turns on a hair's breadth of the
//! parameters (straight lines: the curve closes at most k·u*·(1/n − 1) of the gap, u* =
//! (A_s·n/k)^(1/(1−n))), so two fits a hair either side of that edge put the loop's torque on
//! one held-out swing up to 65 mN·m apart (docs/IDENTIFY.md, the fifth generator's drift
//! seed 4). Here such a transition stops at its closest approach, the point where its slope
//! equals the line's, and from there runs parallel to the line at that distance until the next
//! reversal: the same where the curve meets the line, continuous in the parameters where it
//! does not. A fit holds h to the gap its transitions can
//! close within the widest swing of its data ([`RestoringParams::meeting_within`]), so that h
//! stays the loop's half-height and the loop is one the data show closed: a taller loop never
//! meets its lines there, and runs between reversals as a line whose level is wherever its
//! start left it — a torque offset the loop would hold.
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
    /// The most of the gap between the lines that a transition can close, against straight
    /// lines of slope k: unbounded for n ≥ 1 (n = 1: while A_s > k); for n < 1 the curve's
    /// excess A_s·u^n − k·u over the line is largest at u* = (A_s·n/k)^(1/(1−n)), where the
    /// slopes match, and is k·u*·(1/n − 1) there [N·m].
    pub fn closable_gap(&self) -> f64 {
        if self.n > 1.0 || (self.n == 1.0 && self.a_s > self.k) {
            return f64::INFINITY;
        }
        if self.n == 1.0 {
            return 0.0;
        }
        self.k * self.excess_peak() * (1.0 / self.n - 1.0)
    }

    /// For n < 1, u* = (A_s·n/k)^(1/(1−n)): where the transition's slope falls to the line's
    /// and its excess over the line peaks [rad].
    fn excess_peak(&self) -> f64 {
        ((self.a_s * self.n / self.k).ln() / (1.0 - self.n)).exp()
    }

    /// The most of the gap a transition closes within a swing of `span` [rad] from its vertex,
    /// against straight lines of slope k: max over 0 ≤ u ≤ span of A_s·u^n − k·u (never
    /// negative). The excess is concave for n < 1, so it is [`closable_gap`](Self::closable_gap)
    /// where its peak u* lies within the span and its value at the span otherwise; for n ≥ 1
    /// it is largest at the span.
    pub fn closable_within(&self, span: f64) -> f64 {
        // No swing (or not a number): nothing closes.
        if span.is_nan() || span <= 0.0 {
            return 0.0;
        }
        if span == f64::INFINITY {
            return self.closable_gap();
        }
        if self.n < 1.0 && self.excess_peak() < span {
            return self.closable_gap();
        }
        (self.a_s * span.powf(self.n) - self.k * span).max(0.0)
    }

    /// The same loop with h at most half of what a transition closes over `span`, the widest
    /// swing the data hold: a loop the data can show. A taller one never reaches its lines on
    /// them, and then k and h are not the lines' at all: its transitions run between
    /// reversals as a line of slope ≈ A_s whose level the start left it at, an offset the
    /// loop should not hold (a bench recording's 0.02 N·m offset was held that way, h fitted
    /// at 0.21 N·m on an 80 mrad stroke). `span = ∞` is [`meeting`](Self::meeting).
    #[must_use]
    pub fn meeting_within(self, span: f64) -> Self {
        Self {
            h: self.h.min(0.5 * self.closable_within(span)),
            ..self
        }
    }

    /// The same loop with h at most half the [closable gap](Self::closable_gap): one whose
    /// transitions reach the opposite line after a full swing, as paper B's loop does, so that
    /// h is the loop's half-height. (Past that edge the model runs parallel to the line, see
    /// the module docs, and a fit could trade h against A_s and n with the loop unchanged.)
    /// Where a lever's lines soften away from rest their slope is below k and the curve meets
    /// them sooner.
    #[must_use]
    pub fn meeting(self) -> Self {
        self.meeting_within(f64::INFINITY)
    }

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
    /// A detector starting at `phi0` with unknown direction. `dead_band` [rad] is used as
    /// given; where it is not finite and positive it is one count of the rig's own AS5048A.
    /// It is not clamped to that count: a finer encoder (a measured spring's AS5311, 14 µrad)
    /// swings less than one AS5048A count at small loads, and a dead band of 0.38 mrad would
    /// give it no direction (`rig identify` takes at most a tenth of the data's swing).
    pub fn new(dead_band: f64, phi0: f64) -> Self {
        let dead_band = if dead_band.is_finite() && dead_band > 0.0 {
            dead_band
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
    /// Parallel to the envelope line, at the closest approach of a transition that never met
    /// it (n < 1; module docs).
    Parallel,
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
    /// How far the current transition is from its line, at the last new extreme [N·m] (in
    /// [`Segment::Parallel`], the distance kept).
    gap: f64,
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
            gap: f64::INFINITY,
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
            self.gap = f64::INFINITY;
            self.tau = self.vertex.1;
            self.tau_at_extreme = self.tau;
            return self.tau;
        };
        let (reversal, new_extreme) = det.update(phi);
        if let Some(rev) = reversal {
            self.vertex = (rev.phi, self.tau_at_extreme);
            self.segment = Segment::Transition;
            self.gap = f64::INFINITY;
        }
        let direction = det.direction();
        let centre = p.k * s;
        self.tau = self.evaluate(phi, centre, (direction, new_extreme), &p);
        if new_extreme {
            self.tau_at_extreme = self.tau;
        }
        self.tau
    }

    /// The torque at `phi`, given the centre line's torque there, `centre` = k·s(φ, d), the
    /// direction and whether `phi` is a new extreme of it.
    fn evaluate(
        &mut self,
        phi: f64,
        centre: f64,
        (direction, new_extreme): (i8, bool),
        p: &RestoringParams,
    ) -> f64 {
        if direction == 0 {
            // Inside the first dead band: on the centre line, where the virgin state started.
            return centre;
        }
        let (a, b) = self.vertex;
        let s = f64::from(direction);
        let line = centre + s * p.h;
        match self.segment {
            Segment::Line => line,
            Segment::Parallel => line - s * self.gap,
            Segment::Transition => {
                let u = (s * (phi - a)).max(0.0);
                let curve = b + s * p.a_s * u.powf(p.n);
                let gap = s * (line - curve);
                if gap <= 0.0 {
                    self.segment = Segment::Line;
                    line
                } else if new_extreme && p.n < 1.0 && gap > self.gap {
                    // Further along, and further from the line than at the last extreme: the
                    // closest approach is behind. (Only new extremes count: a count of jitter
                    // back inside the dead band moves the curve back toward its vertex.)
                    self.segment = Segment::Parallel;
                    line - s * self.gap
                } else {
                    if new_extreme {
                        self.gap = gap;
                    }
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
    fn a_transition_that_cannot_reach_its_line_runs_parallel_to_it_from_its_closest_approach() {
        // k = 10, h = 0.2, n = 0.5. Down from the loading line at φ = 0.1, the curve
        // b − A_s·√u closes g(u) = A_s·√u − k·u of the 2h = 0.4 gap; g is largest at
        // u* = (A_s·n/k)², where the curve's slope is the line's. With A_s = 4 that is
        // g(0.04) = 0.8 − 0.4 = 2h: it just touches. With A_s = 3.6 it closes g(0.0324) =
        // 0.648 − 0.324 = 0.324 and never meets the line: from u* on it runs 2h − 0.324 =
        // 0.076 N·m above the unloading line, at that line's slope, until the next reversal.
        let p = RestoringParams {
            a_s: 3.6,
            ..params()
        };
        let mut m = RestoringTorqueModel::new(RestoringCurve::constant(p), AS5048A_COUNT_RAD);
        let step = 1e-5;
        let mut phi = 0.0;
        m.update(phi, 0.0);
        while phi < 0.1 - 1e-12 {
            phi += step;
            m.update(phi, 0.0);
        }
        let (a, b) = (phi, p.k * phi + p.h);
        let u_star = (p.a_s * p.n / p.k).powi(2);
        let closest = 2.0 * p.h - (p.a_s * u_star.sqrt() - p.k * u_star);
        assert!((closest - 0.076).abs() < 1e-12);
        while phi > -0.1 {
            phi -= step;
            let tau = m.update(phi, 0.0);
            let u = a - phi;
            if u > AS5048A_COUNT_RAD && u < u_star - 2.0 * step {
                assert_eq!(m.segment(), Segment::Transition, "u={u}");
                assert!((tau - (b - p.a_s * u.sqrt())).abs() < 1e-12);
            } else if u > u_star + 2.0 * step {
                assert_eq!(m.segment(), Segment::Parallel, "u={u}");
                // Within the curve's change over a sample of the closest approach.
                let off = tau - (p.k * phi - p.h);
                assert!((off - closest).abs() < 1e-6, "u={u}: {off} vs {closest}");
            }
        }
        // The next reversal starts a transition from where the parallel line left the loop,
        // and the curve that does meet its line (A_s = 8, `params`) never runs parallel.
        phi += 0.01;
        m.update(phi, 0.0);
        assert_eq!(m.segment(), Segment::Transition);
        assert!(!segments_over_a_sine(params(), 1000, 4).contains(&Segment::Parallel));
    }

    /// The segment after each sample of `periods` periods of 0.1·sin, `per_period` samples
    /// each, replayed through a loop with `p` everywhere.
    fn segments_over_a_sine(p: RestoringParams, per_period: usize, periods: usize) -> Vec<Segment> {
        let mut m = RestoringTorqueModel::new(RestoringCurve::constant(p), AS5048A_COUNT_RAD);
        (0..per_period * periods)
            .map(|i| {
                let phi = 0.1 * (i as f64 * std::f64::consts::TAU / per_period as f64).sin();
                m.update(phi, 0.0);
                m.segment()
            })
            .collect()
    }

    #[test]
    fn a_loop_held_to_its_closable_gap_meets_its_lines_and_one_past_it_does_not() {
        // A_s = 3.6, n = 0.5, k = 10: the curve closes at most 0.324 (the test above). Held to
        // it, h = 0.162 and a full swing's transition just meets the line; with h = 0.2 it
        // runs parallel. n ≥ 1 closes any gap; n = 1 only while A_s > k.
        let past = RestoringParams {
            a_s: 3.6,
            ..params()
        };
        assert!((past.closable_gap() - 0.324).abs() < 1e-12);
        let held = past.meeting();
        assert!((held.h - 0.162).abs() < 1e-12);
        assert_eq!(params().meeting(), params());
        let n1 = |a_s| RestoringParams {
            a_s,
            n: 1.0,
            ..params()
        };
        assert_eq!(n1(12.0).closable_gap(), f64::INFINITY);
        assert_eq!(n1(8.0).closable_gap(), 0.0);
        let n2 = RestoringParams { n: 2.0, ..params() };
        assert_eq!(n2.meeting(), n2);
        let segments = |p| segments_over_a_sine(p, 20_000, 2);
        // (At the edge itself the curve touches the line: a sample may stop a hair short.)
        assert!(segments(past).contains(&Segment::Parallel));
        let inside = segments(RestoringParams { h: 0.16, ..past });
        assert!(!inside.contains(&Segment::Parallel) && inside.contains(&Segment::Line));
    }

    #[test]
    fn a_loop_held_to_the_gap_its_datas_widest_swing_closes_meets_its_lines_on_that_swing() {
        // n = 1, A_s = 15, k = 10: a transition closes (A_s − k)·u, so over a swing of 0.2
        // (the sine ±0.1 below) at most 1.0: h ≤ 0.5. A loop with h = 2 never meets its lines
        // there and runs between reversals as a line of slope A_s; held, it meets them.
        let tall = RestoringParams {
            k: 10.0,
            h: 2.0,
            a_s: 15.0,
            n: 1.0,
        };
        assert!((tall.closable_within(0.2) - 1.0).abs() < 1e-12);
        let held = tall.meeting_within(0.2);
        assert!((held.h - 0.5).abs() < 1e-12);
        assert_eq!(tall.meeting_within(f64::INFINITY), tall.meeting());
        let segments = |p| segments_over_a_sine(p, 20_000, 2);
        assert!(!segments(tall).contains(&Segment::Line));
        assert!(segments(RestoringParams { h: 0.45, ..held }).contains(&Segment::Line));
        // n < 1 whose excess peaks inside the span: the closable gap itself (0.324, above);
        // past it, the excess at the span: 3.6·√0.01 − 10·0.01 = 0.26.
        let concave = RestoringParams {
            a_s: 3.6,
            ..params()
        };
        assert!((concave.closable_within(0.2) - 0.324).abs() < 1e-12);
        assert!((concave.closable_within(0.01) - 0.26).abs() < 1e-12);
        // n > 1 is below its line near the vertex: nothing closes over a short swing.
        let convex = RestoringParams { n: 2.0, ..params() };
        assert_eq!(convex.closable_within(0.1), 0.0);
        assert_eq!(convex.closable_within(0.0), 0.0);
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
