//! The joint agent stays light: nothing of Rerun in its dependency tree (it runs on the joint
//! boards; the view is `rig-viz`, pulled in by the `rig` command only), and built for hardware
//! only (`--no-default-features`) nothing of the simulator either. `.ci/run` also builds it so
//! (clippy), which proves that build compiles.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Command;

/// `cargo tree` of `pkg` (normal dependencies, one crate per line), with `extra` arguments.
fn tree(pkg: &str, extra: &[&str]) -> String {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let o = Command::new(&cargo)
        .current_dir(&root)
        .args([
            "tree",
            "--offline",
            "-e",
            "normal",
            "--prefix",
            "none",
            "-p",
            pkg,
        ])
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn the_joint_agent_has_nothing_of_rerun_in_its_tree() {
    let joint = tree("rig-joint", &[]);
    let rerun: Vec<&str> = joint
        .lines()
        .filter(|l| l.starts_with("rerun ") || l.starts_with("re_"))
        .collect();
    assert!(rerun.is_empty(), "rig-joint pulls in {rerun:?}");
    // The check can fail: the `rig` command does depend on Rerun.
    assert!(tree("rig", &[]).lines().any(|l| l.starts_with("rerun ")));
}

#[test]
fn a_hardware_only_joint_agent_has_no_simulator_in_its_tree() {
    let sims = |extra: &[&str]| {
        tree("rig-joint", extra)
            .lines()
            .any(|l| l.starts_with("rig-sim "))
    };
    assert!(
        !sims(&["--no-default-features"]),
        "rig-joint --no-default-features pulls in the simulator"
    );
    // The check can fail: the default build (what `rig up` runs) has the simulated board.
    assert!(sims(&[]));
}
