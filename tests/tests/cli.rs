//! The flags every role shares (`rig_runtime::cli`): each long-running command refuses a
//! duration that is not a positive number of seconds — zero, negative, NaN, infinite, or so
//! large that it would overflow — with clap's usage error (status 2) naming `--duration` and
//! the value, before it opens anything; and a Rerun viewer URL given to `--connect` is refused
//! with the flag it belongs to.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::{bin, config};

use std::process::Command;
use std::time::{Duration, Instant};

fn run(binary: &str, args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(bin(binary)).args(args).output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn every_long_running_command_refuses_a_duration_that_is_not_a_positive_number_of_seconds() {
    let cfg = config();
    let cfg = cfg.to_str().unwrap();
    let out = std::env::temp_dir().join("rig-cli-never-written.mcap");
    let commands: Vec<(&str, Vec<&str>)> = vec![
        ("rig", vec!["up"]),
        ("rig", vec!["estimator", "--config", cfg]),
        ("rig", vec!["allocator", "--config", cfg]),
        ("rig", vec!["record", "--out", out.to_str().unwrap()]),
        ("rig", vec!["viz", "--save", "/tmp/never.rrd"]),
        ("rig", vec!["virtual-board", "--joint", "j1"]),
        ("rig", vec!["bench", "latency"]),
        ("rig", vec!["bench", "throughput"]),
        ("rig", vec!["pivot", "--joint", "j1", "--mm", "9"]),
        ("rig-joint", vec!["--config", cfg, "--joint", "j1"]),
    ];
    for (binary, cmd) in &commands {
        for bad in ["0", "-1", "nan", "inf", "1e20"] {
            let start = Instant::now();
            let mut args = cmd.clone();
            args.extend(["--duration", bad]);
            let (code, err) = run(binary, &args);
            assert_eq!(code, Some(2), "{binary} {args:?}: {err}");
            assert!(
                err.contains("--duration") && err.contains(bad),
                "{binary} {args:?}: {err}"
            );
            // Refused while parsing: nothing was started.
            assert!(
                start.elapsed() < Duration::from_secs(5),
                "{binary} {args:?}"
            );
        }
    }
    assert!(
        !out.exists(),
        "record wrote {} before refusing",
        out.display()
    );
}

#[test]
fn a_joint_agent_given_a_joint_twice_says_so_before_it_joins_the_rig() {
    let cfg = config();
    let start = Instant::now();
    let (code, err) = run(
        "rig-joint",
        &[
            "--config",
            cfg.to_str().unwrap(),
            "--joint",
            "j1,j2,j1",
            "--duration",
            "5",
        ],
    );
    assert_ne!(code, Some(0), "{err}");
    assert!(err.contains("joint j1 is named twice in --joint"), "{err}");
    assert!(start.elapsed() < Duration::from_secs(4), "it ran: {err}");
}

#[test]
fn a_rerun_viewer_url_given_to_connect_is_refused_with_the_flag_it_belongs_to() {
    for cmd in [vec!["up"], vec!["viz"]] {
        let mut args = cmd.clone();
        args.extend([
            "--duration",
            "1",
            "--connect",
            "rerun+http://127.0.0.1:9876/proxy",
        ]);
        let (code, err) = run("rig", &args);
        assert_ne!(code, Some(0), "{args:?}: {err}");
        assert!(
            err.contains("--viewer rerun+http://127.0.0.1:9876/proxy"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn a_stiffness_goal_that_is_not_a_percentage_of_the_range_is_refused() {
    let cfg = config();
    let cfg = cfg.to_str().unwrap();
    for bad in ["nan", "-5", "150", "inf"] {
        for cmd in [
            vec!["up", "--duration", "1", "--percent", bad],
            vec![
                "allocate",
                "--config",
                cfg,
                "--at",
                "75,200",
                "--percent",
                bad,
            ],
        ] {
            let (code, err) = run("rig", &cmd);
            assert_eq!(code, Some(2), "{cmd:?}: {err}");
            assert!(
                err.contains("--percent") && err.contains("percentage"),
                "{cmd:?}: {err}"
            );
        }
    }
}

#[test]
fn rig_allocate_live_says_when_no_allocator_answers_and_network_flags_need_live() {
    let cfg = config();
    let cfg = cfg.to_str().unwrap();
    // A port nobody listens on: the session opens, nobody answers.
    let nobody = format!("tcp/127.0.0.1:{}", common::free_port());
    let t0 = Instant::now();
    let (code, err) = run(
        "rig",
        &[
            "allocate",
            "--config",
            cfg,
            "--percent",
            "50",
            "--live",
            "--within",
            "1",
            "--connect",
            &nobody,
        ],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("no allocator answered on rig/parallel/allocate within 1 s"),
        "{err}"
    );
    assert!(t0.elapsed() < Duration::from_secs(20), "{:?}", t0.elapsed());
    let (code, err) = run(
        "rig",
        &[
            "allocate",
            "--config",
            cfg,
            "--percent",
            "50",
            "--connect",
            &nobody,
        ],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("they need --live"), "{err}");
    let (code, err) = run(
        "rig",
        &[
            "allocate",
            "--config",
            cfg,
            "--percent",
            "50",
            "--within",
            "3",
        ],
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--live"), "{err}");
}

#[test]
fn bytes_that_are_no_recording_are_an_error_and_a_report_never_makes_directories() {
    let dir = common::test_dir("cli-files");
    // Random bytes are not a recording: refused with status 1, naming the file.
    let junk = dir.join("junk.mcap");
    let bytes: Vec<u8> = (0..300u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&junk, bytes).unwrap();
    for args in [
        vec!["replay", "--as-fast-as-possible", junk.to_str().unwrap()],
        vec!["replay", "--estimate", junk.to_str().unwrap()],
    ] {
        let (code, err) = run("rig", &args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(
            err.contains("junk.mcap") && err.contains("not an MCAP recording"),
            "{err}"
        );
    }
    // `--report` into a directory that does not exist: refused before the fit, nothing made.
    let csv = dir.join("d.csv");
    std::fs::write(&csv, "t,phi,tau\n0,0,0\n0.001,0.001,0.001\n").unwrap();
    let missing = dir.join("no/such/dir");
    let report = missing.join("o.json");
    let (code, err) = run(
        "rig",
        &[
            "identify",
            "--data",
            csv.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("does not exist"), "{err}");
    assert!(!dir.join("no").exists(), "a directory was made");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn rig_validate_prints_the_plan_and_refuses_one_where_a_joint_runs_nowhere() {
    let o = Command::new(bin("rig"))
        .args(["validate"])
        .arg(config())
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}");
    assert!(
        out.contains(
            "machine \"chain2\" runs j3, j4; listens on nothing; connects to tcp/192.0.2.10:7447"
        ),
        "{out}"
    );
    assert!(
        out.contains(
            "machine \"host\" runs estimator, allocator, recorder; listens on tcp/0.0.0.0:7447"
        ),
        "{out}"
    );

    let dir = common::test_dir("validate-plan");
    let src = std::fs::read_to_string(config()).unwrap();
    let bad = dir.join("plan.toml");
    std::fs::write(
        &bad,
        src.replacen(r#"roles = ["j1", "j2"]"#, r#"roles = ["j1"]"#, 1),
    )
    .unwrap();
    let o = Command::new(bin("rig"))
        .args(["validate"])
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("machine: \"j2\" run(s) on no machine"),
        "{err}"
    );
}

#[test]
fn rig_launch_names_a_machine_the_plan_lacks_and_a_role_that_fails() {
    let o = Command::new(bin("rig"))
        .args(["launch", "--config"])
        .arg(config())
        .args(["--machine", "chain9"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("no such machine; it has host, chain1, chain2"),
        "{err}"
    );

    // chain1's joints on hardware this machine lacks: the joint agent fails, the launcher
    // says which role failed and ends (the hub's link to the host is only retried meanwhile).
    let t0 = Instant::now();
    let o = Command::new(bin("rig"))
        .args(["launch", "--config"])
        .arg(config())
        .args([
            "--machine",
            "chain1",
            "--backend",
            "dynamixel",
            "--duration",
            "20",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("machine chain1: joints j1,j2 (exit status: "),
        "{err}"
    );
    assert!(t0.elapsed() < Duration::from_secs(15), "{:?}", t0.elapsed());
}
