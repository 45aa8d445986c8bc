//! Raw TOML → validated SI config. Every check records an error at a field path; all
//! problems are returned together.

use std::collections::HashMap;
use std::path::Path;

use rig_model::awas::{Awas, AwasDynamics};
use rig_model::hysteresis::{Envelope, RestoringCurve, RestoringParams};
use rig_model::lever::LeverVsa;
use rig_model::planar::Elbow;

use crate::error::{Collector, ConfigError, ConfigErrors, FieldPath, line_of};
use crate::raw::*;
use crate::*;

const MM: f64 = 1e-3;

pub fn parse(path: &Path, src: &str) -> Result<RigConfig, ConfigErrors> {
    let raw: RawConfig =
        toml::from_str(src).map_err(|e| ConfigErrors(vec![deser_error(path, src, &e)]))?;
    let mut c = Collector::new(path, src);
    let cfg = build(&mut c, &raw);
    match cfg {
        Some(cfg) if c.errors.is_empty() => Ok(RigConfig {
            source: path.to_path_buf(),
            ..cfg
        }),
        _ => Err(ConfigErrors(c.errors)),
    }
}

fn deser_error(path: &Path, src: &str, e: &toml::de::Error) -> ConfigError {
    let span = e.span();
    let line = span.as_ref().map(|s| line_of(src, s.start));
    // For a key error the span covers the key: name it as the field.
    let field = span
        .and_then(|s| src.get(s))
        .filter(|t| !t.is_empty() && t.len() < 64 && !t.contains('\n'))
        .map(str::to_string)
        .unwrap_or_default();
    let mut message = e.message().trim().to_string();
    if message.starts_with("unknown field") {
        message.push_str(" (check the spelling and the unit suffix; see rig-config/examples/)");
    }
    ConfigError {
        file: path.to_path_buf(),
        line,
        field,
        message,
    }
}

/// Checks on numbers, recording errors.
trait Checks {
    fn finite(&mut self, p: &FieldPath, v: f64) -> bool;
    fn positive(&mut self, p: &FieldPath, v: f64) -> bool;
    fn non_negative(&mut self, p: &FieldPath, v: f64) -> bool;
    fn one_of<T: Copy>(&mut self, p: &FieldPath, v: &str, allowed: &[(&str, T)]) -> Option<T>;
}

impl Checks for Collector<'_> {
    fn finite(&mut self, p: &FieldPath, v: f64) -> bool {
        if v.is_finite() {
            return true;
        }
        self.push(p, format!("must be a finite number, got {v}"));
        false
    }

    fn positive(&mut self, p: &FieldPath, v: f64) -> bool {
        if !self.finite(p, v) {
            return false;
        }
        if v <= 0.0 {
            self.push(p, format!("must be > 0, got {v}"));
            return false;
        }
        true
    }

    fn non_negative(&mut self, p: &FieldPath, v: f64) -> bool {
        if !self.finite(p, v) {
            return false;
        }
        if v < 0.0 {
            self.push(p, format!("must be >= 0, got {v}"));
            return false;
        }
        true
    }

    fn one_of<T: Copy>(&mut self, p: &FieldPath, v: &str, allowed: &[(&str, T)]) -> Option<T> {
        if let Some((_, t)) = allowed.iter().find(|(name, _)| *name == v) {
            return Some(*t);
        }
        let names: Vec<String> = allowed.iter().map(|(n, _)| format!("\"{n}\"")).collect();
        self.push(
            p,
            format!("\"{v}\" is not allowed; use one of {}", names.join(", ")),
        );
        None
    }
}

fn build(c: &mut Collector<'_>, raw: &RawConfig) -> Option<RigConfig> {
    let root = FieldPath::default();
    let rig = root.key("rig");
    if let Err(e) = rig_protocol_name("rig", &raw.rig.name) {
        c.push(&rig.key("name"), e);
    }
    let topology = c.one_of(
        &rig.key("topology"),
        &raw.rig.topology,
        &[
            ("single", Topology::Single),
            ("serial", Topology::Serial),
            ("parallel", Topology::Parallel),
            ("bench", Topology::Bench),
        ],
    );
    let rate_hz = raw.rig.rate_hz.unwrap_or(1000.0);
    if c.positive(&rig.key("rate_hz"), rate_hz) && !(1.0..=20_000.0).contains(&rate_hz) {
        c.push(
            &rig.key("rate_hz"),
            format!("{rate_hz} Hz is outside [1, 20000] Hz"),
        );
    }

    let geometry = topology.and_then(|t| geometry(c, t, raw.geometry.as_ref()));

    // Joints.
    let jp = root.key("joint");
    if let Some(t) = topology {
        let (lo, hi) = t.joint_count();
        let n = raw.joint.len();
        if n < lo || n > hi {
            let want = if lo == hi {
                format!("{lo}")
            } else {
                format!("{lo} to {hi}")
            };
            c.push(
                &jp,
                format!("a {} rig has {want} [[joint]] tables, found {n}", t.name()),
            );
        }
    }
    let mut joints = Vec::new();
    let mut names: HashMap<&str, usize> = HashMap::new();
    let mut ids: HashMap<(&str, u8), (usize, &'static str)> = HashMap::new();
    for (i, j) in raw.joint.iter().enumerate() {
        let p = jp.index(i);
        if let Err(e) = rig_protocol_name("joint", &j.name) {
            c.push(&p.key("name"), e);
        }
        if let Some(first) = names.insert(&j.name, i) {
            c.push(
                &p.key("name"),
                format!(
                    "joint name \"{}\" is used twice (also joint[{first}])",
                    j.name
                ),
            );
        }
        let servo_ids = j.servo.as_ref().map(|s| {
            [
                (s.bus.as_str(), s.main_id, "main_id"),
                (s.bus.as_str(), s.stiffness_id, "stiffness_id"),
            ]
        });
        for (bus, id, field) in servo_ids.into_iter().flatten() {
            if let Some((other, other_field)) = ids.insert((bus, id), (i, field)) {
                c.push(
                    &p.key("servo").key(field),
                    format!(
                        "servo ID {id} on bus \"{}\" is used twice (also joint[{other}].servo.{other_field}); IDs must be unique per bus",
                        bus
                    ),
                );
            }
        }
        if let Some(jc) = joint(c, &p, i, j, topology) {
            joints.push(jc);
        }
    }

    let observer = observer(c, raw.observer.as_ref());
    let zenoh = zenoh(c, raw.zenoh.as_ref(), raw.security.is_some());
    let clock = clock(c, raw.clock.as_ref());
    let cfg = RigConfig {
        source: Default::default(),
        name: raw.rig.name.clone(),
        topology: topology?,
        rate_hz,
        geometry,
        joints,
        observer: observer?,
        zenoh: zenoh?,
        clock: clock?,
        machines: vec![],
        security: security(c, raw.security.as_ref()),
    };
    home_within_motor_limits(c, &jp, &cfg);
    let machines = machines(c, &raw.machine, &cfg);
    let cfg = RigConfig {
        machines: machines?,
        ..cfg
    };
    Some(cfg)
}

/// `[security]`: the CA and the certificates' directory, relative to the config file.
/// Whether the files are there and match is `rig validate`'s check (it reads them).
fn security(c: &mut Collector<'_>, raw: Option<&RawSecurity>) -> Option<SecurityConfig> {
    let s = raw?;
    let dir = c.file.parent().unwrap_or(Path::new("."));
    let p = FieldPath::default().key("security");
    for (field, v) in [("ca", &s.ca), ("certs", &s.certs)] {
        if v.trim().is_empty() {
            c.push(
                &p.key(field),
                "is empty: give a path relative to this file, e.g. ca = \"certs/ca.pem\", certs = \"certs\" (`rig certs` makes them)",
            );
        }
    }
    Some(SecurityConfig {
        ca: dir.join(&s.ca),
        certs: dir.join(&s.certs),
    })
}

/// Whether endpoint `e` fits the rig's security: with `[security]` every endpoint is TLS
/// (mutual TLS is what authenticates a peer); without it none is (there would be no
/// certificate to present).
pub fn endpoint_security(e: &str, secure: bool) -> Result<(), String> {
    let tls = e.starts_with("tls/");
    match (secure, tls) {
        (true, false) => Err(format!(
            "\"{e}\": with [security] every link is mutual TLS; write tls/<host>:<port> (docs/SECURITY.md)"
        )),
        (false, true) => Err(format!(
            "\"{e}\": a tls endpoint needs the lab's certificates: add a [security] section (ca, certs) and make them with `rig certs` (docs/SECURITY.md), or use tcp/<host>:<port>"
        )),
        _ => Ok(()),
    }
}

/// A robot's home pose puts each actuated joint's motor within its own limits (the
/// simulated world holds the motors there; a real rig starts there).
fn home_within_motor_limits(c: &mut Collector<'_>, jp: &FieldPath, cfg: &RigConfig) {
    let (Some(robot), Some(g)) = (cfg.robot(), cfg.geometry) else {
        return;
    };
    let Ok(at) = robot.at_position(g.home.0, g.home.1) else {
        return;
    };
    for (i, j) in cfg.joints.iter().enumerate().take(robot.actuated()) {
        let Some(&theta) = at.theta.get(i) else {
            continue;
        };
        let l = j.limits;
        if theta < l.motor_min_rad || theta > l.motor_max_rad {
            let field = if theta < l.motor_min_rad {
                "motor_min_deg"
            } else {
                "motor_max_deg"
            };
            c.push(
                &jp.index(i).key("limits").key(field),
                format!(
                    "the home pose ({:.1}, {:.1}) mm puts this joint's motor at {:.1} deg, outside [{:.1}, {:.1}] deg",
                    g.home.0 * 1e3,
                    g.home.1 * 1e3,
                    theta.to_degrees(),
                    l.motor_min_rad.to_degrees(),
                    l.motor_max_rad.to_degrees()
                ),
            );
        }
    }
}

/// Names used in key expressions (rig, joint): 1–64 of `[A-Za-z0-9_-]`.
fn rig_protocol_name(what: &'static str, name: &str) -> Result<(), String> {
    rig_protocol::keys::check_name(what, name).map_err(|e| e.to_string())
}

fn geometry(c: &mut Collector<'_>, t: Topology, raw: Option<&RawGeometry>) -> Option<Geometry> {
    let p = FieldPath::default().key("geometry");
    let Some(g) = raw else {
        if t.is_robot() {
            c.push(
                &p,
                format!(
                    "a {} rig needs a [geometry] table with its link lengths",
                    t.name()
                ),
            );
        }
        return None;
    };
    if !t.is_robot() {
        c.push(
            &p,
            format!("a {} rig has no [geometry]; remove the table", t.name()),
        );
        return None;
    }
    let mut ok = true;
    let mut need =
        |c: &mut Collector<'_>, field: &'static str, v: Option<f64>, allow_zero: bool| -> f64 {
            match v {
                None => {
                    c.push(&p.key(field), format!("is required for a {} rig", t.name()));
                    ok = false;
                    0.0
                }
                Some(v) => {
                    let good = if allow_zero {
                        c.non_negative(&p.key(field), v)
                    } else {
                        c.positive(&p.key(field), v)
                    };
                    ok &= good;
                    v * MM
                }
            }
        };
    let l1 = need(c, "l1_mm", g.l1_mm, false);
    let l2 = need(c, "l2_mm", g.l2_mm, false);
    let (l3, l4, l5, lb) = if t == Topology::Parallel {
        (
            need(c, "l3_mm", g.l3_mm, false),
            need(c, "l4_mm", g.l4_mm, false),
            need(c, "l5_mm", g.l5_mm, true),
            need(c, "lb_mm", g.lb_mm, true),
        )
    } else {
        for (field, v) in [
            ("l3_mm", g.l3_mm),
            ("l4_mm", g.l4_mm),
            ("l5_mm", g.l5_mm),
            ("lb_mm", g.lb_mm),
            ("elbow2", g.elbow2.as_ref().map(|_| 0.0)),
        ] {
            if v.is_some() {
                c.push(
                    &p.key(field),
                    "belongs to the parallel robot only; remove it for a serial rig",
                );
                ok = false;
            }
        }
        (0.0, 0.0, 0.0, 0.0)
    };
    let elbows = [("positive", Elbow::Positive), ("negative", Elbow::Negative)];
    let elbow1 = c.one_of(
        &p.key("elbow1"),
        g.elbow1.as_deref().unwrap_or("negative"),
        &elbows,
    );
    let elbow2 = c.one_of(
        &p.key("elbow2"),
        g.elbow2.as_deref().unwrap_or("positive"),
        &elbows,
    );
    let home = match g.home_mm.as_deref() {
        Some([x, y]) if c.finite(&p.key("home_mm"), *x) && c.finite(&p.key("home_mm"), *y) => {
            (*x * MM, *y * MM)
        }
        Some([_, _]) => return None,
        Some(_) => {
            c.push(&p.key("home_mm"), "must be [x, y] in mm");
            return None;
        }
        None => {
            c.push(
                &p.key("home_mm"),
                "is required: the default end-effector position [x, y] in mm",
            );
            return None;
        }
    };
    if !ok {
        return None;
    }
    let geo = Geometry {
        l1,
        l2,
        l3,
        l4,
        l5,
        lb,
        elbow1: elbow1?,
        elbow2: elbow2?,
        home,
    };
    // The home position must be a usable pose of the robot.
    let cfg = RigConfig {
        source: Default::default(),
        name: String::new(),
        topology: t,
        rate_hz: 1.0,
        geometry: Some(geo),
        joints: vec![],
        observer: ObserverConfig {
            alpha: 1.0,
            k0: 0.0,
            q_diag: [0.0; 4],
            r_diag: [1.0; 2],
            p0_diag: [0.0; 4],
        },
        zenoh: ZenohConfig {
            mode: ZenohMode::Peer,
            listen: vec![],
            connect: vec![],
        },
        clock: ClockConfig::default(),
        machines: vec![],
        security: None,
    };
    match cfg.robot().map(|r| r.at_position(home.0, home.1)) {
        Some(Ok(_)) => Some(geo),
        Some(Err(e)) => {
            c.push(&p.key("home_mm"), format!("is not a usable pose: {e}"));
            None
        }
        None => {
            c.push(&p, "link lengths do not form a robot");
            None
        }
    }
}

fn joint(
    c: &mut Collector<'_>,
    p: &FieldPath,
    index: usize,
    j: &RawJoint,
    topology: Option<Topology>,
) -> Option<JointConfig> {
    let servo = match &j.servo {
        Some(s) => servo(c, &p.key("servo"), s).map(Some),
        None => Some(None),
    };
    let encoder = encoder(c, &p.key("encoder"), &j.encoder);
    let kind_p = p.key("kind");
    let kind = c.one_of(&kind_p, &j.kind, &[("lever", "lever"), ("awas", "awas")])?;
    if kind == "awas" && matches!(topology, Some(Topology::Serial | Topology::Parallel)) {
        c.push(&kind_p, "the serial and parallel robots are built from lever VSAs (paper B); use kind = \"lever\"");
    }
    let resolution = encoder
        .as_ref()
        .map_or(rig_model::hysteresis::AS5048A_COUNT_RAD, |e| {
            e.resolution_rad
        });
    let (kind, range) = match kind {
        "lever" => {
            for (field, present) in [("awas", j.awas.is_some())] {
                if present {
                    c.push(
                        &p.key(field),
                        "a lever joint has no [joint.awas] table; remove it",
                    );
                }
            }
            lever(c, p, j, resolution)?
        }
        _ => {
            for (field, present) in [
                ("lever", j.lever.is_some()),
                ("restoring", j.restoring.is_some()),
            ] {
                if present {
                    c.push(&p.key(field), "an AWAS joint has no such table; remove it");
                }
            }
            awas(c, p, j)?
        }
    };
    let limits = limits(c, &p.key("limits"), &j.limits, &kind, range)?;
    let lever = matches!(kind, JointKind::Lever { .. });
    let effects = effects(c, &p.key("effects"), j.effects.as_ref(), lever)?;
    let torque_sensor = match &j.torque_sensor {
        Some(t) => Some(torque_sensor(c, &p.key("torque_sensor"), t)?),
        None => None,
    };
    Some(JointConfig {
        name: j.name.clone(),
        index,
        servo: servo?,
        encoder: encoder?,
        kind,
        limits,
        effects,
        torque_sensor,
    })
}

/// `[joint.torque_sensor]`: an HX711 channel of the bridge, its zero within the 24-bit range
/// and a finite, non-zero scale.
fn torque_sensor(
    c: &mut Collector<'_>,
    p: &FieldPath,
    t: &RawTorqueSensor,
) -> Option<TorqueSensorConfig> {
    let kind = c.one_of(&p.key("kind"), &t.kind, &[("hx711", ())]);
    let mut ok = kind.is_some();
    let channel = t.channel.unwrap_or(0);
    if channel > 3 {
        c.push(
            &p.key("channel"),
            format!("{channel}: the bridge reads load cells 0..3"),
        );
        ok = false;
    }
    let (lo, hi) = (-(1i64 << 23), (1i64 << 23) - 1);
    let zero = t.zero_counts.unwrap_or(0);
    if !(lo..=hi).contains(&zero) {
        c.push(
            &p.key("zero_counts"),
            format!("{zero} is not a 24-bit conversion ({lo}..={hi})"),
        );
        ok = false;
    }
    if !(t.nm_per_count.is_finite() && t.nm_per_count != 0.0 && t.nm_per_count.abs() < 1.0) {
        c.push(
            &p.key("nm_per_count"),
            format!(
                "{} is not a load cell's scale: give N·m per count, non-zero and below 1 (hang a known weight on a known arm and divide its torque by the change in counts)",
                t.nm_per_count
            ),
        );
        ok = false;
    }
    ok.then_some(TorqueSensorConfig {
        channel,
        zero_counts: zero as i32,
        nm_per_count: t.nm_per_count,
    })
}

/// `[joint.effects]`: sensor zeros within what a zero can be off by; the live effects of a
/// lever joint's model (rig_model::live) with their signs, each with what it needs beside it.
fn effects(
    c: &mut Collector<'_>,
    p: &FieldPath,
    e: Option<&RawEffects>,
    lever: bool,
) -> Option<JointEffects> {
    let Some(e) = e else {
        return Some(JointEffects::default());
    };
    let mut ok = true;
    // `v` (0 when absent) must lie in [lo, hi]; `what` says what the field is.
    let mut within = |c: &mut Collector<'_>,
                      field: &'static str,
                      v: Option<f64>,
                      (lo, hi): (f64, f64),
                      what: &str| {
        let x = v.unwrap_or(0.0);
        if !(x.is_finite() && (lo..=hi).contains(&x)) {
            c.push(
                &p.key(field),
                format!("{x} is not {what}: give a number in [{lo}, {hi}]"),
            );
            ok = false;
        }
        x
    };
    // Each field, its range and what it is (in the order of the names bound below).
    type Bounded = (&'static str, Option<f64>, (f64, f64), &'static str);
    let fields: [Bounded; 11] = [
        (
            "torque_offset_nm",
            e.torque_offset_nm,
            (-1e3, 1e3),
            "a sensor zero [N·m]",
        ),
        (
            "encoder_offset_deg",
            e.encoder_offset_deg,
            (-180.0, 180.0),
            "a sensor zero [deg]",
        ),
        (
            "backlash_half_width_deg",
            e.backlash_half_width_deg,
            (0.0, 10.0),
            "a gap's half-width [deg]",
        ),
        (
            "stop_onset_deg",
            e.stop_onset_deg,
            (0.0, 90.0),
            "where a stop on the wound side begins [deg]",
        ),
        (
            "stop_rate_nm_per_rad",
            e.stop_rate_nm_per_rad,
            (0.0, 1e6),
            "a stop's stiffness [N·m/rad]",
        ),
        (
            "stop_onset_negative_deg",
            e.stop_onset_negative_deg,
            (-90.0, 0.0),
            "where a stop on the unwound side begins [deg]",
        ),
        (
            "stop_rate_negative_nm_per_rad",
            e.stop_rate_negative_nm_per_rad,
            (0.0, 1e6),
            "a stop's stiffness [N·m/rad]",
        ),
        (
            "ripple_amplitude_nm",
            e.ripple_amplitude_nm,
            (0.0, 1e3),
            "a ripple's amplitude [N·m]",
        ),
        (
            "ripple_period_deg",
            e.ripple_period_deg,
            (0.0, 360.0),
            "a ripple's period [deg]",
        ),
        (
            "ripple_phase_deg",
            e.ripple_phase_deg,
            (-360.0, 360.0),
            "a phase [deg]",
        ),
        (
            "torque_lag_ms",
            e.torque_lag_ms,
            (-1000.0, 1000.0),
            "a lag between the sensors [ms]",
        ),
    ];
    let [
        torque,
        encoder,
        gap,
        on,
        k_on,
        under,
        k_under,
        amp,
        period,
        phase,
        lag,
    ] = fields.map(|(field, v, range, what)| within(c, field, v, range, what));
    // Fields that mean nothing apart: a stop's onset and rate, a ripple's amplitude and
    // period, each needing the other; a phase needs a period (a period needs no phase).
    for ((a, va), (b, vb), both_ways) in [
        (
            ("stop_onset_deg", e.stop_onset_deg),
            ("stop_rate_nm_per_rad", e.stop_rate_nm_per_rad),
            true,
        ),
        (
            ("stop_onset_negative_deg", e.stop_onset_negative_deg),
            (
                "stop_rate_negative_nm_per_rad",
                e.stop_rate_negative_nm_per_rad,
            ),
            true,
        ),
        (
            ("ripple_amplitude_nm", e.ripple_amplitude_nm),
            ("ripple_period_deg", e.ripple_period_deg),
            true,
        ),
        (
            ("ripple_phase_deg", e.ripple_phase_deg),
            ("ripple_period_deg", e.ripple_period_deg),
            false,
        ),
    ] {
        let lone = [(a, va, b, vb), (b, vb, a, va)];
        for (field, v, partner, w) in &lone[..if both_ways { 2 } else { 1 }] {
            if v.is_some() && w.is_none() {
                c.push(&p.key(field), format!("needs `{partner}` beside it"));
                ok = false;
            }
        }
    }
    if e.ripple_period_deg.is_some() && period <= 0.0 {
        c.push(
            &p.key("ripple_period_deg"),
            "a ripple's period must be > 0 deg",
        );
        ok = false;
    }
    let live = rig_model::live::LiveEffects {
        backlash_half_width_rad: gap.to_radians(),
        stop: (e.stop_onset_deg.is_some() || e.stop_onset_negative_deg.is_some()).then(|| {
            rig_model::live::HardStop {
                onset_rad: on.to_radians(),
                rate_nm_per_rad: k_on,
                onset_negative_rad: under.to_radians(),
                rate_negative_nm_per_rad: k_under,
            }
        }),
        ripple: (period > 0.0).then(|| rig_model::live::Ripple {
            amplitude_nm: amp,
            period_rad: period.to_radians(),
            phase_rad: phase.to_radians(),
        }),
        torque_lag_s: lag * 1e-3,
    };
    if !lever && !live.is_empty() {
        let field = [
            (
                "backlash_half_width_deg",
                e.backlash_half_width_deg.is_some(),
            ),
            ("stop_onset_deg", e.stop_onset_deg.is_some()),
            (
                "stop_onset_negative_deg",
                e.stop_onset_negative_deg.is_some(),
            ),
            ("ripple_period_deg", e.ripple_period_deg.is_some()),
            ("torque_lag_ms", e.torque_lag_ms.is_some()),
        ]
        .into_iter()
        .find_map(|(f, given)| given.then_some(f))
        .unwrap_or("backlash_half_width_deg");
        c.push(
            &p.key(field),
            "only a lever joint's restoring model applies it live; an AWAS joint takes the sensor zeros alone",
        );
        ok = false;
    }
    ok.then_some(JointEffects {
        torque_offset_nm: torque,
        encoder_offset_rad: encoder.to_radians(),
        live,
    })
}

fn servo(c: &mut Collector<'_>, p: &FieldPath, s: &RawServo) -> Option<ServoConfig> {
    let mut ok = true;
    if s.bus.trim().is_empty() {
        c.push(
            &p.key("bus"),
            "must name the serial port, e.g. \"/dev/ttyUSB0\"",
        );
        ok = false;
    }
    const BAUDS: [u32; 9] = [
        9600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000, 10_500_000,
    ];
    if !BAUDS.contains(&s.baud) {
        c.push(
            &p.key("baud"),
            format!(
                "{} is not a Dynamixel baud rate; use one of {BAUDS:?}",
                s.baud
            ),
        );
        ok = false;
    }
    for (field, id) in [("main_id", s.main_id), ("stiffness_id", s.stiffness_id)] {
        if id > 252 {
            c.push(
                &p.key(field),
                format!("{id} is outside the Dynamixel ID range 0..=252"),
            );
            ok = false;
        }
    }
    if s.main_id == s.stiffness_id {
        c.push(
            &p.key("stiffness_id"),
            format!(
                "equals main_id ({}): each servo needs its own ID",
                s.main_id
            ),
        );
        ok = false;
    }
    for (field, v) in [
        ("main_protocol", s.main_protocol),
        ("stiffness_protocol", s.stiffness_protocol),
    ] {
        if v != 1 && v != 2 {
            c.push(
                &p.key(field),
                format!("{v} is not a Dynamixel protocol; use 1 or 2"),
            );
            ok = false;
        }
    }
    let mut angle = |field: &'static str, v: Option<f64>| -> f64 {
        match v {
            Some(v) if !v.is_finite() || v.abs() > 180.0 => {
                c.push(
                    &p.key(field),
                    format!("{v} is not a servo angle from the centre in [-180, 180] deg"),
                );
                ok = false;
                0.0
            }
            Some(v) => v.to_radians(),
            None => 0.0,
        }
    };
    let main_zero_rad = angle("main_zero_deg", s.main_zero_deg);
    let pivot_zero_rad = angle("pivot_zero_deg", s.pivot_zero_deg);
    let pivot_m_per_rad = match s.pivot_mm_per_deg {
        Some(v) if !v.is_finite() || v == 0.0 || v.abs() > 10.0 => {
            c.push(
                &p.key("pivot_mm_per_deg"),
                format!("{v} is not a rack travel per degree; expect e.g. 0.087 (a 5 mm pinion)"),
            );
            ok = false;
            None
        }
        Some(v) => Some(v * 1e-3 * 180.0 / std::f64::consts::PI),
        None => None,
    };
    ok.then(|| ServoConfig {
        main_zero_rad,
        pivot_zero_rad,
        pivot_m_per_rad,
        bus: s.bus.clone(),
        baud: s.baud,
        main_id: s.main_id,
        main_model: s.main_model.clone(),
        main_protocol: s.main_protocol,
        stiffness_id: s.stiffness_id,
        stiffness_model: s.stiffness_model.clone(),
        stiffness_protocol: s.stiffness_protocol,
    })
}

fn encoder(c: &mut Collector<'_>, p: &FieldPath, e: &RawEncoder) -> Option<EncoderConfig> {
    let interface = c.one_of(
        &p.key("interface"),
        &e.interface,
        &[
            ("spi", EncoderInterface::Spi),
            ("serial", EncoderInterface::Serial),
        ],
    );
    if !(8..=24).contains(&e.bits) {
        c.push(
            &p.key("bits"),
            format!("{} bits is outside [8, 24]", e.bits),
        );
        return None;
    }
    if e.kind.trim().is_empty() {
        c.push(
            &p.key("kind"),
            "must name the encoder model, e.g. \"as5048a\"",
        );
        return None;
    }
    let counts = 1u32 << e.bits;
    if let Some(z) = e.zero_counts
        && z >= counts
    {
        c.push(
            &p.key("zero_counts"),
            format!(
                "{z} is not a count of a {}-bit encoder (0..{counts})",
                e.bits
            ),
        );
        return None;
    }
    if let Some(b) = e.baud
        && b == 0
    {
        c.push(&p.key("baud"), "must be a baud rate, e.g. 115200");
        return None;
    }
    if e.device.as_deref().is_some_and(|d| d.trim().is_empty()) {
        c.push(
            &p.key("device"),
            "must name the bridge's port, e.g. \"/dev/ttyACM0\", or the spidev device",
        );
        return None;
    }
    Some(EncoderConfig {
        model: e.kind.clone(),
        bits: e.bits,
        interface: interface?,
        resolution_rad: 2.0 * std::f64::consts::PI / f64::from(counts),
        device: e.device.clone(),
        baud: e.baud.unwrap_or(1_000_000),
        channel: e.channel.unwrap_or(0),
        zero_counts: e.zero_counts.unwrap_or(0),
    })
}

fn lever(
    c: &mut Collector<'_>,
    p: &FieldPath,
    j: &RawJoint,
    resolution: f64,
) -> Option<(JointKind, (f64, f64))> {
    let lp = p.key("lever");
    let Some(l) = j.lever.as_ref() else {
        c.push(&lp, "a lever joint needs a [joint.lever] table (d0_mm, d_min_mm, d_max_mm, p_mm, k_alpha_nm_per_rad, spring_limit_deg)");
        return None;
    };
    let mut ok = c.positive(&lp.key("d0_mm"), l.d0_mm);
    ok &= c.non_negative(&lp.key("d_min_mm"), l.d_min_mm);
    ok &= c.positive(&lp.key("d_max_mm"), l.d_max_mm);
    ok &= c.positive(&lp.key("p_mm"), l.p_mm);
    ok &= c.positive(&lp.key("k_alpha_nm_per_rad"), l.k_alpha_nm_per_rad);
    if c.positive(&lp.key("spring_limit_deg"), l.spring_limit_deg) && l.spring_limit_deg >= 90.0 {
        c.push(
            &lp.key("spring_limit_deg"),
            format!(
                "{} deg is not a torsion-spring limit; must be < 90",
                l.spring_limit_deg
            ),
        );
        ok = false;
    }
    if !ok {
        return None;
    }
    if l.d_min_mm >= l.d_max_mm {
        c.push(
            &lp.key("d_max_mm"),
            format!(
                "d range [{}, {}] mm is empty: need d_min_mm < d_max_mm",
                l.d_min_mm, l.d_max_mm
            ),
        );
        return None;
    }
    if l.d0_mm + l.d_max_mm >= l.p_mm {
        c.push(
            &lp.key("d_max_mm"),
            format!(
                "d range outside the mechanism: d0 + d_max = {} mm reaches the lever axis at p = {} mm; the pivot must stay between the main joint and the lever axis (d_max_mm < {})",
                l.d0_mm + l.d_max_mm,
                l.p_mm,
                l.p_mm - l.d0_mm
            ),
        );
        return None;
    }
    let vsa = LeverVsa {
        p: l.p_mm * MM,
        d0: l.d0_mm * MM,
        d_min: l.d_min_mm * MM,
        d_max: l.d_max_mm * MM,
        k_alpha: l.k_alpha_nm_per_rad,
        alpha_max: l.spring_limit_deg.to_radians(),
    };
    if let Err(e) = vsa.validate() {
        c.push(&lp, e.to_string());
        return None;
    }
    let rp = p.key("restoring");
    let Some(r) = j.restoring.as_ref() else {
        c.push(&rp, "a lever joint needs a [joint.restoring] table with at least one [[joint.restoring.point]] (fit one with the model's fitting routine)");
        return None;
    };
    let counts = r.dead_band_counts.unwrap_or(1.0);
    if c.finite(&rp.key("dead_band_counts"), counts) && counts < 1.0 {
        c.push(&rp.key("dead_band_counts"), format!("{counts} is below one encoder count: the direction would flip on quantisation noise"));
    }
    if r.point.is_empty() {
        c.push(
            &rp.key("point"),
            "needs at least one [[joint.restoring.point]]",
        );
        return None;
    }
    let mut table = Vec::new();
    let mut prev = f64::NEG_INFINITY;
    for (i, pt) in r.point.iter().enumerate() {
        let pp = rp.key("point").index(i);
        let mut ok = c.non_negative(&pp.key("d_mm"), pt.d_mm);
        ok &= c.positive(&pp.key("k_nm_per_rad"), pt.k_nm_per_rad);
        ok &= c.non_negative(&pp.key("h_nm"), pt.h_nm);
        ok &= c.positive(&pp.key("a_s"), pt.a_s);
        ok &= c.positive(&pp.key("n"), pt.n);
        if !ok {
            continue;
        }
        if pt.d_mm <= prev {
            c.push(
                &pp.key("d_mm"),
                format!(
                    "points must be sorted by strictly increasing d_mm ({} after {prev})",
                    pt.d_mm
                ),
            );
            continue;
        }
        if pt.d_mm < l.d_min_mm || pt.d_mm > l.d_max_mm {
            c.push(
                &pp.key("d_mm"),
                format!(
                    "{} mm is outside the pivot travel [{}, {}] mm",
                    pt.d_mm, l.d_min_mm, l.d_max_mm
                ),
            );
            continue;
        }
        prev = pt.d_mm;
        table.push((
            pt.d_mm * MM,
            RestoringParams {
                k: pt.k_nm_per_rad,
                h: pt.h_nm,
                a_s: pt.a_s,
                n: pt.n,
            },
        ));
    }
    if table.len() != r.point.len() {
        return None;
    }
    let envelope = match r.envelope.as_deref() {
        None | Some("linear") => Envelope::Linear,
        Some("lever") => Envelope::Lever(vsa),
        Some(other) => {
            c.push(
                &rp.key("envelope"),
                format!(
                    "\"{other}\" is not an envelope shape: \"lever\" (the lines follow the lever's own curve; what `rig calibrate` fits) or \"linear\" (paper B's straight lines)"
                ),
            );
            return None;
        }
    };
    let restoring = match RestoringCurve::new(&table) {
        Ok(curve) => curve.with_envelope(envelope),
        Err(e) => {
            c.push(&rp, e.to_string());
            return None;
        }
    };
    // The allocator maps a stiffness to a pivot through the calibrated k(d), so the default
    // bounds are the calibrated table's over the travel (not the lever law's).
    let range = restoring.stiffness_range(vsa.d_min, vsa.d_max);
    Some((
        JointKind::Lever {
            vsa,
            restoring: Box::new(restoring),
            dead_band_rad: counts.max(1.0) * resolution,
        },
        range,
    ))
}

fn awas(c: &mut Collector<'_>, p: &FieldPath, j: &RawJoint) -> Option<(JointKind, (f64, f64))> {
    let ap = p.key("awas");
    let Some(a) = j.awas.as_ref() else {
        c.push(&ap, "an AWAS joint needs a [joint.awas] table");
        return None;
    };
    let fields = [
        ("k_s_n_per_m", a.k_s_n_per_m),
        ("r0_mm", a.r0_mm),
        ("screw_lead_mm", a.screw_lead_mm),
        ("r_min_mm", a.r_min_mm),
        ("r_max_mm", a.r_max_mm),
        ("link_inertia_kg_m2", a.link_inertia_kg_m2),
        ("b1_kg_m2", a.b1_kg_m2),
        ("b2_kg_m2", a.b2_kg_m2),
    ];
    let mut ok = true;
    for (f, v) in fields {
        ok &= c.positive(&ap.key(f), v);
    }
    for (f, v) in [
        ("link_damping_nms_per_rad", a.link_damping_nms_per_rad),
        ("d1_nms_per_rad", a.d1_nms_per_rad),
        ("d2_nms_per_rad", a.d2_nms_per_rad),
    ] {
        ok &= c.non_negative(&ap.key(f), v);
    }
    if !ok {
        return None;
    }
    let awas = Awas {
        k_s: a.k_s_n_per_m,
        r0: a.r0_mm * MM,
        n: a.screw_lead_mm * MM / (2.0 * std::f64::consts::PI),
        r_min: a.r_min_mm * MM,
        r_max: a.r_max_mm * MM,
    };
    if let Err(e) = awas.validate() {
        c.push(&ap.key("r_max_mm"), e.to_string());
        return None;
    }
    let dynamics = AwasDynamics {
        link_inertia: a.link_inertia_kg_m2,
        link_damping: a.link_damping_nms_per_rad,
        b1: a.b1_kg_m2,
        d1: a.d1_nms_per_rad,
        b2: a.b2_kg_m2,
        d2: a.d2_nms_per_rad,
    };
    Some((JointKind::Awas { awas, dynamics }, awas.stiffness_range()))
}

fn limits(
    c: &mut Collector<'_>,
    p: &FieldPath,
    l: &RawLimits,
    kind: &JointKind,
    range: (f64, f64),
) -> Option<Limits> {
    let mut ok = c.finite(&p.key("motor_min_deg"), l.motor_min_deg)
        & c.finite(&p.key("motor_max_deg"), l.motor_max_deg);
    if ok && l.motor_min_deg >= l.motor_max_deg {
        c.push(
            &p.key("motor_max_deg"),
            format!(
                "motor range [{}, {}] deg is empty",
                l.motor_min_deg, l.motor_max_deg
            ),
        );
        ok = false;
    }
    if !c.positive(&p.key("watchdog_ms"), l.watchdog_ms) {
        ok = false;
    } else if l.watchdog_ms > 60_000.0 {
        c.push(
            &p.key("watchdog_ms"),
            format!(
                "{} ms is no watchdog: a joint must hold within a minute of its last command (paper B's rig: 500)",
                l.watchdog_ms
            ),
        );
        ok = false;
    }
    let (rate_field, rate, other_field, other, scale) = match kind {
        JointKind::Lever { .. } => (
            "pivot_rate_mm_per_s",
            l.pivot_rate_mm_per_s,
            "stiffness_motor_rate_deg_per_s",
            l.stiffness_motor_rate_deg_per_s,
            MM,
        ),
        JointKind::Awas { .. } => (
            "stiffness_motor_rate_deg_per_s",
            l.stiffness_motor_rate_deg_per_s,
            "pivot_rate_mm_per_s",
            l.pivot_rate_mm_per_s,
            std::f64::consts::PI / 180.0,
        ),
    };
    if other.is_some() {
        c.push(
            &p.key(other_field),
            format!("does not apply to this joint kind; use {rate_field}"),
        );
        ok = false;
    }
    let rate = match rate {
        Some(r) if c.positive(&p.key(rate_field), r) => r * scale,
        Some(_) => return None,
        None => {
            c.push(
                &p.key(rate_field),
                "is required: the fastest allowed stiffness-actuator motion",
            );
            return None;
        }
    };
    // The defaults are `range` (a lever joint's calibrated table over the travel); a bound set
    // by hand may reach to the mechanism's end by the lever law as well (the allocator keeps
    // within what the table reaches, so a table still to be calibrated does not block the
    // config).
    let k_min = l.k_min_nm_per_rad.unwrap_or(range.0);
    let k_max = l.k_max_nm_per_rad.unwrap_or(range.1);
    let (lo, hi) = match kind {
        JointKind::Lever { vsa, .. } => {
            let law = vsa.stiffness_range();
            (range.0.min(law.0), range.1.max(law.1))
        }
        JointKind::Awas { .. } => range,
    };
    let tol = 1e-9 * hi;
    if c.positive(&p.key("k_min_nm_per_rad"), k_min) && k_min < lo - tol {
        c.push(&p.key("k_min_nm_per_rad"), format!("{k_min} N·m/rad is below what the mechanism reaches ({lo:.4} N·m/rad at the end of its travel)"));
        ok = false;
    }
    if c.positive(&p.key("k_max_nm_per_rad"), k_max) && k_max > hi + tol {
        c.push(&p.key("k_max_nm_per_rad"), format!("{k_max} N·m/rad is above what the mechanism reaches ({hi:.4} N·m/rad at the end of its travel)"));
        ok = false;
    }
    if k_min >= k_max {
        c.push(
            &p.key("k_max_nm_per_rad"),
            format!("stiffness range [{k_min}, {k_max}] N·m/rad is empty"),
        );
        ok = false;
    }
    ok.then(|| Limits {
        motor_min_rad: l.motor_min_deg.to_radians(),
        motor_max_rad: l.motor_max_deg.to_radians(),
        stiffness_rate: rate,
        k_min,
        k_max,
        watchdog_s: l.watchdog_ms * 1e-3,
    })
}

fn observer(c: &mut Collector<'_>, raw: Option<&RawObserver>) -> Option<ObserverConfig> {
    let p = FieldPath::default().key("observer");
    let Some(o) = raw else {
        // Paper A's experimental tuning.
        return Some(ObserverConfig {
            alpha: 8.0,
            k0: 0.0,
            q_diag: [1e-3; 4],
            r_diag: [1e-3; 2],
            p0_diag: [100.0; 4],
        });
    };
    let mut ok = c.positive(&p.key("alpha"), o.alpha);
    let k0 = o.k0_nm_per_rad.unwrap_or(0.0);
    ok &= c.finite(&p.key("k0_nm_per_rad"), k0);
    let mut arr = |c: &mut Collector<'_>,
                   field: &'static str,
                   v: &[f64],
                   n: usize,
                   strict: bool|
     -> Vec<f64> {
        if v.len() != n {
            c.push(
                &p.key(field),
                format!("needs {n} values (a diagonal), got {}", v.len()),
            );
            ok = false;
        }
        for &x in v {
            let good = if strict {
                c.positive(&p.key(field), x)
            } else {
                c.non_negative(&p.key(field), x)
            };
            ok &= good;
        }
        v.to_vec()
    };
    let q = arr(c, "q_diag", &o.q_diag, 4, false);
    let r = arr(c, "r_diag", &o.r_diag, 2, true);
    let p0 = arr(c, "p0_diag", &o.p0_diag, 4, false);
    if !ok {
        return None;
    }
    Some(ObserverConfig {
        alpha: o.alpha,
        k0,
        q_diag: [q[0], q[1], q[2], q[3]],
        r_diag: [r[0], r[1]],
        p0_diag: [p0[0], p0[1], p0[2], p0[3]],
    })
}

/// `[clock]`: the bound on a sample's stamp against the receiving host's clock.
fn clock(c: &mut Collector<'_>, raw: Option<&RawClock>) -> Option<ClockConfig> {
    let Some(ms) = raw.and_then(|r| r.max_offset_ms) else {
        return Some(ClockConfig::default());
    };
    let p = FieldPath::default().key("clock").key("max_offset_ms");
    if !(ms.is_finite() && ms > 0.0 && ms <= 60_000.0) {
        c.push(
            &p,
            format!(
                "{ms} is not a bound: give milliseconds in (0, 60000], e.g. 100 (a sample's transit is ≤ 1 ms on a lab network)"
            ),
        );
        return None;
    }
    Some(ClockConfig {
        max_offset_s: ms * 1e-3,
    })
}

fn zenoh(c: &mut Collector<'_>, raw: Option<&RawZenoh>, secure: bool) -> Option<ZenohConfig> {
    let p = FieldPath::default().key("zenoh");
    let Some(z) = raw else {
        return Some(ZenohConfig {
            mode: ZenohMode::Peer,
            listen: vec![],
            connect: vec![],
        });
    };
    let mode = c.one_of(
        &p.key("mode"),
        &z.mode,
        &[
            ("peer", ZenohMode::Peer),
            ("client", ZenohMode::Client),
            ("router", ZenohMode::Router),
        ],
    );
    let mut ok = endpoints(c, &p, &z.listen, &z.connect, secure);
    if mode == Some(ZenohMode::Client) && z.connect.is_empty() {
        c.push(
            &p.key("connect"),
            "client mode needs at least one endpoint to connect to",
        );
        ok = false;
    }
    ok.then(|| ZenohConfig {
        mode: mode.unwrap_or(ZenohMode::Peer),
        listen: z.listen.clone(),
        connect: z.connect.clone(),
    })
}

/// Checks the `listen` and `connect` endpoints of the section at `p` (TLS exactly when
/// `secure`); whether all are good.
fn endpoints(
    c: &mut Collector<'_>,
    p: &FieldPath,
    listen: &[String],
    connect: &[String],
    secure: bool,
) -> bool {
    let mut ok = true;
    for (field, list) in [("listen", listen), ("connect", connect)] {
        for (i, e) in list.iter().enumerate() {
            if let Err(msg) = check_endpoint(e) {
                c.push(&p.key(field).index(i), msg);
                ok = false;
            } else if let Err(msg) = endpoint_security(e, secure) {
                // Well-formed, so the rest of the file is still checked (and its other
                // mismatches named too); the error alone refuses the file.
                c.push(&p.key(field).index(i), msg);
            }
        }
    }
    ok
}

/// The plan (`[[machine]]`): each machine's roles and endpoints. Where there is a plan,
/// every joint and the estimator run on exactly one machine, no role runs twice, and every
/// machine reaches every other through a chain of links (a link: one connects to an endpoint
/// the other listens on). Each machine's hub is a Zenoh router, and routers forward.
fn machines(c: &mut Collector<'_>, raw: &[RawMachine], cfg: &RigConfig) -> Option<Vec<Machine>> {
    let mp = FieldPath::default().key("machine");
    let before = c.errors.len();
    let mut out = Vec::new();
    let mut names: HashMap<&str, usize> = HashMap::new();
    let mut runs: HashMap<Role, usize> = HashMap::new();
    let joints: Vec<&str> = cfg.joints.iter().map(|j| j.name.as_str()).collect();
    for (i, m) in raw.iter().enumerate() {
        let p = mp.index(i);
        if let Err(e) = rig_protocol_name("machine", &m.name) {
            c.push(&p.key("name"), e);
        }
        if let Some(first) = names.insert(&m.name, i) {
            c.push(
                &p.key("name"),
                format!(
                    "machine name \"{}\" is used twice (also machine[{first}])",
                    m.name
                ),
            );
        }
        let mut roles = Vec::new();
        for (k, r) in m.roles.iter().enumerate() {
            let role = match r.as_str() {
                "estimator" => Role::Estimator,
                "allocator" => Role::Allocator,
                "recorder" => Role::Recorder,
                "viz" => Role::Viz,
                j if joints.contains(&j) => Role::Joint(j.to_string()),
                other => {
                    c.push(
                        &p.key("roles").index(k),
                        format!(
                            "\"{other}\" is no role: write \"estimator\", \"allocator\", \"recorder\", \"viz\" or a joint's name ({})",
                            joints.join(", ")
                        ),
                    );
                    continue;
                }
            };
            if let Some(first) = runs.insert(role.clone(), i) {
                c.push(
                    &p.key("roles").index(k),
                    format!(
                        "\"{r}\" also runs on machine \"{}\" (machine[{first}]); each role runs on one machine",
                        raw[first].name
                    ),
                );
            }
            roles.push(role);
        }
        if endpoints(c, &p, &m.listen, &m.connect, cfg.security.is_some()) {
            out.push(Machine {
                name: m.name.clone(),
                roles,
                listen: m.listen.clone(),
                connect: m.connect.clone(),
            });
        }
    }
    if raw.is_empty() {
        return Some(out);
    }
    let missing: Vec<&str> = joints
        .iter()
        .copied()
        .filter(|j| !runs.contains_key(&Role::Joint(j.to_string())))
        .chain((!runs.contains_key(&Role::Estimator)).then_some("estimator"))
        .collect();
    if !missing.is_empty() {
        c.push(
            &mp,
            format!(
                "{} run(s) on no machine; add each to one machine's roles",
                missing
                    .iter()
                    .map(|m| format!("\"{m}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
    }
    if c.errors.len() == before {
        for (a, b) in unreachable_pairs(&out) {
            c.push(
                &mp.index(a),
                format!(
                    "machine \"{}\" cannot reach machine \"{}\" (machine[{b}]): no chain of links joins them (a link: one connects to an endpoint the other listens on); add an endpoint one of its group listens on to a `connect` list of the other group",
                    out[a].name, out[b].name
                ),
            );
        }
    }
    (c.errors.len() == before).then_some(out)
}

/// Whether `connect` reaches a session listening on `listen`: the same protocol and port,
/// and the same host or a listener on every address (0.0.0.0, [::]).
pub fn endpoint_reaches(connect: &str, listen: &str) -> bool {
    let split = |e: &str| -> Option<(String, String, String)> {
        let (proto, addr) = e.split_once('/')?;
        let addr = addr.split('#').next()?;
        let (host, port) = addr.rsplit_once(':')?;
        Some((proto.to_string(), host.to_string(), port.to_string()))
    };
    match (split(connect), split(listen)) {
        (Some((pc, hc, portc)), Some((pl, hl, portl))) => {
            pc == pl && portc == portl && (hc == hl || hl == "0.0.0.0" || hl == "[::]")
        }
        _ => false,
    }
}

/// Whether machine `a` links to machine `b`: one connects to an endpoint the other listens on.
pub fn linked(a: &Machine, b: &Machine) -> bool {
    let one_way = |x: &Machine, y: &Machine| {
        x.connect
            .iter()
            .any(|c| y.listen.iter().any(|l| endpoint_reaches(c, l)))
    };
    one_way(a, b) || one_way(b, a)
}

/// Pairs of machines (indices, each pair once) that no chain of links joins: for each
/// machine outside the first machine's group, the pair (it, the first machine).
pub fn unreachable_pairs(ms: &[Machine]) -> Vec<(usize, usize)> {
    let mut reached = vec![false; ms.len()];
    let mut todo = vec![0];
    while let Some(i) = todo.pop() {
        if i >= ms.len() || reached[i] {
            continue;
        }
        reached[i] = true;
        todo.extend((0..ms.len()).filter(|&j| !reached[j] && linked(&ms[i], &ms[j])));
    }
    (1..ms.len())
        .filter(|&j| !reached[j])
        .map(|j| (j, 0))
        .collect()
}

/// The Zenoh transports the rig is built with (the workspace's `zenoh` features).
pub const TRANSPORTS: [&str; 3] = ["tcp", "udp", "tls"];

/// A Zenoh endpoint: `<protocol>/<address>`, e.g. `tcp/127.0.0.1:7447`, on a transport the
/// rig is built with ([`TRANSPORTS`]).
pub fn check_endpoint(e: &str) -> Result<(), String> {
    const PROTOS: [&str; 6] = ["tcp", "udp", "tls", "quic", "ws", "unixsock-stream"];
    match e.split_once('/') {
        Some((proto, _)) if PROTOS.contains(&proto) && !TRANSPORTS.contains(&proto) => {
            Err(format!(
                "\"{e}\": the rig's Zenoh is built with {TRANSPORTS:?} only, so a {proto} endpoint would fail when the role starts; use tcp/<host>:<port> (TLS and access control: docs/SECURITY.md)"
            ))
        }
        Some((proto, addr)) if PROTOS.contains(&proto) && !addr.is_empty() => {
            let has_port = addr
                .rsplit_once(':')
                .is_some_and(|(_, port)| port.parse::<u16>().is_ok());
            let needs_port = proto != "unixsock-stream";
            if needs_port && !has_port {
                return Err(format!(
                    "\"{e}\" needs a port: <protocol>/<host>:<port>, e.g. \"tcp/127.0.0.1:7447\""
                ));
            }
            Ok(())
        }
        _ => Err(format!(
            "\"{e}\" is not an endpoint; write <protocol>/<address> with protocol one of {PROTOS:?}, e.g. \"tcp/127.0.0.1:7447\""
        )),
    }
}
