//! The TOML file as written: field names carry their units (mm, deg), unknown keys are
//! rejected. [`crate::validate`] turns this into SI types.

use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    pub rig: RawRig,
    pub geometry: Option<RawGeometry>,
    #[serde(default)]
    pub joint: Vec<RawJoint>,
    pub observer: Option<RawObserver>,
    pub zenoh: Option<RawZenoh>,
    pub clock: Option<RawClock>,
    #[serde(default)]
    pub machine: Vec<RawMachine>,
    pub security: Option<RawSecurity>,
}

/// `[security]`: the lab CA and the directory of the identities' certificates.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSecurity {
    pub ca: String,
    pub certs: String,
}

/// One machine of the lab's plan: the roles it runs and how it joins the others.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMachine {
    pub name: String,
    pub roles: Vec<String>,
    #[serde(default)]
    pub listen: Vec<String>,
    #[serde(default)]
    pub connect: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawClock {
    pub max_offset_ms: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRig {
    pub name: String,
    pub topology: String,
    pub rate_hz: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawGeometry {
    pub l1_mm: Option<f64>,
    pub l2_mm: Option<f64>,
    pub l3_mm: Option<f64>,
    pub l4_mm: Option<f64>,
    pub l5_mm: Option<f64>,
    pub lb_mm: Option<f64>,
    pub elbow1: Option<String>,
    pub elbow2: Option<String>,
    pub home_mm: Option<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawJoint {
    pub name: String,
    pub kind: String,
    /// Absent for a joint that only runs simulated (e.g. paper A's AWAS, which used custom boards).
    pub servo: Option<RawServo>,
    pub encoder: RawEncoder,
    pub lever: Option<RawLever>,
    pub restoring: Option<RawRestoring>,
    pub awas: Option<RawAwas>,
    pub limits: RawLimits,
    pub effects: Option<RawEffects>,
    pub torque_sensor: Option<RawTorqueSensor>,
}

/// A torque reference on the joint board: a load cell through an HX711 on the encoder bridge.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawTorqueSensor {
    pub kind: String,
    pub channel: Option<u8>,
    pub zero_counts: Option<i64>,
    pub nm_per_count: f64,
}

/// Effects `rig identify --apply` found and the estimator applies live.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEffects {
    pub torque_offset_nm: Option<f64>,
    pub encoder_offset_deg: Option<f64>,
    pub backlash_half_width_deg: Option<f64>,
    pub stop_onset_deg: Option<f64>,
    pub stop_rate_nm_per_rad: Option<f64>,
    pub stop_onset_negative_deg: Option<f64>,
    pub stop_rate_negative_nm_per_rad: Option<f64>,
    pub ripple_amplitude_nm: Option<f64>,
    pub ripple_period_deg: Option<f64>,
    pub ripple_phase_deg: Option<f64>,
    pub torque_lag_ms: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawServo {
    pub bus: String,
    pub baud: u32,
    pub main_id: u8,
    pub main_model: String,
    pub main_protocol: u8,
    pub stiffness_id: u8,
    pub stiffness_model: String,
    pub stiffness_protocol: u8,
    /// Main servo angle (from its centre) at joint angle 0.
    pub main_zero_deg: Option<f64>,
    /// Pivot servo angle (from its centre) at pivot displacement d = 0.
    pub pivot_zero_deg: Option<f64>,
    /// Rack travel per degree of the pivot servo (pinion radius × π/180; negative if the rack
    /// moves towards the main joint as the servo turns positive).
    pub pivot_mm_per_deg: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEncoder {
    pub kind: String,
    pub bits: u8,
    pub interface: String,
    /// The serial bridge's port (interface = "serial") or the spidev device ("spi").
    pub device: Option<String>,
    /// Baud rate of the serial bridge.
    pub baud: Option<u32>,
    /// This encoder's index on the bridge.
    pub channel: Option<u8>,
    /// The count at zero deflection.
    pub zero_counts: Option<u32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLever {
    pub d0_mm: f64,
    pub d_min_mm: f64,
    pub d_max_mm: f64,
    pub p_mm: f64,
    pub k_alpha_nm_per_rad: f64,
    pub spring_limit_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRestoring {
    pub dead_band_counts: Option<f64>,
    /// "linear" (paper B's straight envelope lines, the default) or "lever".
    pub envelope: Option<String>,
    pub point: Vec<RawRestoringPoint>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRestoringPoint {
    pub d_mm: f64,
    pub k_nm_per_rad: f64,
    pub h_nm: f64,
    pub a_s: f64,
    pub n: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawAwas {
    pub k_s_n_per_m: f64,
    pub r0_mm: f64,
    pub screw_lead_mm: f64,
    pub r_min_mm: f64,
    pub r_max_mm: f64,
    pub link_inertia_kg_m2: f64,
    pub link_damping_nms_per_rad: f64,
    pub b1_kg_m2: f64,
    pub d1_nms_per_rad: f64,
    pub b2_kg_m2: f64,
    pub d2_nms_per_rad: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLimits {
    pub motor_min_deg: f64,
    pub motor_max_deg: f64,
    /// Lever VSA: fastest pivot motion.
    pub pivot_rate_mm_per_s: Option<f64>,
    /// AWAS: fastest stiffness-motor motion.
    pub stiffness_motor_rate_deg_per_s: Option<f64>,
    pub k_min_nm_per_rad: Option<f64>,
    pub k_max_nm_per_rad: Option<f64>,
    pub watchdog_ms: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawObserver {
    pub alpha: f64,
    pub k0_nm_per_rad: Option<f64>,
    pub q_diag: Vec<f64>,
    pub r_diag: Vec<f64>,
    pub p0_diag: Vec<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawZenoh {
    pub mode: String,
    #[serde(default)]
    pub listen: Vec<String>,
    #[serde(default)]
    pub connect: Vec<String>,
}
