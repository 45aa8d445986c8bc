use std::path::{Path, PathBuf};

use super::*;

fn example(name: &str) -> (PathBuf, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name);
    let src = std::fs::read_to_string(&path).unwrap();
    (path, src)
}

/// Parses `src` after replacing the first `from` with `to`; returns the errors.
fn errors_after(name: &str, from: &str, to: &str) -> Vec<ConfigError> {
    let (path, src) = example(name);
    assert!(src.contains(from), "{from:?} not in {name}");
    let bad = src.replacen(from, to, 1);
    parse(&path, &bad).expect_err("should be refused").0
}

fn line_containing(name: &str, needle: &str, nth: usize) -> usize {
    let (_, src) = example(name);
    src.lines()
        .enumerate()
        .filter(|(_, l)| l.contains(needle))
        .nth(nth)
        .map(|(i, _)| i + 1)
        .unwrap()
}

#[test]
fn examples_validate_into_si() {
    let (p, src) = example("parallel.toml");
    let cfg = parse(&p, &src).unwrap();
    assert_eq!(cfg.topology, Topology::Parallel);
    assert_eq!(cfg.joints.len(), 4);
    let g = cfg.geometry.unwrap();
    assert!((g.l5 - 0.05).abs() < 1e-15 && (g.home.1 - 0.2).abs() < 1e-15);
    let JointKind::Lever {
        vsa,
        restoring,
        dead_band_rad,
    } = &cfg.joints[0].kind
    else {
        panic!()
    };
    assert!((vsa.p - 0.0315).abs() < 1e-15);
    assert!((vsa.alpha_max - 43f64.to_radians()).abs() < 1e-15);
    assert!((restoring.at(0.018).k - 62.2473).abs() < 1e-9);
    assert_eq!(
        restoring.envelope(),
        rig_model::hysteresis::Envelope::Lever(*vsa)
    );
    assert!((dead_band_rad - 2.0 * std::f64::consts::PI / 16384.0).abs() < 1e-15);
    assert_eq!(cfg.joints[2].limits.k_max, 60.0);
    assert!(cfg.robot().is_some());

    let (p, src) = example("serial.toml");
    let cfg = parse(&p, &src).unwrap();
    assert_eq!(cfg.joints.len(), 2);
    assert!(matches!(
        cfg.robot(),
        Some(rig_model::planar::PlanarRobot::Serial(_))
    ));

    let (p, src) = example("awas.toml");
    let cfg = parse(&p, &src).unwrap();
    let JointKind::Awas { awas, dynamics } = &cfg.joints[0].kind else {
        panic!()
    };
    let (lo, hi) = awas.stiffness_range();
    assert!(
        (lo - 30.0).abs() < 0.01 && (hi - 1500.0).abs() < 0.01,
        "{lo} {hi}"
    );
    assert_eq!(dynamics.link_inertia, 0.05);
    assert!(cfg.joints[0].servo.is_none());
    assert!((cfg.joints[0].limits.k_min - lo).abs() < 1e-12);
    assert!(cfg.robot().is_none());
}

#[test]
fn nan_is_refused_with_line_and_field() {
    let e = errors_after("parallel.toml", "l2_mm = 150.0", "l2_mm = nan");
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "geometry.l2_mm");
    assert_eq!(
        e[0].line,
        Some(line_containing("parallel.toml", "l2_mm", 0))
    );
    assert!(e[0].message.contains("finite"));
    assert!(
        e[0].to_string()
            .starts_with(&format!("{}:", example("parallel.toml").0.display()))
    );
}

#[test]
fn negative_length_is_refused() {
    let e = errors_after("serial.toml", "l1_mm = 150.0", "l1_mm = -150.0");
    assert_eq!(e[0].field, "geometry.l1_mm");
    assert!(e[0].message.contains("> 0"), "{}", e[0].message);
}

#[test]
fn an_unknown_envelope_shape_is_named_and_the_stiffness_bounds_default_to_the_calibrated_table() {
    let e = errors_after(
        "parallel.toml",
        "envelope = \"lever\"",
        "envelope = \"cubic\"",
    );
    assert_eq!(e[0].field, "joint[0].restoring.envelope");
    assert!(e[0].message.contains("\"lever\""), "{}", e[0].message);
    assert_eq!(
        e[0].line,
        Some(line_containing("parallel.toml", "envelope = ", 0))
    );
    // A bound set by hand may reach the mechanism's end by the lever law (65.3 N·m/rad), not
    // beyond; left out, it is the calibrated table's end (62.2 N·m/rad).
    let e = errors_after(
        "parallel.toml",
        "k_max_nm_per_rad = 60.0",
        "k_max_nm_per_rad = 66.0",
    );
    assert_eq!(e[0].field, "joint[2].limits.k_max_nm_per_rad");
    assert!(e[0].message.contains("65.3"), "{}", e[0].message);
    let (path, src) = example("parallel.toml");
    let cfg = parse(&path, &src.replacen("k_max_nm_per_rad = 60.0\n", "", 1)).unwrap();
    assert!((cfg.joints[2].limits.k_max - 62.2473).abs() < 1e-9);
}

#[test]
fn d_range_outside_the_mechanism_is_refused() {
    let e = errors_after("parallel.toml", "d_max_mm = 18.0", "d_max_mm = 25.0");
    assert_eq!(e[0].field, "joint[0].lever.d_max_mm");
    assert!(
        e[0].message.contains("outside the mechanism"),
        "{}",
        e[0].message
    );
    assert_eq!(
        e[0].line,
        Some(line_containing("parallel.toml", "d_max_mm", 0))
    );
}

#[test]
fn duplicate_servo_id_is_refused_naming_both() {
    let e = errors_after("parallel.toml", "main_id = 2 ", "main_id = 1 ");
    let dup = e
        .iter()
        .find(|e| e.message.contains("used twice"))
        .expect("a duplicate error");
    assert_eq!(dup.field, "joint[1].servo.main_id");
    assert!(dup.message.contains("joint[0].servo.main_id"));
    assert_eq!(
        dup.line,
        Some(line_containing("parallel.toml", "main_id", 1))
    );
}

#[test]
fn unknown_key_is_refused_with_its_line() {
    let e = errors_after("parallel.toml", "p_mm = 31.5", "p_mm = 31.5\nstiffnes = 3");
    assert_eq!(e[0].field, "stiffnes");
    assert!(e[0].message.contains("unknown field"), "{}", e[0].message);
    assert_eq!(
        e[0].line,
        Some(line_containing("parallel.toml", "p_mm", 0) + 1)
    );
}

#[test]
fn wrong_type_and_bad_enum_name_the_field() {
    let e = errors_after(
        "parallel.toml",
        "topology = \"parallel\"",
        "topology = \"delta\"",
    );
    assert_eq!(e[0].field, "rig.topology");
    assert!(e[0].message.contains("\"parallel\""));
    let e = errors_after("parallel.toml", "baud = 1000000", "baud = \"fast\"");
    assert!(e[0].line.is_some());
}

#[test]
fn several_problems_are_reported_together() {
    let (p, src) = example("parallel.toml");
    let bad = src.replacen("l1_mm = 150.0", "l1_mm = -1.0", 1).replacen(
        "spring_limit_deg = 43.0",
        "spring_limit_deg = 120.0",
        1,
    );
    let e = parse(&p, &bad).unwrap_err();
    assert!(e.0.len() >= 2, "{e}");
    assert!(e.to_string().lines().count() >= 2);
}

#[test]
fn topology_joint_count_and_bounds_are_checked() {
    let e = errors_after(
        "serial.toml",
        "topology = \"serial\"",
        "topology = \"parallel\"",
    );
    assert!(
        e.iter()
            .any(|e| e.field == "joint" && e.message.contains("4 [[joint]]")),
        "{e:?}"
    );
    let e = errors_after(
        "parallel.toml",
        "k_max_nm_per_rad = 50.0",
        "k_max_nm_per_rad = 80.0",
    );
    assert_eq!(e[0].field, "joint[0].limits.k_max_nm_per_rad");
    let e = errors_after(
        "parallel.toml",
        "home_mm = [75.0, 200.0]",
        "home_mm = [75.0, 900.0]",
    );
    assert_eq!(e[0].field, "geometry.home_mm");
    assert!(e[0].message.contains("out of reach"), "{}", e[0].message);
}

#[test]
fn a_bench_takes_independent_joints_and_no_geometry() {
    // The serial example's two joints as a bench: valid without the geometry table.
    let (path, src) = example("serial.toml");
    let start = src.find("[geometry]").unwrap();
    let end = start + src[start..].find("\n[zenoh]").unwrap();
    let bench = format!("{}{}", &src[..start], &src[end..]).replacen(
        "topology = \"serial\"",
        "topology = \"bench\"",
        1,
    );
    let cfg = parse(&path, &bench).unwrap();
    assert_eq!(cfg.topology, Topology::Bench);
    assert_eq!(cfg.joints.len(), 2);
    assert!(cfg.robot().is_none());
    // With the geometry it is refused, naming the table.
    let e = errors_after(
        "serial.toml",
        "topology = \"serial\"",
        "topology = \"bench\"",
    );
    assert!(
        e.iter()
            .any(|e| e.field == "geometry" && e.message.contains("bench rig has no [geometry]")),
        "{e:?}"
    );
    assert_eq!(Topology::Bench.joint_count(), (1, MAX_BENCH_JOINTS));
}

#[test]
fn zenoh_endpoints_are_checked() {
    let e = errors_after(
        "parallel.toml",
        "listen = []",
        "listen = [\"127.0.0.1:7447\"]",
    );
    assert_eq!(e[0].field, "zenoh.listen[0]");
    // A transport this build does not have is refused when the config is read, not when a
    // role starts.
    let e = errors_after(
        "parallel.toml",
        "listen = []",
        "listen = [\"quic/127.0.0.1:7447\"]",
    );
    assert_eq!(e[0].field, "zenoh.listen[0]");
    assert!(e[0].message.contains("built with"), "{}", e[0].message);
    // TLS needs the lab's certificates, and with them every link is TLS.
    let e = errors_after(
        "parallel.toml",
        "listen = []",
        "listen = [\"tls/127.0.0.1:7447\"]",
    );
    assert_eq!(e[0].field, "zenoh.listen[0]");
    assert!(e[0].message.contains("[security]"), "{}", e[0].message);
    let e = errors_after(
        "parallel.toml",
        "connect = []",
        "connect = [\"tcp/127.0.0.1:7447\"]\n\n[security]\nca = \"certs/ca.pem\"\ncerts = \"certs\"",
    );
    // Every plain endpoint is named, the plan's too.
    let fields: Vec<&str> = e.iter().map(|e| e.field.as_str()).collect();
    assert_eq!(
        fields,
        [
            "zenoh.connect[0]",
            "machine[0].listen[0]",
            "machine[1].connect[0]",
            "machine[2].connect[0]"
        ]
    );
    assert!(e.iter().all(|e| e.message.contains("mutual TLS")), "{e:?}");
}

#[test]
fn the_security_paths_are_read_relative_to_the_config_file() {
    let (path, src) = example("parallel.toml");
    let src = src.replace("\"tcp/", "\"tls/").replace(
        "[clock]",
        "[security]\nca = \"certs/ca.pem\"\ncerts = \"certs\"\n\n[clock]",
    );
    let cfg = parse(&path, &src).unwrap();
    let s = cfg.security.unwrap();
    let dir = path.parent().unwrap();
    assert_eq!(s.ca, dir.join("certs/ca.pem"));
    assert_eq!(
        s.cert(&Identity::Estimator),
        dir.join("certs/estimator.pem")
    );
    assert_eq!(
        s.key(&Identity::Joint("j1".into())),
        dir.join("certs/joint-j1.key")
    );
}

#[test]
fn missing_file_is_a_clear_error() {
    let e = load(Path::new("/nonexistent/rig.toml")).unwrap_err();
    assert!(e.to_string().contains("cannot read the file"));
}

#[test]
fn hardware_fields_are_read_in_lab_units_and_checked() {
    let cfg = crate::examples::load("parallel").unwrap();
    let s = cfg.joints[0].servo.as_ref().unwrap();
    // 0.0873 mm per degree: a 5 mm pinion, 5.0020e-3 m per radian.
    let m_per_rad = s.pivot_m_per_rad.unwrap();
    assert!((m_per_rad - 0.0873e-3 * 180.0 / std::f64::consts::PI).abs() < 1e-12);
    assert!((s.pivot_zero_rad + 100f64.to_radians()).abs() < 1e-12);
    let e = &cfg.joints[3].encoder;
    assert_eq!((e.channel, e.zero_counts, e.baud), (3, 8192, 1_000_000));
    assert_eq!(e.device.as_deref(), Some("/dev/ttyACM0"));
    let e = errors_after(
        "parallel.toml",
        "pivot_mm_per_deg = 0.0873",
        "pivot_mm_per_deg = 0.0",
    );
    assert_eq!(e[0].field, "joint[0].servo.pivot_mm_per_deg");
    let e = errors_after(
        "parallel.toml",
        "main_zero_deg = 0.0",
        "main_zero_deg = 270.0",
    );
    assert_eq!(e[0].field, "joint[0].servo.main_zero_deg");
    let e = errors_after("parallel.toml", "zero_counts = 8192", "zero_counts = 16384");
    assert_eq!(e[0].field, "joint[0].encoder.zero_counts");
    assert!(e[0].message.contains("14-bit"), "{}", e[0].message);
}

#[test]
fn the_clock_bound_defaults_to_100_ms_and_a_bad_one_is_named_with_its_line() {
    let (p, src) = example("bench.toml");
    assert_eq!(parse(&p, &src).unwrap().clock.max_offset_s, 0.1);
    let set = |ms: &str| {
        src.replacen(
            "[rig]\n",
            &format!("[clock]\nmax_offset_ms = {ms}\n\n[rig]\n"),
            1,
        )
    };
    assert_eq!(parse(&p, &set("250")).unwrap().clock.max_offset_s, 0.25);
    let bad = set("-5");
    let e = parse(&p, &bad).expect_err("a negative bound is refused").0;
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "clock.max_offset_ms");
    let line = bad
        .lines()
        .position(|l| l.starts_with("max_offset_ms"))
        .unwrap()
        + 1;
    assert_eq!(e[0].line, Some(line));
    assert!(e[0].message.contains("(0, 60000]"), "{}", e[0].message);
}

#[test]
fn joint_effects_are_read_in_lab_units_and_a_bad_zero_is_named() {
    let (p, src) = example("bench.toml");
    assert_eq!(
        parse(&p, &src).unwrap().joints[0].effects,
        JointEffects::default()
    );
    let with = |t: &str, e: &str| {
        src.replacen(
            "[joint.limits]",
            &format!(
                "[joint.effects]\ntorque_offset_nm = {t}\nencoder_offset_deg = {e}\n\n[joint.limits]"
            ),
            1,
        )
    };
    let e = parse(&p, &with("0.02", "-0.5")).unwrap().joints[0].effects;
    assert_eq!(e.torque_offset_nm, 0.02);
    assert!((e.encoder_offset_rad + 0.5f64.to_radians()).abs() < 1e-15);
    let errs = parse(&p, &with("nan", "400")).expect_err("refused").0;
    let fields: Vec<&str> = errs.iter().map(|e| e.field.as_str()).collect();
    assert_eq!(
        fields,
        [
            "joint[0].effects.torque_offset_nm",
            "joint[0].effects.encoder_offset_deg"
        ]
    );
}

#[test]
fn live_effects_are_read_in_si_and_each_bad_or_lone_field_is_named() {
    let (p, src) = example("bench.toml");
    let with = |body: &str| {
        src.replacen(
            "[joint.limits]",
            &format!("[joint.effects]\n{body}\n[joint.limits]"),
            1,
        )
    };
    let e = parse(
        &p,
        &with(
            "backlash_half_width_deg = 0.3\nstop_onset_negative_deg = -2.0\nstop_rate_negative_nm_per_rad = 4.0\n\
             ripple_amplitude_nm = 0.01\nripple_period_deg = 3.0\nripple_phase_deg = 90.0\ntorque_lag_ms = -12.0\n",
        ),
    )
    .unwrap()
    .joints[0]
        .effects
        .live;
    assert!((e.backlash_half_width_rad - 0.3f64.to_radians()).abs() < 1e-15);
    let stop = e.stop.unwrap();
    assert!((stop.onset_negative_rad + 2f64.to_radians()).abs() < 1e-15);
    assert_eq!(
        (stop.rate_negative_nm_per_rad, stop.rate_nm_per_rad),
        (4.0, 0.0)
    );
    let r = e.ripple.unwrap();
    assert!((r.period_rad - 3f64.to_radians()).abs() < 1e-15);
    assert!((r.phase_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    assert!((e.torque_lag_s + 0.012).abs() < 1e-15);
    // A negative gap, a stop's onset on the wrong side, a rate without its onset, a ripple
    // without its period: every one named at once.
    let errs = parse(
        &p,
        &with("backlash_half_width_deg = -1.0\nstop_onset_deg = -3.0\nstop_rate_nm_per_rad = 2.0\nstop_rate_negative_nm_per_rad = 1.0\nripple_amplitude_nm = 0.1\ntorque_lag_ms = nan\n"),
    )
    .expect_err("refused")
    .0;
    let fields: Vec<&str> = errs.iter().map(|e| e.field.as_str()).collect();
    assert_eq!(
        fields,
        [
            "joint[0].effects.backlash_half_width_deg",
            "joint[0].effects.stop_onset_deg",
            "joint[0].effects.torque_lag_ms",
            "joint[0].effects.stop_rate_negative_nm_per_rad",
            "joint[0].effects.ripple_amplitude_nm",
        ],
        "{errs:?}"
    );
    assert!(
        errs[3].message.contains("stop_onset_negative_deg"),
        "{}",
        errs[3].message
    );
    // An AWAS joint has no restoring model to apply them to.
    let (p, src) = example("awas.toml");
    let src = src.replacen(
        "[joint.limits]",
        "[joint.effects]\ntorque_lag_ms = 5.0\n\n[joint.limits]",
        1,
    );
    let errs = parse(&p, &src).expect_err("refused").0;
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_eq!(errs[0].field, "joint[0].effects.torque_lag_ms");
    assert!(errs[0].message.contains("lever"), "{}", errs[0].message);
}

#[test]
fn a_load_cell_is_read_with_its_zero_and_scale_and_every_bad_field_is_named() {
    let (p, src) = example("bench.toml");
    let with = |body: &str| format!("{src}\n[joint.torque_sensor]\n{body}");
    let t = parse(
        &p,
        &with("kind = \"hx711\"\nchannel = 2\nzero_counts = -8000\nnm_per_count = 2e-5\n"),
    )
    .unwrap()
    .joints[0]
        .torque_sensor
        .unwrap();
    assert_eq!((t.channel, t.zero_counts, t.nm_per_count), (2, -8000, 2e-5));
    let errs = parse(
        &p,
        &with("kind = \"strain\"\nchannel = 4\nzero_counts = 9000000\nnm_per_count = 0.0\n"),
    )
    .expect_err("refused")
    .0;
    let fields: Vec<&str> = errs.iter().map(|e| e.field.as_str()).collect();
    assert_eq!(
        fields,
        [
            "joint[0].torque_sensor.kind",
            "joint[0].torque_sensor.channel",
            "joint[0].torque_sensor.zero_counts",
            "joint[0].torque_sensor.nm_per_count",
        ],
        "{errs:?}"
    );
    assert!(
        errs[3].message.contains("known weight"),
        "{}",
        errs[3].message
    );
}

#[test]
fn a_watchdog_of_ages_is_refused() {
    let e = errors_after("bench.toml", "watchdog_ms = 500.0", "watchdog_ms = 1e300");
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "joint[0].limits.watchdog_ms");
    assert!(e[0].message.contains("within a minute"), "{}", e[0].message);
}

#[test]
fn a_home_pose_outside_a_motors_limits_is_refused_naming_the_angle() {
    let e = errors_after(
        "parallel.toml",
        "motor_min_deg = 0.0 ",
        "motor_min_deg = 120.0 ",
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "joint[0].limits.motor_min_deg");
    assert!(e[0].message.contains("114.0 deg"), "{}", e[0].message);
}

#[test]
fn the_example_plan_puts_every_role_on_one_machine() {
    let (p, src) = example("parallel.toml");
    let cfg = parse(&p, &src).unwrap();
    let names: Vec<&str> = cfg.machines.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["host", "chain1", "chain2"]);
    let host = cfg.machine("host").unwrap();
    assert_eq!(
        host.roles,
        [Role::Estimator, Role::Allocator, Role::Recorder]
    );
    assert_eq!(
        cfg.machine("chain2").unwrap().roles,
        [Role::Joint("j3".into()), Role::Joint("j4".into())]
    );
    assert_eq!(host.listen, ["tcp/0.0.0.0:7447"]);
    assert_eq!(
        cfg.machine("chain1").unwrap().connect,
        ["tcp/192.0.2.10:7447"]
    );
}

#[test]
fn a_plan_where_a_joint_runs_nowhere_is_refused_naming_it() {
    let e = errors_after(
        "parallel.toml",
        r#"roles = ["j3", "j4"]"#,
        r#"roles = ["j3"]"#,
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "machine");
    assert!(e[0].message.contains("\"j4\""), "{}", e[0].message);
}

#[test]
fn a_role_on_two_machines_is_refused_at_the_second() {
    let e = errors_after(
        "parallel.toml",
        r#"roles = ["j3", "j4"]"#,
        r#"roles = ["j3", "j4", "allocator"]"#,
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "machine[2].roles[2]");
    assert_eq!(
        e[0].line,
        Some(line_containing(
            "parallel.toml",
            r#"roles = ["j3", "j4"]"#,
            0
        ))
    );
    assert!(e[0].message.contains("\"host\""), "{}", e[0].message);
}

#[test]
fn an_unknown_role_is_refused_with_the_roles_there_are() {
    let e = errors_after(
        "parallel.toml",
        r#"roles = ["j1", "j2"]"#,
        r#"roles = ["j1", "j2", "j9"]"#,
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "machine[1].roles[2]");
    assert!(e[0].message.contains("j1, j2, j3, j4"), "{}", e[0].message);
}

#[test]
fn a_machine_no_chain_of_links_joins_to_the_others_is_refused() {
    let (path, src) = example("parallel.toml");
    let at = src.rfind(r#"connect = ["tcp/192.0.2.10:7447"]"#).unwrap();
    let mut cut = src.clone();
    cut.replace_range(
        at..at + r#"connect = ["tcp/192.0.2.10:7447"]"#.len(),
        "connect = []",
    );
    let e = parse(&path, &cut).expect_err("chain2 links to nobody").0;
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].field, "machine[2]");
    assert!(
        e[0].message.contains("\"chain2\"") && e[0].message.contains("\"host\""),
        "{}",
        e[0].message
    );
    // chain2 linked to chain1 only: joined to the host through chain1's hub.
    let through = src.replacen(
        "roles = [\"j1\", \"j2\"]",
        "roles = [\"j1\", \"j2\"]\nlisten = [\"tcp/0.0.0.0:7448\"]",
        1,
    );
    let at = through
        .rfind(r#"connect = ["tcp/192.0.2.10:7447"]"#)
        .unwrap();
    let mut through = through.clone();
    through.replace_range(
        at..at + r#"connect = ["tcp/192.0.2.10:7447"]"#.len(),
        r#"connect = ["tcp/192.0.2.11:7448"]"#,
    );
    parse(&path, &through).unwrap();
}

#[test]
fn an_endpoint_reaches_a_listener_on_its_host_or_on_every_address() {
    assert!(endpoint_reaches("tcp/10.0.0.1:7447", "tcp/10.0.0.1:7447"));
    assert!(endpoint_reaches("tcp/10.0.0.1:7447", "tcp/0.0.0.0:7447"));
    assert!(!endpoint_reaches("tcp/10.0.0.1:7447", "tcp/0.0.0.0:7448"));
    assert!(!endpoint_reaches("udp/10.0.0.1:7447", "tcp/0.0.0.0:7447"));
    assert!(!endpoint_reaches("tcp/10.0.0.2:7447", "tcp/10.0.0.1:7447"));
}
