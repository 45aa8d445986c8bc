//! Effects a scenario can switch on without telling the estimator (its config does not know
//! them). Each is physical, with its parameters and units in the field names. All default to
//! off (zero).
//!
//! | effect | fields | what it does |
//! |---|---|---|
//! | Coulomb friction | `coulomb_friction_nm` | adds F_c·sgn(ẋ) to the joint torque (x: deflection for a lever joint, link angle for AWAS) |
//! | viscous friction | `viscous_friction_nms_per_rad` | adds b·ẋ to the joint torque |
//! | backlash | `backlash_rad` | a gap of this total width in series with the spring: the spring sees the deflection through a dead zone (unloaded inside the gap) |
//! | sensor delay | `sensor_delay_s` | the torque sensor lags the encoders (whole samples) |
//! | offsets | `encoder_offset_rad`, `torque_offset_nm` | constant biases of the deflection encoder and torque sensor |
//! | offset jump | `offset_jump_at_s`, `offset_jump_rad` | the encoder slips by this much at this time (a mount slipping) |
//! | stiffness drift | `stiffness_drift_per_s` | the spring rate scales by (1 + rate·t) (temperature, creep) |
//! | gravity | `gravity_mass_kg`, `gravity_com_m` | m·g·l·sin(q) on a link moving in a vertical plane, q from the vertical |
//! | hard stop | `stop_at_rad`, `stop_rate_nm_per_rad` | an end stop of the deflection: rate·(|x| − at)·sgn(x) beyond ±at (lever bench only; the lever's own spring limit is part of every lever plant) |
//! | periodic ripple | `ripple_nm`, `ripple_period_rad` | A·sin(2π·x/P) added to the measured torque, periodic in the measured angle x (gear teeth, cogging, encoder eccentricity; lever bench only) |

use serde::Deserialize;

/// Standard gravity [m/s²].
pub const G0: f64 = 9.80665;

/// Undeclared effects of one joint.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Effects {
    pub coulomb_friction_nm: f64,
    pub viscous_friction_nms_per_rad: f64,
    pub backlash_rad: f64,
    pub sensor_delay_s: f64,
    pub encoder_offset_rad: f64,
    pub torque_offset_nm: f64,
    pub offset_jump_at_s: Option<f64>,
    pub offset_jump_rad: f64,
    pub stiffness_drift_per_s: f64,
    pub gravity_mass_kg: f64,
    pub gravity_com_m: f64,
    pub ripple_nm: f64,
    pub ripple_period_rad: f64,
    pub stop_at_rad: Option<f64>,
    pub stop_rate_nm_per_rad: f64,
}

impl Effects {
    /// Checks signs and finiteness; returns the name of the first bad field.
    pub fn validate(&self) -> Result<(), String> {
        let nonneg = [
            ("coulomb_friction_nm", self.coulomb_friction_nm),
            (
                "viscous_friction_nms_per_rad",
                self.viscous_friction_nms_per_rad,
            ),
            ("backlash_rad", self.backlash_rad),
            ("sensor_delay_s", self.sensor_delay_s),
            ("gravity_mass_kg", self.gravity_mass_kg),
            ("gravity_com_m", self.gravity_com_m),
            ("ripple_nm", self.ripple_nm),
            ("ripple_period_rad", self.ripple_period_rad),
            ("stop_rate_nm_per_rad", self.stop_rate_nm_per_rad),
            ("stop_at_rad", self.stop_at_rad.unwrap_or(0.0)),
        ];
        for (name, v) in nonneg {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "effects.{name} must be a finite number >= 0, got {v}"
                ));
            }
        }
        let finite = [
            ("encoder_offset_rad", self.encoder_offset_rad),
            ("torque_offset_nm", self.torque_offset_nm),
            ("offset_jump_rad", self.offset_jump_rad),
            ("stiffness_drift_per_s", self.stiffness_drift_per_s),
            ("offset_jump_at_s", self.offset_jump_at_s.unwrap_or(0.0)),
        ];
        for (name, v) in finite {
            if !v.is_finite() {
                return Err(format!("effects.{name} must be finite, got {v}"));
            }
        }
        if self.ripple_nm > 0.0 && self.ripple_period_rad <= 0.0 {
            return Err(
                "effects.ripple_period_rad must be > 0 when effects.ripple_nm is set".into(),
            );
        }
        Ok(())
    }

    /// Reads undeclared effects for live simulated joints (`rig-joint --sim-effects`,
    /// `rig up --sim-effects`): a TOML file of the fields above, e.g. `torque_offset_nm = 0.05`.
    pub fn load(path: &std::path::Path) -> Result<Self, String> {
        let src = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: cannot read the file: {e}", path.display()))?;
        let e: Effects = toml::from_str(&src).map_err(|e| {
            let line = e.span().map_or(0, |sp| {
                src[..sp.start.min(src.len())].matches('\n').count() + 1
            });
            format!("{}:{line}: {}", path.display(), e.message().trim())
        })?;
        e.validate()
            .map_err(|m| format!("{}: {m}", path.display()))?;
        Ok(e)
    }

    /// Friction torque for a rate `x_dot`.
    pub fn friction(&self, x_dot: f64) -> f64 {
        let s = if x_dot > 0.0 {
            1.0
        } else if x_dot < 0.0 {
            -1.0
        } else {
            0.0
        };
        self.coulomb_friction_nm * s + self.viscous_friction_nms_per_rad * x_dot
    }

    /// Gravity torque at link angle `q` (from the vertical).
    pub fn gravity(&self, q: f64) -> f64 {
        self.gravity_mass_kg * G0 * self.gravity_com_m * q.sin()
    }

    /// Torque ripple at angle `x` [rad].
    pub fn ripple(&self, x: f64) -> f64 {
        if self.ripple_nm == 0.0 || self.ripple_period_rad <= 0.0 {
            return 0.0;
        }
        self.ripple_nm * (std::f64::consts::TAU * x / self.ripple_period_rad).sin()
    }

    /// End-stop torque at deflection `x` [rad].
    pub fn stop(&self, x: f64) -> f64 {
        match self.stop_at_rad {
            Some(at) => self.stop_rate_nm_per_rad * (x.abs() - at).max(0.0) * x.signum(),
            None => 0.0,
        }
    }

    /// Encoder bias at time `t`.
    pub fn encoder_bias(&self, t: f64) -> f64 {
        let jump = match self.offset_jump_at_s {
            Some(tj) if t >= tj => self.offset_jump_rad,
            _ => 0.0,
        };
        self.encoder_offset_rad + jump
    }

    /// Spring-rate scale at time `t`.
    pub fn stiffness_scale(&self, t: f64) -> f64 {
        1.0 + self.stiffness_drift_per_s * t
    }

    /// Torque-sensor delay in whole samples at sample time `ts`.
    pub fn delay_samples(&self, ts: f64) -> usize {
        (self.sensor_delay_s / ts).round() as usize
    }
}
