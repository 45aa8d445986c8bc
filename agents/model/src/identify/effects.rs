//! The library of candidate effects (MODEL.md §6.1). Each is a change to the plant at a
//! physical place, and its prediction is the declared model evaluated on the changed plant:
//!
//! - on the **inputs** the declared model sees (a sensor delay shifts them in time, backlash
//!   passes the deflection through a dead zone, an encoder offset shifts it — the last
//!   linearised through the declared model's own slope dτ̂/dx, exact for a linear spring);
//! - on the **torque** (a torque-sensor offset, friction, a hard stop, gravity, ripple);
//! - on the **spring** (hysteresis as friction inside it, a drift of its stiffness scaling
//!   the declared model's elastic torque).
//!
//! Passive effects keep their sign: friction and hysteresis dissipate (loading above
//! unloading), a stop stiffens. The fit enforces that as a bound, not as a filter afterwards.

use std::fmt;

use super::model::Signals;
use super::signals::stop_operator_from;
use super::stats::Bound;

/// An effect a declared model may lack. Names are those of the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Effect {
    Hysteresis,
    CoulombFriction,
    ViscousFriction,
    Backlash,
    HardStop,
    GeometricStiffness,
    SensorDelay,
    Offset,
    StiffnessDrift,
    Gravity,
    PeriodicRipple,
}

impl Effect {
    pub const ALL: [Effect; 11] = [
        Effect::Hysteresis,
        Effect::CoulombFriction,
        Effect::ViscousFriction,
        Effect::Backlash,
        Effect::HardStop,
        Effect::GeometricStiffness,
        Effect::SensorDelay,
        Effect::Offset,
        Effect::StiffnessDrift,
        Effect::Gravity,
        Effect::PeriodicRipple,
    ];

    /// The name used in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Hysteresis => "hysteresis",
            Effect::CoulombFriction => "coulomb_friction",
            Effect::ViscousFriction => "viscous_friction",
            Effect::Backlash => "backlash",
            Effect::HardStop => "hard_stop",
            Effect::GeometricStiffness => "geometric_stiffness",
            Effect::SensorDelay => "sensor_delay",
            Effect::Offset => "offset",
            Effect::StiffnessDrift => "stiffness_drift",
            Effect::Gravity => "gravity",
            Effect::PeriodicRipple => "periodic_ripple",
        }
    }

    /// What it means physically and how it enters the prediction (x: deflection φ for the
    /// joint torque, link angle q for the link equation; τ̂ the declared model).
    pub fn meaning(self) -> &'static str {
        match self {
            Effect::Hysteresis => {
                "friction in the spring or the lever: τ̂ + Σ wᵢ·s_rᵢ(x), a Prandtl–Ishlinskii sum of stop operators with wᵢ ≥ 0 (loading above unloading: it dissipates)"
            }
            Effect::CoulombFriction => {
                "dry friction where the part moves: + F_c·sgn(ẋ), F_c ≥ 0, the direction from a centred rate with a dead band; where the motion stops the force is released (0) or held (a stuck contact keeps it: held_at_rest = 1); or built up over a small speed, + F_c·tanh(ẋ/v_s) (builds_over_rad_per_s = v_s), whichever the data shows"
            }
            Effect::ViscousFriction => "viscous friction where the part moves: + b·ẋ, b ≥ 0",
            Effect::Backlash => {
                "a gap of total width 2r in series with the spring: the spring is unloaded inside it, τ̂(sgn x·max(|x| − r, 0))"
            }
            Effect::HardStop => {
                "the spring meets a stop on either side: + k₊·max(x − x₊, 0) + k₋·min(x + x₋, 0), k± ≥ 0 (stiffening beyond x₊ wound and beyond −x₋ unwound; one side's k may be 0)"
            }
            Effect::GeometricStiffness => {
                "the lever's exact torque τ(φ, d) less its linearisation G(0)²k_α·φ (the k_α·α·dG/dφ term that k_φ = G²k_α drops)"
            }
            Effect::SensorDelay => {
                "one sensor path lags the other: the declared model is fed x(t − δ); δ > 0 the torque lags the deflection, δ < 0 the deflection lags the torque; on the link equation and a linear spring the lag may instead be a sensor's first-order low-pass of time constant |δ| (first_order_filter = 1)"
            }
            Effect::Offset => {
                "a sensor zero: on the torque sensor (+ c, and + c₂ after t_j when a mount slips) or on the deflection encoder (a zero slip: τ̂(x − s) after t_j)"
            }
            Effect::StiffnessDrift => {
                "the spring's stiffness changes over the run (temperature, creep): the declared model's elastic torque × (1 + c·t); or at once part-way (a spring that re-seats in its clamp): × (1 + c·1[t ≥ t_j])"
            }
            Effect::Gravity => "gravity on the link: + m·g·l·sin(q + q₀)",
            Effect::PeriodicRipple => {
                "ripple periodic in the angle a part turns with (gear teeth, cogging, encoder eccentricity): + A·sin(2π·θ/P + ψ)"
            }
        }
    }

    /// Parses a report name.
    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s)
    }

    /// Whether it acts by changing the inputs the declared model sees (not by adding columns).
    pub(crate) fn is_input(self) -> bool {
        matches!(self, Effect::SensorDelay | Effect::Backlash)
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Which sensor an offset sits on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    Torque,
    Deflection,
}

impl Place {
    pub fn name(self) -> &'static str {
        match self {
            Place::Torque => "torque",
            Place::Deflection => "deflection",
        }
    }
}

/// Dry friction's shape when the force is held where the motion stops (a stuck contact keeps
/// it). NaN is the force released there, F_c·sgn(ẋ); a positive shape is a speed v_s [rad/s]
/// over which the force builds up, F_c·tanh(ẋ/v_s) (a contact that slides a little before it
/// slips: a lubricated bearing, a bristle model's steady state).
pub(crate) const FRICTION_HELD: f64 = -1.0;

/// One effect with its shape fixed: a delay [s], a gap or stop [rad], a jump time [s] (NaN:
/// a constant offset), a period [rad], a loop's initial state (−1, 0, +1), dry friction
/// released (NaN) or held ([`FRICTION_HELD`]) at rest or built up over a speed [rad/s]; NaN
/// when none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shaped {
    pub effect: Effect,
    pub shape: f64,
    /// For offsets: which sensor.
    pub on: Place,
    /// For an encoder offset: the correction δ the declared model's input gets, x + δ after
    /// t_j [rad]. NaN while it is searched (then it is a column linearised through the
    /// model's slope); once known, the model is replayed on the corrected input.
    pub size: f64,
    /// For viscous friction on a joint model: the sensor delay (< 0: the deflection lags) [s]
    /// that validated as well and was not named for it, else NaN. Reported only.
    pub delay_alike: f64,
    /// For a hard stop: the onset x₋ > 0 of the stop on the negative side [rad] (`shape` is
    /// x₊, the positive side's). A torsion spring wound and unwound meets different stops at
    /// different deflections. NaN where the data never reaches that side.
    pub lower: f64,
    /// For a hard stop: one stop, the same onset and rate on both sides (`lower` = `shape`),
    /// MODEL.md §6.1's k_s·max(|x| − x_s, 0)·sgn x. Where the data barely passes one side's
    /// onset, that side's own onset and rate trade off and extrapolate badly.
    pub symmetric: bool,
    /// For a sensor delay: the lagging path is a first-order low-pass of time constant
    /// |`shape`| (a sensor's filter) rather than a pure delay (a transport or sampling
    /// latency). The two agree to first order and part at the second: a delay δ is
    /// 1 − δ·s + δ²·s²/2, a filter T is 1 − T·s + T²·s², and through the link equation's
    /// inertia the difference is I·T²·q⁗/2, which a pure delay leaves for a companion.
    pub filter: bool,
}

impl Shaped {
    /// A jump at an instant (`shape`, s): an offset's step or a stiffness step, not a constant
    /// or a drift.
    pub(crate) fn is_jump(&self) -> bool {
        matches!(self.effect, Effect::Offset | Effect::StiffnessDrift) && self.shape.is_finite()
    }

    pub(crate) fn new(effect: Effect, shape: f64) -> Self {
        Self {
            effect,
            shape,
            on: Place::Torque,
            size: f64::NAN,
            delay_alike: f64::NAN,
            lower: f64::NAN,
            symmetric: false,
            filter: false,
        }
    }

    /// A hard stop at x₊ on the positive side and −x₋ on the negative (either NaN: none).
    pub(crate) fn stops(upper: f64, lower: f64) -> Self {
        Self {
            lower,
            ..Self::new(Effect::HardStop, upper)
        }
    }

    /// One hard stop at x_s on both sides, one rate.
    pub(crate) fn symmetric_stop(at: f64) -> Self {
        Self {
            symmetric: true,
            ..Self::stops(at, at)
        }
    }

    /// Whether two have the same shape (the searched numbers, NaN equal to NaN).
    pub(crate) fn same_shape(&self, other: &Shaped) -> bool {
        let eq = |a: f64, b: f64| a == b || (a.is_nan() && b.is_nan());
        eq(self.shape, other.shape)
            && eq(self.lower, other.lower)
            && self.symmetric == other.symmetric
            && self.filter == other.filter
    }

    /// Whether it acts by changing the inputs the declared model sees (a lag, a gap, an
    /// encoder offset of known size) rather than by adding columns.
    pub(crate) fn is_input(&self) -> bool {
        self.effect.is_input() || (self.on == Place::Deflection && self.size.is_finite())
    }

    /// Feature columns with the sign each coefficient must keep (input effects add none:
    /// they change the signals).
    pub(crate) fn columns(&self, s: &Signals) -> Vec<(Vec<f64>, Bound)> {
        let cols = self.raw_columns(s);
        if s.weak.is_none() {
            return cols;
        }
        cols.into_iter().map(|(c, b)| (s.smoothed(c), b)).collect()
    }

    /// [`Self::columns`] before the weak form's smoother.
    fn raw_columns(&self, s: &Signals) -> Vec<(Vec<f64>, Bound)> {
        let xs = &s.xs;
        let r = self.shape;
        let step = |tj: f64| s.step(tj);
        match self.effect {
            Effect::Hysteresis => s
                .stop_columns(s.states.is_none().then_some(r), || {
                    (s.widths.iter())
                        .map(|&w| {
                            s.per_run_k(|k, a, b| {
                                let state = s.states.as_ref().map_or(r, |v| v[k]);
                                stop_operator_from(&xs[a..b], w, state * w)
                            })
                        })
                        .collect()
                })
                .into_iter()
                .map(|c| (c, Bound::NonNegative))
                .collect(),
            Effect::CoulombFriction if r == FRICTION_HELD => {
                vec![(s.dir_held.clone(), Bound::NonNegative)]
            }
            Effect::CoulombFriction if r > 0.0 => vec![(
                s.sign_rate.iter().map(|v| (v / r).tanh()).collect(),
                Bound::NonNegative,
            )],
            Effect::CoulombFriction => vec![(s.dir.clone(), Bound::NonNegative)],
            Effect::ViscousFriction => vec![(s.xdot.clone(), Bound::NonNegative)],
            // The live stop's own torque at unit rate on both sides.
            Effect::HardStop if self.symmetric => {
                let unit = crate::live::HardStop {
                    onset_rad: r,
                    rate_nm_per_rad: 1.0,
                    onset_negative_rad: -r,
                    rate_negative_nm_per_rad: 1.0,
                };
                vec![(
                    xs.iter().map(|&v| unit.torque(v)).collect(),
                    Bound::NonNegative,
                )]
            }
            // Each side's column is ≤ 0 or ≥ 0 with the side, so k± ≥ 0 stiffens.
            Effect::HardStop => [(r, 1.0), (self.lower, -1.0)]
                .into_iter()
                .filter(|(at, _)| at.is_finite())
                .map(|(at, side)| {
                    (
                        xs.iter()
                            .map(|&v| crate::live::stop_side(v, at, side))
                            .collect(),
                        Bound::NonNegative,
                    )
                })
                .collect(),
            Effect::GeometricStiffness => match &s.lever {
                Some(vsa) => vec![(
                    xs.iter()
                        .zip(&s.d)
                        .map(|(&p, &d)| vsa.torque(p, d) - vsa.stiffness_at_rest(d) * p)
                        .collect(),
                    Bound::Free,
                )],
                None => vec![],
            },
            Effect::SensorDelay | Effect::Backlash => vec![],
            Effect::Offset => {
                let mut cols = Vec::new();
                match (self.on, &s.slope) {
                    // Known size: it is in the signals' input already.
                    (Place::Deflection, _) if self.size.is_finite() => {}
                    (Place::Deflection, Some(slope)) => {
                        // τ̂(x + δ·1[t ≥ t_j]) ≈ τ̂(x) + δ·1[t ≥ t_j]·dτ̂/dx.
                        let h = if r.is_finite() {
                            step(r)
                        } else {
                            vec![1.0; xs.len()]
                        };
                        cols.push((
                            h.iter().zip(slope).map(|(h, k)| h * k).collect(),
                            Bound::Free,
                        ));
                    }
                    _ => {
                        if !s.base_has_intercept {
                            cols.push((vec![1.0; xs.len()], Bound::Free));
                        }
                        if r.is_finite() {
                            cols.push((step(r), Bound::Free));
                        }
                    }
                }
                cols
            }
            // The elastic torque × t over the run, or × 1[t ≥ t_j] for a step.
            Effect::StiffnessDrift => s
                .elastic
                .iter()
                .map(|c| {
                    let col = if r.is_finite() {
                        c.iter().zip(s.step(r)).map(|(v, h)| v * h).collect()
                    } else {
                        c.iter().zip(&s.t_rel).map(|(v, t)| v * t).collect()
                    };
                    (col, Bound::Free)
                })
                .collect(),
            Effect::Gravity => match &s.q {
                Some(q) => vec![
                    (q.iter().map(|q| q.sin()).collect(), Bound::Free),
                    (q.iter().map(|q| q.cos()).collect(), Bound::Free),
                ],
                None => vec![],
            },
            Effect::PeriodicRipple => {
                let w = std::f64::consts::TAU / r;
                // Tared runs read zero at rest (zero deflection), where the ripple's cosine
                // part is 1: the tare took that share as the torque zero, so the column does
                // too (else an offset must come back to add it again).
                let at_rest = if s.zero_at_rest { 1.0 } else { 0.0 };
                vec![
                    (s.angle.iter().map(|a| (w * a).sin()).collect(), Bound::Free),
                    (
                        s.angle.iter().map(|a| (w * a).cos() - at_rest).collect(),
                        Bound::Free,
                    ),
                ]
            }
        }
    }

    /// Parameters the selection criterion charges for: the fitted coefficients that are not
    /// held at zero by their bound, plus one for a searched shape (`joint`: a joint-torque
    /// model, not the link equation).
    pub(crate) fn parameters(&self, coefs: &[f64], joint: bool) -> usize {
        let fitted = coefs.iter().filter(|c| **c != 0.0).count();
        let shaped = usize::from(self.shape.is_finite() && self.effect != Effect::Hysteresis);
        match self.effect {
            // Each side that stiffens has its onset searched.
            Effect::HardStop if self.symmetric => 2,
            Effect::HardStop => (2 * fitted).max(1),
            // A torque that leads the deflection is, to first order in δ, viscous friction
            // k·δ·ẋ; in the link equation either lag is, to first order, a change of the
            // inertia (N·δ·q̈). Such a delay is charged one parameter more, so that it is
            // named only where the higher orders show (the simpler claim wins a tie).
            Effect::SensorDelay if self.shape < 0.0 || !joint => 2,
            Effect::SensorDelay | Effect::Backlash => 1,
            // A slip part-way: δ and t_j. A constant encoder offset equals a torque offset k·δ
            // through a linear spring: it is charged one parameter more, named only where the
            // model's curvature tells them apart (a constant zero is the torque sensor's more
            // often; a slip part-way, a mount's).
            Effect::Offset if self.on == Place::Deflection => 2,
            _ => (fitted + shaped).max(1),
        }
    }

    /// Named parameters from the shape and the fitted coefficients of its columns. `base`
    /// are the declared model's coefficients (a scale or a stiffness, first).
    pub(crate) fn params(
        &self,
        coefs: &[f64],
        s: &Signals,
        base: &[f64],
    ) -> Vec<(&'static str, f64)> {
        let c = |i: usize| coefs.get(i).copied().unwrap_or(f64::NAN);
        let b0 = base.first().copied().unwrap_or(f64::NAN);
        match self.effect {
            Effect::Hysteresis => {
                // Half the gap between loading and unloading branches of a full loop: Σ wᵢ·rᵢ.
                let h: f64 = s.widths.iter().zip(coefs).map(|(w, c)| w * c).sum();
                let active = coefs.iter().filter(|c| **c > 0.0).count() as f64;
                let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
                for (w, c) in s.widths.iter().zip(coefs) {
                    if *c > 0.0 {
                        lo = lo.min(*w);
                        hi = hi.max(*w);
                    }
                }
                vec![
                    ("loop_half_height_nm", h),
                    ("operators", active),
                    (
                        "narrowest_half_width_rad",
                        if lo.is_finite() { lo } else { 0.0 },
                    ),
                    ("widest_half_width_rad", hi),
                    ("initial_state", self.shape),
                ]
            }
            Effect::Backlash => vec![
                ("width_rad", 2.0 * self.shape),
                ("half_width_rad", self.shape),
            ],
            Effect::CoulombFriction => vec![
                ("friction_nm", c(0)),
                ("held_at_rest", f64::from(self.shape == FRICTION_HELD)),
                // 0: the force is all there at any speed the dead band lets through.
                ("builds_over_rad_per_s", self.shape.max(0.0)),
            ],
            Effect::ViscousFriction => {
                let mut p = vec![("damping_nms_per_rad", c(0))];
                // The lag of the deflection that validated as well (to first order the same
                // column, b ≈ k·|δ|): where the two could not be told apart, the friction is
                // named ([`super::select`]'s `rank`).
                if self.delay_alike.is_finite() {
                    p.push(("or_delay_s", self.delay_alike));
                }
                p
            }
            Effect::HardStop if self.symmetric => vec![
                ("onset_rad", self.shape),
                ("stop_rate_nm_per_rad", c(0)),
                ("onset_negative_rad", -self.shape),
                ("stop_rate_negative_nm_per_rad", c(0)),
            ],
            Effect::HardStop => {
                // Only the sides that stiffen: onset_rad > 0 wound, < 0 unwound.
                let mut p = Vec::new();
                let mut i = 0;
                for (at, side) in [(self.shape, 1.0), (self.lower, -1.0)] {
                    if !at.is_finite() {
                        continue;
                    }
                    if c(i) > 0.0 {
                        if side > 0.0 {
                            p.push(("onset_rad", at));
                            p.push(("stop_rate_nm_per_rad", c(i)));
                        } else {
                            p.push(("onset_negative_rad", -at));
                            p.push(("stop_rate_negative_nm_per_rad", c(i)));
                        }
                    }
                    i += 1;
                }
                p
            }
            Effect::GeometricStiffness => vec![("scale", c(0))],
            // A filter's time constant is its delay at low frequencies.
            Effect::SensorDelay => vec![
                ("delay_s", self.shape),
                ("first_order_filter", f64::from(self.filter)),
            ],
            Effect::Offset => match self.on {
                Place::Deflection => {
                    // The model is fed x + δ after t_j (or, while searched, the column
                    // 1[t ≥ t_j]·dτ̂/dx of the unscaled model: δ = c / scale). The encoder
                    // read x + s, s = −δ.
                    let shift = if self.size.is_finite() {
                        -self.size
                    } else {
                        -c(0) / b0
                    };
                    if self.shape.is_finite() {
                        vec![("jump_rad", shift), ("jump_at_s", self.shape)]
                    } else {
                        vec![("bias_rad", shift)]
                    }
                }
                Place::Torque => {
                    let mut p = Vec::new();
                    let mut i = 0;
                    if !s.base_has_intercept {
                        p.push(("bias_nm", c(0)));
                        i = 1;
                    }
                    if self.shape.is_finite() {
                        p.push(("jump_nm", c(i)));
                        p.push(("jump_at_s", self.shape));
                    }
                    // The encoder slip that fits as well (the restoring model: where the two
                    // could not be told apart, the torque is named).
                    if self.size.is_finite() {
                        let slip = if self.shape.is_finite() {
                            "or_encoder_jump_rad"
                        } else {
                            "or_encoder_bias_rad"
                        };
                        p.push((slip, -self.size));
                    }
                    p
                }
            },
            // (1 + c·t)·τ̂_elastic, or (1 + c·1[t ≥ t_j])·τ̂_elastic: the column's coefficient
            // over the elastic one.
            Effect::StiffnessDrift if self.shape.is_finite() => {
                vec![("stiffness_step", c(0) / b0), ("step_at_s", self.shape)]
            }
            Effect::StiffnessDrift => vec![
                ("stiffness_rate_per_s", c(0) / b0),
                ("stiffness_change_over_run", c(0) / b0 * s.duration),
            ],
            Effect::Gravity => vec![
                ("mgl_nm", c(0).hypot(c(1))),
                ("angle_offset_rad", c(1).atan2(c(0))),
            ],
            Effect::PeriodicRipple => vec![
                ("period_rad", self.shape),
                ("amplitude_nm", c(0).hypot(c(1))),
                ("phase_rad", c(1).atan2(c(0))),
            ],
        }
    }
}
