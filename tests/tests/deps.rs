//! The joint agent stays light: nothing of Rerun in its dependency tree (it runs on the joint
//! boards; the view is `rig-viz`, pulled in by the `rig` command only).

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Command;

#[test]
fn the_joint_agent_has_nothing_of_rerun_in_its_tree() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let tree = |pkg: &str| {
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
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let joint = tree("rig-joint");
    let rerun: Vec<&str> = joint
        .lines()
        .filter(|l| l.starts_with("rerun ") || l.starts_with("re_"))
        .collect();
    assert!(rerun.is_empty(), "rig-joint pulls in {rerun:?}");
    // The check can fail: the `rig` command does depend on Rerun.
    assert!(tree("rig").lines().any(|l| l.starts_with("rerun ")));
}
