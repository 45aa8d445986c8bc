//! The library of candidate effects (MODEL.md §6): each has a physical meaning, the model
//! (joint torque or link equation) it applies to, its shape parameter searched on a grid, and
//! the feature columns it adds to the linear-in-parameters prediction.

use std::fmt;

use super::Signals;
use super::signals::stop_operator;

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
    /// joint torque, link angle q for the link equation).
    pub fn meaning(self) -> &'static str {
        match self {
            Effect::Hysteresis => {
                "friction in the spring and lever: a rate-independent loop, g·s_r(x) with s_r the stop operator of half-width r (loading above unloading)"
            }
            Effect::CoulombFriction => {
                "dry friction: F_c·sgn(ẋ), the direction taken from increments with a dead band"
            }
            Effect::ViscousFriction => "viscous friction: b·ẋ",
            Effect::Backlash => {
                "free play between motor and spring: the spring sees the play operator of x, −k·s_r(x) (loading below unloading)"
            }
            Effect::HardStop => {
                "the spring meets its stop: k_s·max(|x| − x_s, 0)·sgn(x), stiffening beyond x_s"
            }
            Effect::GeometricStiffness => {
                "the lever's exact torque τ(φ, d) less its linearisation G(0)²k_α·φ (the k_α·α·dG/dφ term that k_φ = G²k_α drops)"
            }
            Effect::SensorDelay => {
                "the torque sensor lags the encoders by δ > 0: the model is fed x(t − δ) (a torque that leads looks like k·δ·ẋ, viscous friction)"
            }
            Effect::Offset => {
                "a sensor bias: constant, or jumping by j at t_j (an encoder or a spring mount slipping)"
            }
            Effect::StiffnessDrift => {
                "the spring rate drifts in time (temperature, creep): (dk/dt)·t·x"
            }
            Effect::Gravity => "gravity on the link: m·g·l·sin(q + q₀)",
            Effect::PeriodicRipple => {
                "ripple periodic in the angle (gear teeth, cogging, encoder eccentricity): A·sin(2π·θ/P + ψ)"
            }
        }
    }

    /// Parses a report name.
    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s)
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Sign a fitted coefficient must have for the effect to mean what it says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Sign {
    Positive,
    Negative,
    Any,
}

/// One effect with its shape parameter fixed (delay, width, onset, jump time, period).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shaped {
    pub effect: Effect,
    /// The shape parameter; its unit depends on the effect (s, rad); NaN when it has none.
    pub shape: f64,
}

impl Shaped {
    /// Feature columns over the signals (the delay adds none: it changes the signals).
    pub(crate) fn columns(&self, s: &Signals) -> Vec<Vec<f64>> {
        let x = &s.x;
        let r = self.shape;
        match self.effect {
            Effect::Hysteresis | Effect::Backlash => {
                vec![s.per_run(|a, b| stop_operator(&x[a..b], r))]
            }
            Effect::CoulombFriction => vec![s.dir.clone()],
            Effect::ViscousFriction => vec![s.xdot.clone()],
            Effect::HardStop => vec![
                x.iter()
                    .map(|v| (v.abs() - r).max(0.0) * v.signum())
                    .collect(),
            ],
            Effect::GeometricStiffness => match &s.lever {
                Some(vsa) => vec![
                    x.iter()
                        .zip(&s.d)
                        .map(|(&p, &d)| vsa.torque(p, d) - vsa.stiffness_at_rest(d) * p)
                        .collect(),
                ],
                None => vec![],
            },
            Effect::SensorDelay => vec![],
            Effect::Offset => {
                let mut cols = Vec::new();
                if !s.base_has_intercept {
                    cols.push(vec![1.0; x.len()]);
                }
                if r.is_finite() {
                    cols.push(s.t_rel.iter().map(|&t| f64::from(t >= r)).collect());
                }
                cols
            }
            Effect::StiffnessDrift => vec![x.iter().zip(&s.t_rel).map(|(x, t)| x * t).collect()],
            Effect::Gravity => match &s.q {
                Some(q) => vec![
                    q.iter().map(|q| q.sin()).collect(),
                    q.iter().map(|q| q.cos()).collect(),
                ],
                None => vec![],
            },
            Effect::PeriodicRipple => {
                let w = std::f64::consts::TAU / r;
                vec![
                    s.angle.iter().map(|a| (w * a).sin()).collect(),
                    s.angle.iter().map(|a| (w * a).cos()).collect(),
                ]
            }
        }
    }

    /// The sign the first coefficient must have.
    pub(crate) fn sign(&self) -> Sign {
        match self.effect {
            Effect::Hysteresis | Effect::CoulombFriction | Effect::ViscousFriction => {
                Sign::Positive
            }
            Effect::HardStop => Sign::Positive,
            Effect::Backlash => Sign::Negative,
            _ => Sign::Any,
        }
    }

    /// Named parameters from the shape and the fitted coefficients of its columns.
    pub(crate) fn params(&self, coefs: &[f64], has_intercept: bool) -> Vec<(&'static str, f64)> {
        let c = |i: usize| coefs.get(i).copied().unwrap_or(f64::NAN);
        match self.effect {
            Effect::Hysteresis => vec![
                ("half_width_rad", self.shape),
                ("gain_nm_per_rad", c(0)),
                ("loop_half_height_nm", c(0) * self.shape),
            ],
            Effect::Backlash => vec![
                ("width_rad", 2.0 * self.shape),
                ("spring_rate_nm_per_rad", -c(0)),
            ],
            Effect::CoulombFriction => vec![("friction_nm", c(0))],
            Effect::ViscousFriction => vec![("damping_nms_per_rad", c(0))],
            Effect::HardStop => vec![("onset_rad", self.shape), ("stop_rate_nm_per_rad", c(0))],
            Effect::GeometricStiffness => vec![("scale", c(0))],
            Effect::SensorDelay => vec![("delay_s", self.shape)],
            Effect::Offset => {
                let mut p = Vec::new();
                let mut i = 0;
                if !has_intercept {
                    p.push(("bias_nm", c(0)));
                    i = 1;
                }
                if self.shape.is_finite() {
                    p.push(("jump_nm", c(i)));
                    p.push(("jump_at_s", self.shape));
                }
                p
            }
            Effect::StiffnessDrift => vec![("stiffness_rate_nm_per_rad_s", c(0))],
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
