//! `rig calibrate` end to end: a bench joint whose config carries a wrong restoring table
//! (every stiffness 40 % low) is recorded on the simulated bench at three pivot positions
//! (`rig sim`), calibrated with `--write`, and scored on held-out runs of other seeds: the
//! torque error falls to within 2× the simulator's torque-sensor noise, the pivot positions the
//! data does not reach are named and kept, and the written config validates and reproduces the
//! fitted table.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::bin;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

/// The lever-bench scenario's torque-sensor noise [N·m] (agents/sim/scenarios/lever-bench.toml).
const NOISE_NM: f64 = 0.003;

fn scratch(name: &str) -> PathBuf {
    common::test_dir("calibrate").join(name)
}

/// A simulated bench run at pivot `d_mm` (20 s at 1 kHz, 14-bit encoder, 3 mN·m torque noise).
fn bench_run(d_mm: f64, seed: u64) -> PathBuf {
    let scenario = scratch(&format!("bench-{d_mm}-{seed}.toml"));
    std::fs::write(
        &scenario,
        format!(
            "kind = \"lever-bench\"\nduration_s = 20.0\nrate_hz = 1000.0\nseed = {seed}\n\
             [lever_bench]\npivot_mm = {d_mm}\namplitude_rad = 0.04\n\
             [sensors]\nencoder_bits = 14\ntorque_noise_nm = {NOISE_NM}\n"
        ),
    )
    .unwrap();
    let out = scratch(&format!("bench-{d_mm}-{seed}.csv"));
    let o = Command::new(bin("rig"))
        .args(["sim", "--scenario"])
        .arg(&scenario)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

/// The bench example with every k and A_s of its table scaled by `factor`.
fn wrong_config(factor: f64) -> PathBuf {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../rig-config/examples/bench.toml");
    let text = std::fs::read_to_string(example).unwrap();
    let scaled: Vec<String> = text
        .lines()
        .map(|l| match l.split_once(" = ") {
            Some((key @ ("k_nm_per_rad" | "a_s"), v)) => {
                format!("{key} = {}", v.trim().parse::<f64>().unwrap() * factor)
            }
            _ => l.to_string(),
        })
        .collect();
    let path = scratch("bench-wrong.toml");
    std::fs::write(&path, scaled.join("\n") + "\n").unwrap();
    path
}

fn calibrate(config: &Path, extra: &[&str], fit: &[PathBuf], held: &[PathBuf]) -> Value {
    let mut c = Command::new(bin("rig"));
    c.args(["calibrate", "--joint", "j1", "--json", "--config"])
        .arg(config);
    for f in fit {
        c.arg("--data").arg(f);
    }
    for f in held {
        c.arg("--holdout").arg(f);
    }
    let o = c.args(extra).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn a_wrong_table_is_calibrated_to_the_noise_floor_and_written_into_the_config() {
    let pivots = [4.5, 9.0, 13.5];
    let fit: Vec<PathBuf> = pivots.iter().map(|&d| bench_run(d, 1)).collect();
    let held: Vec<PathBuf> = pivots.iter().map(|&d| bench_run(d, 7)).collect();
    let config = wrong_config(0.6);

    let r = calibrate(&config, &["--write"], &fit, &held);
    let (before, after) = (
        r["rmse_before_nm"].as_f64().unwrap(),
        r["rmse_after_nm"].as_f64().unwrap(),
    );
    println!("calibrate: held-out torque RMSE {before:.4} → {after:.4} N·m (noise {NOISE_NM})");
    assert_eq!(r["scored_on"], "holdout");
    assert!(after <= 2.0 * NOISE_NM, "after {after} N·m");
    assert!(before >= 3.0 * after, "before {before}, after {after}");
    // Fitted where the data is; the config's other points kept and named.
    let fitted: Vec<f64> = r["fitted"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g["d_mm"].as_f64().unwrap())
        .collect();
    assert_eq!(fitted.len(), 3);
    for (f, d) in fitted.iter().zip(pivots) {
        assert!((f - d).abs() < 1e-9, "{f} vs {d}");
    }
    let kept: Vec<f64> = r["kept_from_config_mm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(kept.len(), 6, "{kept:?}");

    // The written config validates, keeps its comments, and now scores as the new table did.
    let text = std::fs::read_to_string(&config).unwrap();
    assert!(text.contains("# Fitted by `rig calibrate` on"));
    assert!(text.contains("[joint.lever]                 # paper B §2"));
    let v = Command::new(bin("rig"))
        .args(["validate"])
        .arg(&config)
        .output()
        .unwrap();
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
    let again = calibrate(&config, &[], &fit, &held);
    let now = again["rmse_before_nm"].as_f64().unwrap();
    assert!(
        (now - after).abs() <= 0.02 * after,
        "the written table scores {now}, the fitted one {after}"
    );
}

#[test]
fn calibrate_refuses_data_without_a_pivot_and_writes_nothing() {
    let fit = bench_run(9.0, 3);
    // Drop the d column: the pivot is then unknown unless --pivot-mm gives it.
    let text = std::fs::read_to_string(&fit).unwrap();
    let no_d: String = text
        .lines()
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            format!("{},{},{}\n", c[0], c[1], c[2])
        })
        .collect();
    let path = scratch("no-d.csv");
    std::fs::write(&path, no_d).unwrap();
    let config = scratch("untouched.toml");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../rig-config/examples/bench.toml"),
        &config,
    )
    .unwrap();
    let before = std::fs::read_to_string(&config).unwrap();
    let o = Command::new(bin("rig"))
        .args(["calibrate", "--joint", "j1", "--write", "--config"])
        .arg(&config)
        .arg("--data")
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no pivot position (d) column"), "{err}");
    assert_eq!(std::fs::read_to_string(&config).unwrap(), before);
    // With the pivot given, the same data calibrates.
    let r = calibrate(&config, &["--pivot-mm", "9"], &[path], &[]);
    assert_eq!(r["scored_on"], "fit");
}
