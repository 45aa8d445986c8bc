//! The recordings' JSON (feature `json`) is lossless: every kind, read back from its JSON,
//! encodes to the same wire bytes; random numbers of every magnitude survive; JSON that is not
//! a valid message is an error naming the kind or the field; each kind's schema names every
//! field its JSON carries.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use proptest::prelude::*;
use rig_protocol::json::{
    encode_any, from_json, json_schema, kind_of_schema, schema_name, to_json,
};
use rig_protocol::*;

const T: u64 = 1_700_000_000_123_456_789;

fn one_of_each() -> Vec<AnyMessage> {
    let k = StiffnessTriple {
        xx: 1358.7,
        xy: -1e-13,
        yy: 1429.7,
    };
    vec![
        JointSample {
            joint: 3,
            seq: u64::MAX - 1,
            t_acq_ns: T,
            motor_rad: 0.1 + 0.2,
            deflection_rad: -0.012_345_678_901_234_5,
            pivot_m: Some(0.0091),
            torque_nm: None,
            motor_torque_nm: Some(5e-324),
            stiffness_motor_rad: None,
        }
        .into(),
        JointCommand {
            joint: 1,
            seq: 7,
            t_ns: T,
            motor_goal_rad: None,
            pivot_goal_m: Some(0.012),
            stiffness_motor_goal_rad: None,
            torque_enable: true,
        }
        .into(),
        JointStatus {
            joint: 2,
            seq: 9,
            t_ns: T,
            state: JointState::Rejected,
            text: "pivot_goal_m 0.03 > d_max 0.018 (µ \"quoted\")".into(),
        }
        .into(),
        JointEstimate {
            joint: 0,
            seq: 12345,
            t_acq_ns: T,
            torque_nm: 0.75,
            stiffness_nm_per_rad: Some(12.5),
            inertia_kg_m2: None,
            inertia_var: Some(1.234_567_890_123e-9),
            damping_nms_per_rad: Some(0.4),
            damping_var: None,
            residual_nm: Some(-0.0),
        }
        .into(),
        EeEstimate {
            seq: 5,
            t_ns: T,
            stale_mask: 0b1000,
            x_m: 0.075,
            y_m: 0.2,
            phi_rad: 0.4,
            force_n: Some((1.5, -2.25)),
            stiffness_n_per_m: Some(k),
        }
        .into(),
        AllocationRequest {
            id: 77,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Percent(25.0),
        }
        .into(),
        AllocationRequest {
            id: 78,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Stiffness(k),
        }
        .into(),
        AllocationResult {
            id: 77,
            feasible: true,
            residual: 1.6e-12,
            target: k,
            achieved: k,
            k_joint_nm_per_rad: vec![10.07, 9.96, 14.5, 21.8],
            pivot_m: vec![0.01356, 0.01353, 0.01463, 0.01571],
            error: String::new(),
        }
        .into(),
        BoardSample {
            samples: vec![
                JointSample {
                    joint: 0,
                    seq: 8,
                    t_acq_ns: T,
                    motor_rad: 0.1,
                    deflection_rad: -0.002,
                    pivot_m: Some(0.012),
                    torque_nm: None,
                    motor_torque_nm: Some(0.3),
                    stiffness_motor_rad: None,
                },
                JointSample {
                    joint: 2,
                    seq: 8,
                    t_acq_ns: T,
                    motor_rad: -0.7,
                    deflection_rad: 0.1 + 0.2,
                    pivot_m: None,
                    torque_nm: Some(1e-300),
                    motor_torque_nm: None,
                    stiffness_motor_rad: Some(2.0),
                },
            ],
        }
        .into(),
        SimTruth {
            joint: 1,
            seq: 3,
            t_acq_ns: T,
            deflection_rad: 0.01,
            torque_nm: 0.2,
            link_rad: 1.1,
            stiffness_nm_per_rad: 9.9,
        }
        .into(),
    ]
}

#[test]
fn every_kind_reads_back_from_json_to_the_same_wire_bytes() {
    let msgs = one_of_each();
    let kinds: std::collections::BTreeSet<u8> = msgs.iter().map(|m| m.kind() as u8).collect();
    assert_eq!(kinds.len(), Kind::ALL.len(), "one message of every kind");
    for m in msgs {
        let wire = encode_any(&m).unwrap();
        let json = to_json(&m);
        let back = from_json(m.kind(), &json).unwrap();
        assert_eq!(back, m, "{}", String::from_utf8_lossy(&json));
        assert_eq!(encode_any(&back).unwrap(), wire);
        assert_eq!(decode_any(&wire).unwrap(), m);
    }
}

#[test]
fn each_schema_names_every_field_of_its_json_and_its_kind() {
    for m in one_of_each() {
        let kind = m.kind();
        assert_eq!(kind_of_schema(&schema_name(kind)), Some(kind));
        let schema: serde_json::Value = serde_json::from_str(&json_schema(kind)).unwrap();
        assert_eq!(schema["type"], "object", "{}", kind.name());
        assert!(
            schema.get("$defs").is_none() && schema.get("definitions").is_none(),
            "{}: the schema stands alone (no references)",
            kind.name()
        );
        let json: serde_json::Value = serde_json::from_slice(&to_json(&m)).unwrap();
        let props = schema["properties"].as_object().unwrap();
        for field in json.as_object().unwrap().keys() {
            assert!(
                props.contains_key(field),
                "{}: {field} not in the schema",
                kind.name()
            );
        }
        assert_eq!(
            props.len(),
            json.as_object().unwrap().len(),
            "{}",
            kind.name()
        );
    }
    assert_eq!(kind_of_schema("rig.Nothing"), None);
    assert_eq!(kind_of_schema("JointSample"), None);
}

#[test]
fn json_that_is_not_a_valid_message_is_an_error_naming_it() {
    let e = from_json(Kind::JointSample, b"{\"joint\": 1}").unwrap_err();
    assert!(e.to_string().contains("JointSample"), "{e}");
    // Valid JSON, an invalid message: the validation names the field.
    let mut v: serde_json::Value = serde_json::from_slice(&to_json(&one_of_each()[0])).unwrap();
    v["deflection_rad"] = serde_json::json!(7.0);
    let e = from_json(Kind::JointSample, v.to_string().as_bytes()).unwrap_err();
    assert!(e.to_string().contains("deflection_rad"), "{e}");
    assert!(from_json(Kind::SimTruth, b"not json").is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_numbers_survive_json_exactly(
        bits in prop::collection::vec(any::<u64>(), 4),
        seq in any::<u64>(),
        t in 1..u64::MAX,
    ) {
        // Any finite f64 of any magnitude and any last bit (scaled into each field's range).
        let f = |b: u64, range: f64| {
            let x = f64::from_bits(b);
            if x.is_finite() { (x / f64::MAX) * range } else { 0.5 * range }
        };
        let m: AnyMessage = JointSample {
            joint: (seq % 1000) as u16,
            seq,
            t_acq_ns: t,
            motor_rad: f(bits[0], 3.0),
            deflection_rad: f(bits[1], 3.0),
            pivot_m: Some(f(bits[2], 0.5)),
            torque_nm: Some(f(bits[3], 100.0)),
            motor_torque_nm: None,
            stiffness_motor_rad: None,
        }
        .into();
        let back = from_json(m.kind(), &to_json(&m)).unwrap();
        prop_assert_eq!(encode_any(&back).unwrap(), encode_any(&m).unwrap());
    }
}
