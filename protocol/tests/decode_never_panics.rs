//! Property tests: decoding arbitrary or truncated bytes returns an error, never panics,
//! and every valid message survives a round trip.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use proptest::prelude::*;
use rig_protocol::*;

fn finite() -> impl Strategy<Value = f64> {
    -1e3..1e3f64
}

fn opt() -> impl Strategy<Value = Option<f64>> {
    prop::option::of(-0.5..0.5f64)
}

fn sample() -> impl Strategy<Value = JointSample> {
    (
        any::<u16>(),
        any::<u64>(),
        1..u64::MAX,
        finite(),
        -3.0..3.0f64,
        opt(),
        opt(),
        opt(),
        opt(),
    )
        .prop_map(|(joint, seq, t, m, d, p, tq, mt, sm)| JointSample {
            joint,
            seq,
            t_acq_ns: t,
            motor_rad: m,
            deflection_rad: d,
            pivot_m: p,
            torque_nm: tq,
            motor_torque_nm: mt,
            stiffness_motor_rad: sm,
        })
}

fn status() -> impl Strategy<Value = JointStatus> {
    (
        any::<u16>(),
        any::<u64>(),
        1..u64::MAX,
        0u8..5,
        "[ -~]{0,80}",
    )
        .prop_map(|(joint, seq, t, s, text)| JointStatus {
            joint,
            seq,
            t_ns: t,
            state: [
                JointState::Ok,
                JointState::Rejected,
                JointState::SafeHold,
                JointState::Fault,
                JointState::Stopped,
            ][s as usize],
            text,
        })
}

fn result() -> impl Strategy<Value = AllocationResult> {
    (
        any::<u64>(),
        any::<bool>(),
        0.0..1e3f64,
        prop::collection::vec((0.0..100.0f64, -0.02..0.02f64), 0..6),
        "[ -~]{0,40}",
    )
        .prop_map(|(id, feasible, residual, kd, error)| AllocationResult {
            id,
            feasible,
            residual,
            target: StiffnessTriple {
                xx: 100.0,
                xy: 0.0,
                yy: 200.0,
            },
            achieved: StiffnessTriple {
                xx: 99.0,
                xy: 0.5,
                yy: 201.0,
            },
            k_joint_nm_per_rad: kd.iter().map(|p| p.0).collect(),
            pivot_m: kd.iter().map(|p| p.1).collect(),
            error,
        })
}

/// A board's tick: 1 to 8 samples, each of its own joint.
fn board() -> impl Strategy<Value = BoardSample> {
    prop::collection::vec(sample(), 1..8).prop_map(|mut samples| {
        for (i, s) in samples.iter_mut().enumerate() {
            s.joint = i as u16;
        }
        BoardSample { samples }
    })
}

fn all_encodings() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        sample().prop_map(|m| encode(&m).unwrap()),
        board().prop_map(|m| encode(&m).unwrap()),
        status().prop_map(|m| encode(&m).unwrap()),
        result().prop_map(|m| encode(&m).unwrap()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let _ = decode_any(&bytes);
    }

    #[test]
    fn random_bodies_behind_a_valid_header_never_panic(kind in 1u8..=9, body in prop::collection::vec(any::<u8>(), 0..200)) {
        let mut bytes = vec![b'V', b'R', VERSION, kind];
        bytes.extend_from_slice(&(body.len() as u32).to_le_bytes());
        bytes.extend_from_slice(&body);
        let _ = decode_any(&bytes);
    }

    #[test]
    fn every_truncation_is_an_error(bytes in all_encodings()) {
        prop_assert!(decode_any(&bytes).is_ok());
        for n in 0..bytes.len() {
            prop_assert!(decode_any(&bytes[..n]).is_err(), "truncated to {} of {} decoded", n, bytes.len());
        }
        let mut longer = bytes.clone();
        longer.push(0);
        prop_assert!(decode_any(&longer).is_err());
    }

    #[test]
    fn samples_round_trip(m in sample()) {
        prop_assert_eq!(decode::<JointSample>(&encode(&m).unwrap()).unwrap(), m);
    }

    #[test]
    fn board_samples_round_trip(m in board()) {
        prop_assert_eq!(decode::<BoardSample>(&encode(&m).unwrap()).unwrap(), m);
    }

    #[test]
    fn statuses_round_trip(m in status()) {
        prop_assert_eq!(decode::<JointStatus>(&encode(&m).unwrap()).unwrap(), m);
    }

    #[test]
    fn results_round_trip(m in result()) {
        prop_assert_eq!(decode::<AllocationResult>(&encode(&m).unwrap()).unwrap(), m);
    }
}

#[test]
fn every_kind_round_trips() {
    let t = 1_700_000_000_000_000_000;
    let msgs = vec![
        encode(&JointCommand {
            joint: 1,
            seq: 2,
            t_ns: t,
            motor_goal_rad: Some(0.3),
            pivot_goal_m: None,
            stiffness_motor_goal_rad: Some(4.0),
            torque_enable: true,
        })
        .unwrap(),
        encode(&JointEstimate {
            joint: 3,
            seq: 9,
            t_acq_ns: t,
            torque_nm: 0.4,
            stiffness_nm_per_rad: Some(12.0),
            inertia_kg_m2: Some(0.05),
            inertia_var: Some(1e-6),
            damping_nms_per_rad: None,
            damping_var: None,
            residual_nm: Some(-0.01),
        })
        .unwrap(),
        encode(&EeEstimate {
            seq: 1,
            t_ns: t,
            stale_mask: 0b100,
            x_m: 0.075,
            y_m: 0.2,
            phi_rad: 0.3,
            force_n: Some((1.0, -2.0)),
            stiffness_n_per_m: None,
        })
        .unwrap(),
        encode(&AllocationRequest {
            id: 5,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Percent(25.0),
        })
        .unwrap(),
        encode(&AllocationRequest {
            id: 6,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Stiffness(StiffnessTriple {
                xx: 500.0,
                xy: 0.0,
                yy: 700.0,
            }),
        })
        .unwrap(),
    ];
    for bytes in msgs {
        let m = decode_any(&bytes).unwrap();
        let again = match &m {
            AnyMessage::JointCommand(x) => encode(x).unwrap(),
            AnyMessage::JointEstimate(x) => encode(x).unwrap(),
            AnyMessage::EeEstimate(x) => encode(x).unwrap(),
            AnyMessage::AllocationRequest(x) => encode(x).unwrap(),
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(again, bytes);
    }
}
