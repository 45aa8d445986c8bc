//! `rig-joint` refuses bad input with a clear message and a non-zero status.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::Command;

fn example() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../rig-config/examples/parallel.toml")
        .to_string_lossy()
        .into_owned()
}

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_rig-joint"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn bad_config_unknown_joint_and_missing_backend_are_clear_errors() {
    let (code, err) = run(&["--config", "/nonexistent.toml", "--joint", "j1"]);
    assert_eq!(code, Some(1));
    assert!(err.contains("cannot read the file"), "{err}");
    let (code, err) = run(&["--config", &example(), "--joint", "j9", "--duration", "0.1"]);
    assert_eq!(code, Some(1));
    assert!(
        err.contains("j9") && err.contains("j1, j2, j3, j4"),
        "{err}"
    );
    // The hardware is not there: the port is named, the agent ends with status 1.
    let dynamixel = [
        "--config",
        &example(),
        "--joint",
        "j1",
        "--backend",
        "dynamixel",
    ];
    let (code, err) = run(&dynamixel);
    assert_eq!(code, Some(1));
    assert!(
        err.contains("/dev/ttyUSB0: cannot open at 1000000 baud"),
        "{err}"
    );
    // Paper A's AWAS joint has no Dynamixel board.
    let awas = example().replace("parallel.toml", "awas.toml");
    let (code, err) = run(&[
        "--config",
        &awas,
        "--joint",
        "awas",
        "--backend",
        "dynamixel",
    ]);
    assert_eq!(code, Some(1));
    assert!(err.contains("Dynamixel boards drive lever VSAs"), "{err}");
    // Ports belong to the dynamixel backend; unknown backends are refused by name.
    let (code, err) = run(&["--config", &example(), "--joint", "j1", "--bus", "/dev/x"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--backend dynamixel"), "{err}");
    let (code, err) = run(&["--config", &example(), "--joint", "j1", "--backend", "can"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("[possible values: sim, dynamixel]"), "{err}");
}

#[test]
fn runs_for_a_duration_and_reports() {
    let (code, err) = run(&["--config", &example(), "--joint", "j2", "--duration", "0.5"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("samples"), "{err}");
}

#[test]
fn listening_beyond_loopback_without_security_says_insecure_and_on_loopback_does_not() {
    let port = rig_runtime::free_loopback_port().unwrap();
    // Listening only: nothing is sent anywhere (multicast scouting is off, nothing to connect).
    let everywhere = format!("tcp/0.0.0.0:{port}");
    let (code, err) = run(&[
        "--config",
        &example(),
        "--joint",
        "j1",
        "--listen",
        &everywhere,
        "--duration",
        "0.3",
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("INSECURE") && err.contains(&everywhere) && err.contains("SECURITY.md"),
        "{err}"
    );
    let (code, err) = run(&["--config", &example(), "--joint", "j1", "--duration", "0.3"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("INSECURE"), "{err}");
}

#[test]
fn one_board_serves_several_joints() {
    let (code, err) = run(&[
        "--config",
        &example(),
        "--joint",
        "j1,j3",
        "--duration",
        "0.5",
    ]);
    assert_eq!(code, Some(0), "{err}");
    for j in ["j1", "j3"] {
        let line = err
            .lines()
            .find(|l| l.starts_with(&format!("rig-joint {j}: ")))
            .unwrap_or_else(|| panic!("no report for {j}: {err}"));
        let samples: u64 = line.split_whitespace().nth(2).unwrap().parse().unwrap();
        // 0.5 s at 1 kHz, the timer's first wake-up and last tick give or take.
        assert!((400..=510).contains(&samples), "{line}");
    }
}
