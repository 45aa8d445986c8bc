//! The wire format is cross-language: `protocol/python/rig_wire.py`, written from WIRE.md with
//! Python's `struct` only, decodes what the Rust encoder writes, field by field.
//!
//! Needs `python3` (`cargo xtask test` provides it). A missing interpreter fails the test.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};

use rig_protocol::*;
use serde_json::Value;

const T: u64 = 1_763_776_000_123_456_789;

fn decoder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../protocol/python/rig_wire.py")
}

/// Writes each payload to a file and returns what the Python decoder prints, one per payload.
fn python_decode(payloads: &[Vec<u8>]) -> Result<Vec<Value>, String> {
    let dir = std::env::temp_dir().join(format!(
        "rig-wire-{}-{}",
        std::process::id(),
        payloads.len()
    ));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let mut files = Vec::new();
    for (i, p) in payloads.iter().enumerate() {
        let f = dir.join(format!("{i}.bin"));
        std::fs::write(&f, p).map_err(|e| e.to_string())?;
        files.push(f);
    }
    let out = common::tool("python3")
        .arg(decoder())
        .args(&files)
        .output()
        .map_err(|e| format!("python3 is required for this test (CI installs it): {e}"))?;
    std::fs::remove_dir_all(&dir).ok();
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).map_err(|e| e.to_string()))
        .collect()
}

#[test]
fn python_decodes_every_kind_like_rust() {
    let sample = JointSample {
        joint: 3,
        seq: 12345,
        t_acq_ns: T,
        motor_rad: 0.25,
        deflection_rad: -0.0123,
        pivot_m: Some(0.0091),
        torque_nm: None,
        motor_torque_nm: Some(0.5),
        stiffness_motor_rad: None,
    };
    let command = JointCommand {
        joint: 1,
        seq: 7,
        t_ns: T,
        motor_goal_rad: None,
        pivot_goal_m: Some(0.012),
        stiffness_motor_goal_rad: None,
        torque_enable: true,
    };
    let status = JointStatus {
        joint: 2,
        seq: 9,
        t_ns: T,
        state: JointState::Rejected,
        text: "pivot_goal_m 0.03 > d_max 0.018 (µ ok)".into(),
    };
    let estimate = JointEstimate {
        joint: 0,
        seq: 12345,
        t_acq_ns: T,
        torque_nm: 0.75,
        stiffness_nm_per_rad: Some(12.5),
        inertia_kg_m2: None,
        inertia_var: None,
        damping_nms_per_rad: Some(0.4),
        damping_var: Some(1e-4),
        residual_nm: None,
    };
    let ee = EeEstimate {
        seq: 5,
        t_ns: T,
        stale_mask: 0b1000,
        x_m: 0.075,
        y_m: 0.2,
        phi_rad: 0.4,
        force_n: Some((1.5, -2.25)),
        stiffness_n_per_m: Some(StiffnessTriple {
            xx: 1358.7,
            xy: 0.0,
            yy: 1429.7,
        }),
    };
    let request = AllocationRequest {
        id: 77,
        x_m: 0.075,
        y_m: 0.2,
        target: AllocationTarget::Percent(25.0),
    };
    let result = AllocationResult {
        id: 77,
        feasible: true,
        residual: 1.6e-12,
        target: StiffnessTriple {
            xx: 1358.7,
            xy: 0.0,
            yy: 1429.7,
        },
        achieved: StiffnessTriple {
            xx: 1358.7,
            xy: -1e-13,
            yy: 1429.7,
        },
        k_joint_nm_per_rad: vec![10.07, 9.96, 14.5, 21.8],
        pivot_m: vec![0.01356, 0.01353, 0.01463, 0.01571],
        error: String::new(),
    };
    let payloads = vec![
        encode(&sample).unwrap(),
        encode(&command).unwrap(),
        encode(&status).unwrap(),
        encode(&estimate).unwrap(),
        encode(&ee).unwrap(),
        encode(&request).unwrap(),
        encode(&result).unwrap(),
        encode(&SimTruth {
            joint: 1,
            seq: 7,
            t_acq_ns: T,
            deflection_rad: 0.004,
            torque_nm: 0.031,
            link_rad: -0.2,
            stiffness_nm_per_rad: 3.5,
        })
        .unwrap(),
        encode(&BoardSample {
            samples: vec![
                sample,
                JointSample {
                    joint: 5,
                    seq: 12346,
                    torque_nm: Some(-0.75),
                    pivot_m: None,
                    ..sample
                },
            ],
        })
        .unwrap(),
    ];
    let v = python_decode(&payloads).unwrap();
    assert_eq!(v.len(), 9);

    assert_eq!(v[0]["kind"], "joint_sample");
    assert_eq!(v[0]["joint"], 3);
    assert_eq!(v[0]["seq"], 12345);
    assert_eq!(v[0]["t_acq_ns"].as_u64(), Some(T));
    assert_eq!(v[0]["deflection_rad"].as_f64(), Some(-0.0123));
    assert_eq!(v[0]["pivot_m"].as_f64(), Some(0.0091));
    assert_eq!(v[0]["torque_nm"], Value::Null);
    assert_eq!(v[0]["motor_torque_nm"].as_f64(), Some(0.5));

    assert_eq!(v[1]["kind"], "joint_command");
    assert_eq!(v[1]["pivot_goal_m"].as_f64(), Some(0.012));
    assert_eq!(v[1]["motor_goal_rad"], Value::Null);
    assert_eq!(v[1]["torque_enable"], true);

    assert_eq!(v[2]["state"], "rejected");
    assert_eq!(v[2]["text"], status.text.as_str());

    assert_eq!(v[3]["stiffness_nm_per_rad"].as_f64(), Some(12.5));
    assert_eq!(v[3]["inertia_kg_m2"], Value::Null);
    assert_eq!(v[3]["damping_var"].as_f64(), Some(1e-4));

    assert_eq!(v[4]["stale_mask"], 8);
    assert_eq!(v[4]["force_n"][1].as_f64(), Some(-2.25));
    assert_eq!(v[4]["stiffness_n_per_m"]["yy"].as_f64(), Some(1429.7));

    assert_eq!(v[5]["target"]["percent"].as_f64(), Some(25.0));
    assert_eq!(v[6]["k_joint_nm_per_rad"][3].as_f64(), Some(21.8));
    assert_eq!(v[6]["pivot_m"][0].as_f64(), Some(0.01356));
    assert_eq!(v[6]["achieved"]["xy"].as_f64(), Some(-1e-13));
    assert_eq!(v[6]["feasible"], true);

    assert_eq!(v[7]["kind"], "sim_truth");
    assert_eq!(v[7]["stiffness_nm_per_rad"].as_f64(), Some(3.5));

    // A board's tick: each sample decoded as kind 1 is.
    assert_eq!(v[8]["kind"], "board_sample");
    let samples = v[8]["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 2);
    assert_eq!(samples[0], v[0]);
    assert_eq!(samples[1]["joint"], 5);
    assert_eq!(samples[1]["seq"], 12346);
    assert_eq!(samples[1]["torque_nm"].as_f64(), Some(-0.75));
    assert_eq!(samples[1]["pivot_m"], Value::Null);
    assert_eq!(samples[1]["t_acq_ns"].as_u64(), Some(T));
}

#[test]
fn python_refuses_what_rust_refuses() {
    let good = encode(&JointSample {
        joint: 0,
        seq: 1,
        t_acq_ns: T,
        motor_rad: 0.0,
        deflection_rad: 0.0,
        pivot_m: None,
        torque_nm: None,
        motor_torque_nm: None,
        stiffness_motor_rad: None,
    })
    .unwrap();
    let mut nan = good.clone();
    nan[36..44].copy_from_slice(&f64::NAN.to_le_bytes());
    let truncated = good[..good.len() - 3].to_vec();
    let mut version = good.clone();
    version[2] = 2;
    // A board message naming one joint twice, and one of no samples.
    let board = |bodies: &[&[u8]]| -> Vec<u8> {
        let mut body = (bodies.len() as u16).to_le_bytes().to_vec();
        for b in bodies {
            body.extend_from_slice(b);
        }
        let mut m = vec![b'V', b'R', 1, 9];
        m.extend_from_slice(&(body.len() as u32).to_le_bytes());
        m.extend(body);
        m
    };
    let twice = board(&[&good[8..], &good[8..]]);
    let empty = board(&[]);
    let mut other = good.clone();
    other[8] = 1;
    assert!(decode_any(&board(&[&good[8..], &other[8..]])).is_ok());
    assert!(python_decode(&[board(&[&good[8..], &other[8..]])]).is_ok());
    for bad in [nan, truncated, version, twice, empty] {
        assert!(decode_any(&bad).is_err());
        let err = python_decode(&[bad]).expect_err("python must refuse it too");
        assert!(err.contains("WireError"), "{err}");
    }
}
