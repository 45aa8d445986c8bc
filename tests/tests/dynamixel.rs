//! The hardware path without hardware: virtual servos behind a pseudo-terminal, found by the
//! built `rig scan`.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::bin;

use std::process::Command;

use rig_dynamixel::models::{AX_12A, XH540_W150};
use rig_dynamixel::virtual_bus::{VirtualBus, VirtualServo};

#[test]
fn rig_scan_lists_the_virtual_servos_of_each_protocol_as_json() {
    let (_bus, path) = VirtualBus::start_with_path(vec![
        VirtualServo::new(XH540_W150, 1),
        VirtualServo::new(XH540_W150, 2),
        VirtualServo::new(AX_12A, 11),
    ])
    .unwrap();
    let scan = |protocol: &str| {
        let o = Command::new(bin("rig"))
            .args([
                "scan",
                "--baud",
                "1000000",
                "--json",
                "--protocol",
                protocol,
                "--port",
            ])
            .arg(&path)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    assert_eq!(
        scan("2"),
        serde_json::json!([
            {"id": 1, "model_number": 1110, "model": "XH540-W150"},
            {"id": 2, "model_number": 1110, "model": "XH540-W150"}
        ])
    );
    assert_eq!(
        scan("1"),
        serde_json::json!([{"id": 11, "model_number": 12, "model": "AX-12A"}])
    );
    // A port that is not there: a clear error naming it, exit status 1.
    let o = Command::new(bin("rig"))
        .args(["scan", "--port", "/dev/no-such-bus"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("/dev/no-such-bus: cannot open"), "{err}");
}
