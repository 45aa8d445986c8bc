//! The `rig` binary end to end: exit codes, messages that name the problem, and the numbers
//! of `rig allocate --json` checked against closed forms.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn example(name: &str) -> PathBuf {
    root().join("rig-config/examples").join(name)
}

fn rig(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rig"))
        .args(args)
        .output()
        .expect("run rig")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn allocate_json(extra: &[&str]) -> (Output, Value) {
    let cfg = example("parallel.toml");
    let mut args = vec!["allocate", "--config", cfg.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    let out = rig(&args);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
    (out, v)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

#[test]
fn validate_accepts_the_examples() {
    let files: Vec<PathBuf> = ["awas.toml", "serial.toml", "parallel.toml"]
        .iter()
        .map(|n| example(n))
        .collect();
    let mut args = vec!["validate"];
    args.extend(files.iter().map(|p| p.to_str().unwrap()));
    let out = rig(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        text(&out.stdout)
            .lines()
            .filter(|l| l.starts_with("ok: "))
            .count(),
        3
    );
}

#[test]
fn validate_refuses_bad_files_naming_file_line_and_field() {
    let dir = std::env::temp_dir().join(format!("rig-validate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = std::fs::read_to_string(example("parallel.toml")).unwrap();
    let cases = [
        ("nan.toml", "l1_mm = 150.0", "l1_mm = nan", "geometry.l1_mm"),
        (
            "negative.toml",
            "l3_mm = 150.0",
            "l3_mm = -150.0",
            "geometry.l3_mm",
        ),
        (
            "d_range.toml",
            "d_max_mm = 18.0",
            "d_max_mm = 30.0",
            "joint[0].lever.d_max_mm",
        ),
        (
            "dup_id.toml",
            "stiffness_id = 12",
            "stiffness_id = 11",
            "joint[1].servo.stiffness_id",
        ),
        (
            "unknown.toml",
            "[joint.lever]",
            "[joint.lever]\nspring_rate = 2.0",
            "spring_rate",
        ),
    ];
    for (file, from, to, field) in cases {
        let path = dir.join(file);
        std::fs::write(&path, good.replacen(from, to, 1)).unwrap();
        let out = rig(&["validate", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(1), "{file}");
        let err = text(&out.stderr);
        // The line of the replaced text (its last line, where a key was added).
        let expected_line =
            good[..good.find(from).unwrap()].matches('\n').count() + to.matches('\n').count() + 1;
        let prefix = format!("{}:{expected_line}: {field}: ", path.display());
        assert!(
            err.contains(&prefix),
            "{file}: expected {prefix:?} in\n{err}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn allocate_json_has_every_key_and_consistent_numbers() {
    let (out, v) = allocate_json(&["--at", "75,200", "--percent", "25"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for key in [
        "k_joint_nm_per_rad",
        "pivot_mm",
        "k_operational_n_per_m",
        "target_n_per_m",
        "residual",
        "feasible",
        "range_n_per_m",
        "s_matrix",
        "k_bounds_nm_per_rad",
        "geometry_m",
        "joint_angles_rad",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["feasible"], Value::Bool(true));
    let k: Vec<f64> = v["k_joint_nm_per_rad"]
        .as_array()
        .unwrap()
        .iter()
        .map(f)
        .collect();
    let s: Vec<Vec<f64>> = v["s_matrix"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_array().unwrap().iter().map(f).collect())
        .collect();
    assert_eq!((k.len(), s.len(), s[0].len()), (4, 3, 4));
    assert_eq!(v["joint_angles_rad"].as_array().unwrap().len(), 5);
    // Achieved = S·k, and it equals the target: k_xy = 0, k_xx/k_yy at 25 % of the range.
    let sk: Vec<f64> = s
        .iter()
        .map(|row| row.iter().zip(&k).map(|(a, b)| a * b).sum())
        .collect();
    let ach = &v["k_operational_n_per_m"];
    let tgt = &v["target_n_per_m"];
    let (min, max) = (&v["range_n_per_m"]["min"], &v["range_n_per_m"]["max"]);
    for (i, c) in ["xx", "xy", "yy"].iter().enumerate() {
        assert!((sk[i] - f(&ach[c])).abs() < 1e-9 * f(&max["xx"]));
        assert!(
            (f(&ach[c]) - f(&tgt[c])).abs() < 1e-8 * f(&max["xx"]),
            "{c}"
        );
    }
    assert_eq!(f(&tgt["xy"]), 0.0);
    assert!(
        (f(&tgt["xx"]) - (f(&min["xx"]) + 0.25 * (f(&max["xx"]) - f(&min["xx"])))).abs()
            < 1e-9 * f(&max["xx"])
    );
    // Range ends are S·k_min and S·k_max.
    let kmin: Vec<f64> = v["k_bounds_nm_per_rad"]["min"]
        .as_array()
        .unwrap()
        .iter()
        .map(f)
        .collect();
    let s_kmin: f64 = s[0].iter().zip(&kmin).map(|(a, b)| a * b).sum();
    assert!((s_kmin - f(&min["xx"])).abs() < 1e-9 * s_kmin);
    // Each pivot gives its joint stiffness by the joint's calibrated table k(d) (what the
    // estimator reports), within a few per cent of paper B eq. 3, (d_a/(p − d_a))²·k_α, the
    // lever law the table's simulated joint has (5 % of its spring is friction).
    let cfg = rig_config::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../rig-config/examples/parallel.toml"),
    )
    .unwrap();
    let pivots: Vec<f64> = v["pivot_mm"].as_array().unwrap().iter().map(f).collect();
    for ((d_mm, kj), joint) in pivots.iter().zip(&k).zip(&cfg.joints) {
        let rig_config::JointKind::Lever { restoring, .. } = &joint.kind else {
            panic!("the example's joints are lever joints")
        };
        let k_table = restoring.at(d_mm * 1e-3).k;
        assert!(
            (k_table - kj).abs() < 1e-6 * kj,
            "pivot {d_mm} mm gives {k_table} by the table, wanted {kj}"
        );
        let da = 9.6 + d_mm;
        let k_eq3 = (da / (31.5 - da)).powi(2) * 1.3042;
        assert!(
            (0.93..1.0).contains(&(kj / k_eq3)),
            "pivot {d_mm} mm: table {kj}, lever law {k_eq3}"
        );
        assert!((0.0..=18.0).contains(d_mm));
    }
    // The geometry is the example's, in metres.
    assert_eq!(f(&v["geometry_m"]["l5"]), 0.05);
}

#[test]
fn allocate_table_is_readable() {
    let cfg = example("parallel.toml");
    let out = rig(&[
        "allocate",
        "--config",
        cfg.to_str().unwrap(),
        "--at",
        "75,200",
        "--k",
        "800,900",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let t = text(&out.stdout);
    for needle in ["target", "achieved", "pivot d [mm]", "j4", "target met"] {
        assert!(t.contains(needle), "{needle} missing in\n{t}");
    }
}

#[test]
fn allocate_refuses_what_it_cannot_do() {
    // Unreachable pose.
    let (out, _) = allocate_json(&["--at", "75,900", "--percent", "25"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(
        text(&out.stderr).contains("out of reach"),
        "{}",
        text(&out.stderr)
    );
    // Target outside the range: no silent clamp.
    let (out, _) = allocate_json(&["--at", "75,200", "--k", "1e6,100"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(text(&out.stderr).contains("k_xx"), "{}", text(&out.stderr));
    // Percent outside [0, 100]: a usage error, refused while parsing.
    let (out, _) = allocate_json(&["--at", "75,200", "--percent", "140"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("140 is not a percentage"),
        "{}",
        text(&out.stderr)
    );
    // A single-joint rig has no operational space.
    let out = rig(&[
        "allocate",
        "--config",
        example("awas.toml").to_str().unwrap(),
        "--percent",
        "10",
    ]);
    assert_eq!(out.status.code(), Some(1));
    // Malformed numbers are usage errors.
    let (out, _) = allocate_json(&["--at", "75,abc", "--percent", "25"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("abc"));
}

#[test]
fn a_target_met_only_approximately_is_reported_with_the_compromise() {
    // Within each component's range but not jointly reachable: a strongly coupled k_xy with
    // tiny diagonal terms.
    let (_, v) = allocate_json(&["--at", "75,200", "--percent", "0"]);
    let min = &v["range_n_per_m"]["min"];
    let (out, v) = allocate_json(&[
        "--at",
        "75,200",
        "--k",
        &format!("{},{},{}", f(&min["xx"]), f(&min["yy"]), 1000.0),
    ]);
    assert_eq!(out.status.code(), Some(3), "{}", text(&out.stderr));
    assert_eq!(v["feasible"], Value::Bool(false));
    assert!(f(&v["residual"]) > 1.0);
    assert!(text(&out.stderr).contains("cannot be met exactly"));
}

#[test]
fn sim_writes_every_example_scenario_as_csv_and_as_mcap_that_exports_back_to_the_same_numbers() {
    let dir = std::env::temp_dir().join(format!("rig-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for name in [
        "lever-bench",
        "lever-bench-friction",
        "awas",
        "parallel-strokes",
        "serial-strokes",
    ] {
        // A shortened copy of each example: same content, 0.5 s.
        let src = std::fs::read_to_string(
            root()
                .join("agents/sim/scenarios")
                .join(format!("{name}.toml")),
        )
        .unwrap();
        let short: String = src
            .lines()
            .map(|l| {
                if l.starts_with("duration_s") {
                    "duration_s = 0.5".to_string()
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let scen = dir.join(format!("{name}.toml"));
        std::fs::write(&scen, short).unwrap();
        let out = dir.join(format!("{name}.csv"));
        let o = rig(&[
            "sim",
            "--scenario",
            scen.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        let csv = std::fs::read_to_string(&out).unwrap();
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(header[0], "t");
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 500, "{name}");
        assert!(
            rows.iter()
                .all(|r| r.len() == header.len() && r.iter().all(|v| v.is_finite()))
        );
        // The same scenario into MCAP, exported back to CSV: the same columns in the same
        // order after the log time, and the same numbers.
        let mcap = dir.join(format!("{name}.mcap"));
        let o = rig(&[
            "sim",
            "--scenario",
            scen.to_str().unwrap(),
            "--out",
            mcap.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        let exported = dir.join(format!("{name}-export"));
        let o = rig(&[
            "export",
            mcap.to_str().unwrap(),
            "--to",
            "csv",
            exported.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        let kind = src
            .lines()
            .find_map(|l| l.strip_prefix("kind = "))
            .unwrap()
            .trim_matches('"');
        let back = std::fs::read_to_string(exported.join(format!("sim.{kind}.csv"))).unwrap();
        let mut lines = back.lines();
        let back_header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let back_rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(back_rows.len(), rows.len(), "{name}");
        assert_eq!(back_header[0], "log_time_ns");
        assert_eq!(back_header[1..], header[..], "{name}");
        for (c, col) in header.iter().enumerate() {
            let b = back_header.iter().position(|h| h == col).unwrap();
            for (r, (row, back)) in rows.iter().zip(&back_rows).enumerate() {
                assert_eq!(row[c], back[b], "{name}: row {r}, column {col}");
            }
        }
        let log_time = back_header
            .iter()
            .position(|h| *h == "log_time_ns")
            .unwrap();
        assert_eq!(back_rows[1][log_time], (rows[1][0] * 1e9).round(), "{name}");
    }
    // A broken scenario names the problem; an output neither CSV nor MCAP is refused.
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "kind = \"lever-bench\"\nduration_s = 1.0\n").unwrap();
    let o = rig(&[
        "sim",
        "--scenario",
        bad.to_str().unwrap(),
        "--out",
        dir.join("x.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("[lever_bench]"),
        "{}",
        text(&o.stderr)
    );
    let scen = root().join("agents/sim/scenarios/awas.toml");
    let o = rig(&[
        "sim",
        "--scenario",
        scen.to_str().unwrap(),
        "--out",
        dir.join("x.parquet").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn reproduce_paper_a_json_has_the_documented_shape() {
    let o = rig(&["reproduce", "paper-a", "--quick", "--json"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let s = v["scenarios"].as_array().unwrap();
    assert_eq!(s.len(), 4);
    for row in s {
        for key in [
            "name",
            "noisy",
            "tuning",
            "stiffness_rel_err",
            "damping_rel_err",
            "inertia_rel_err",
            "convergence_s",
        ] {
            assert!(row.get(key).is_some(), "missing {key}");
        }
        assert!(row["tuning"] == "paper" || row["tuning"] == "ours");
    }
    let noisy_ours = s
        .iter()
        .find(|r| r["noisy"] == true && r["tuning"] == "ours")
        .unwrap();
    assert!(f(&noisy_ours["stiffness_rel_err"]) <= 0.01);
}

#[test]
fn reproduce_paper_b_json_has_the_documented_shape() {
    let o = rig(&["reproduce", "paper-b", "--quick", "--json"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    for (table, keys) in [
        ("torque_mae", &["d_mm", "mae_nm", "peak_nm"][..]),
        ("force", &["robot", "axis", "rmse_pct_of_peak"][..]),
        (
            "decoupling",
            &["percent", "spike_before_n", "spike_after_n"][..],
        ),
    ] {
        let rows = v[table].as_array().unwrap();
        assert!(!rows.is_empty(), "{table}");
        for row in rows {
            for key in keys {
                assert!(row.get(*key).is_some(), "{table}: missing {key}");
            }
        }
    }
    let percents: Vec<f64> = v["decoupling"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| f(&r["percent"]))
        .collect();
    assert_eq!(percents, vec![12.5, 25.0, 37.5]);
}
