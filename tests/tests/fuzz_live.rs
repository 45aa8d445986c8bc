//! A hostile peer against the running rig: 10⁵ payloads that must not be believed — random
//! bytes, truncated and oversized messages, a wrong version, NaN fields, out-of-range values,
//! samples on another joint's key, stamps an hour ahead, replays — sent to every key a role
//! listens on, while the honest joints go on. Asserted: no process exits or panics, the
//! end-effector force stays within its usual error of the simulated truth while the flood
//! runs, and every payload is counted by the role it reached, under the heading it belongs
//! to (malformed, or refused and why), exactly.
//!
//! Bounded in count (10⁵) and time (the flood must end within 120 s; it takes a few seconds).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::{Proc, alive, config, free_port, rt, s, serial, spawn_logged, wait_alive};

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rig_protocol::*;
use rig_runtime::now_ns;
use rig_runtime::zenoh::qos::CongestionControl;

const PAYLOADS: usize = 100_000;
const JOINTS: [&str; 4] = ["j1", "j2", "j3", "j4"];

/// A tiny deterministic generator (xorshift64*): the flood is the same on every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// `bytes` with the little-endian f64 `marker` replaced by NaN (a field a sender filled
/// with NaN: `encode` itself refuses it, a hostile peer does not ask `encode`).
fn with_nan(mut bytes: Vec<u8>, marker: f64) -> Vec<u8> {
    let m = marker.to_le_bytes();
    let at = bytes
        .windows(8)
        .position(|w| w == m)
        .expect("the marker is in the message");
    bytes[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    bytes
}

fn wrong_version(mut bytes: Vec<u8>) -> Vec<u8> {
    bytes[2] = 2;
    bytes
}

/// What the flood sent, by the role it reaches and the heading it must be counted under.
#[derive(Debug, Default)]
struct Sent {
    /// To the estimator (sample keys): undecodable.
    samples_malformed: u64,
    /// Decodable samples it must refuse: stamped an hour ahead, a pivot off its travel,
    /// another joint's index on this joint's key, a replayed sequence number and stamp.
    samples_refused: u64,
    /// To the joints (command keys): undecodable; decodable but refused by the guard.
    commands_malformed: u64,
    commands_refused: u64,
    /// To the allocator (goal key and the end-effector estimates it follows): undecodable.
    allocator_malformed: u64,
}

fn sample(joint: u16, seq: u64, t: u64, deflection: f64, pivot: f64) -> JointSample {
    JointSample {
        joint,
        seq,
        t_acq_ns: t,
        motor_rad: 0.1,
        deflection_rad: deflection,
        pivot_m: Some(pivot),
        torque_nm: None,
        motor_torque_nm: None,
        stiffness_motor_rad: None,
    }
}

fn command(joint: u16, t: u64, pivot: f64, marker: f64) -> JointCommand {
    JointCommand {
        joint,
        seq: 1,
        t_ns: t,
        motor_goal_rad: Some(marker),
        pivot_goal_m: Some(pivot),
        stiffness_motor_goal_rad: None,
        torque_enable: true,
    }
}

/// Payload `i` of the flood and the key index it goes to: 0–3 a joint's sample key, 4–7 a
/// joint's command key, 8 the stiffness goal, 9 the end-effector estimate. `launched_ns`: when
/// the joints were launched (before any sample of theirs).
fn payload(i: usize, rng: &mut Rng, sent: &mut Sent, launched_ns: u64) -> (usize, Vec<u8>) {
    const MARK: f64 = 0.123_456_789;
    let kind = (i / 10) % 8;
    let now = now_ns();
    let hour = 3_600_000_000_000;
    match i % 10 {
        j @ 0..=3 => {
            let joint = j as u16;
            let valid = encode(&sample(joint, 7, now, MARK, 0.009)).unwrap();
            let (bytes, refused) = match kind {
                0 => (rng.bytes(i % 120), false),
                1 => (valid[..(i % valid.len())].to_vec(), false),
                2 => (rng.bytes(8192), false),
                3 => (wrong_version(valid), false),
                4 => (with_nan(valid, MARK), false),
                5 => {
                    let other = (joint + 1) % 4;
                    (encode(&sample(other, 7, now, 0.0, 0.009)).unwrap(), true)
                }
                6 => (
                    encode(&sample(joint, 7, now + hour, 0.0, 0.009)).unwrap(),
                    true,
                ),
                _ if (i / 80).is_multiple_of(2) => {
                    (encode(&sample(joint, 7, now, 0.0, 0.5)).unwrap(), true)
                }
                // Sequence 1, stamped when the joints were launched: older than every sample
                // the estimator has accepted, so it is a replay however long the joint's own
                // samples were held up (one stamped 50 ms ago passed as a restart behind a
                // joint stalled longer than that on a loaded machine). Within the test's clock
                // bound (`config_for_replays`) it is refused as a replay.
                _ => (
                    encode(&sample(joint, 1, launched_ns, 0.0, 0.009)).unwrap(),
                    true,
                ),
            };
            if refused {
                sent.samples_refused += 1;
            } else {
                sent.samples_malformed += 1;
            }
            (j, bytes)
        }
        j @ 4..=7 => {
            let joint = (j - 4) as u16;
            let valid = encode(&command(joint, now, 0.009, MARK)).unwrap();
            let (bytes, refused) = match kind % 6 {
                0 => (rng.bytes(i % 90), false),
                1 => (valid[..(i % valid.len())].to_vec(), false),
                2 => (wrong_version(valid), false),
                3 => (with_nan(valid, MARK), false),
                4 => (
                    encode(&command(joint, now + hour, 0.009, 0.0)).unwrap(),
                    true,
                ),
                _ => (encode(&command(joint, now, 0.5, 0.0)).unwrap(), true),
            };
            if refused {
                sent.commands_refused += 1;
            } else {
                sent.commands_malformed += 1;
            }
            (j, bytes)
        }
        8 => {
            let valid = encode(&AllocationRequest {
                id: i as u64,
                x_m: MARK,
                y_m: 0.2,
                target: AllocationTarget::Percent(50.0),
            })
            .unwrap();
            sent.allocator_malformed += 1;
            let bytes = match kind % 4 {
                0 => rng.bytes(i % 60),
                1 => valid[..(i % valid.len())].to_vec(),
                2 => wrong_version(valid),
                _ => with_nan(valid, MARK),
            };
            (8, bytes)
        }
        _ => {
            let valid = encode(&EeEstimate {
                seq: 1,
                t_ns: now,
                stale_mask: 0,
                x_m: MARK,
                y_m: 0.2,
                phi_rad: 0.0,
                force_n: Some((40.0, 40.0)),
                stiffness_n_per_m: None,
            })
            .unwrap();
            sent.allocator_malformed += 1;
            let bytes = match kind % 4 {
                0 => rng.bytes(i % 100),
                1 => valid[..(i % valid.len())].to_vec(),
                2 => wrong_version(valid),
                _ => with_nan(valid, MARK),
            };
            (9, bytes)
        }
    }
}

/// The example config with a clock bound of 60 s (its largest) written into `dir`: the flood's
/// replays, stamped at the joints' launch, stay within it for the whole test and are refused as
/// replays, not as off the clock; the stamps an hour ahead are still beyond it.
fn config_for_replays(dir: &std::path::Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(config()).unwrap();
    let bound = "max_offset_ms = 100.0";
    assert!(
        text.contains(bound),
        "the example config's clock bound moved"
    );
    let path = dir.join("parallel.toml");
    std::fs::write(&path, text.replace(bound, "max_offset_ms = 60000.0")).unwrap();
    path
}

#[test]
fn a_flood_of_payloads_that_must_not_be_believed_is_counted_and_the_rig_keeps_estimating() {
    let _one_at_a_time = serial();
    let hub = format!("tcp/127.0.0.1:{}", free_port());
    let dir = common::test_dir("fuzz");
    let cfg = config_for_replays(&dir).to_string_lossy().into_owned();
    let est_log = dir.join("estimator.log");
    let alloc_log = dir.join("allocator.log");
    let mut procs: Vec<(String, Proc)> = vec![(
        "estimator".into(),
        spawn_logged(
            "rig",
            &s(&["estimator", "--config", &cfg, "--listen", &hub]),
            &est_log,
        ),
    )];
    wait_alive(&hub, &[alive("estimator", "0")]);
    procs.push((
        "allocator".into(),
        spawn_logged(
            "rig",
            &s(&["allocator", "--config", &cfg, "--connect", &hub]),
            &alloc_log,
        ),
    ));
    let start = now_ns();
    for j in JOINTS {
        let args = s(&[
            "--config",
            &cfg,
            "--joint",
            j,
            "--start-ns",
            &start.to_string(),
            "--connect",
            &hub,
        ]);
        procs.push((
            j.into(),
            spawn_logged("rig-joint", &args, &dir.join(format!("{j}.log"))),
        ));
    }
    let mut everyone = vec![alive("allocator", "0")];
    everyone.extend(JOINTS.iter().map(|j| alive("joint", j)));
    wait_alive(&hub, &everyone);

    let mut sent = Sent::default();
    let (flood_from, flood_to) = rt().block_on(async {
        let z = common::session(&[], &[&hub]).await;
        let (truths, _truths) = common::collect_truths(&z).await;
        let ees = Arc::new(Mutex::new(Vec::<(u64, f64, f64)>::new()));
        let el = ees.clone();
        let _ees = z
            .declare_subscriber("rig/parallel/estimate/ee")
            .callback(move |e| {
                if let Ok(m) = decode::<EeEstimate>(&e.payload().to_bytes())
                    && let Some((fx, fy)) = m.force_n
                {
                    el.lock().unwrap().push((m.t_ns, fx, fy));
                }
            })
            .await
            .unwrap();
        let mut keys: Vec<String> = JOINTS
            .iter()
            .map(|j| format!("rig/parallel/joint/{j}/sample"))
            .collect();
        keys.extend(JOINTS.iter().map(|j| format!("rig/parallel/joint/{j}/command")));
        keys.push("rig/parallel/stiffness/goal".into());
        keys.push("rig/parallel/estimate/ee".into());
        let mut pubs = Vec::new();
        for k in keys {
            let p = z
                .declare_publisher(k)
                .congestion_control(CongestionControl::Block)
                .await
                .unwrap();
            // Every payload must reach a role to be counted: wait for a route.
            let until = Instant::now() + Duration::from_secs(10);
            while !p.matching_status().await.unwrap().matching() {
                assert!(Instant::now() < until, "no route to {}", p.key_expr());
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            pubs.push(p);
        }
        // The estimate/ee publisher matches this test's own subscriber at once: give the
        // allocator's subscription time to be known too, and the rig 3 s to settle.
        tokio::time::sleep(Duration::from_secs(3)).await;
        let mut rng = Rng(0x5EED_F00D_CAFE_0001);
        let flood_from = now_ns();
        let t0 = Instant::now();
        for i in 0..PAYLOADS {
            let (k, bytes) = payload(i, &mut rng, &mut sent, start);
            pubs[k].put(bytes).await.unwrap();
            assert!(t0.elapsed() < Duration::from_secs(120), "the flood is bounded in time");
        }
        let flood_to = now_ns();
        // Two more seconds of honest running after the flood.
        tokio::time::sleep(Duration::from_secs(2)).await;
        let truth = truths.lock().unwrap().clone();
        let ee = ees.lock().unwrap().clone();
        // The force while the flood ran (and its last 2 s), against the simulated truth.
        let during: Vec<(u64, f64, f64)> =
            ee.into_iter().filter(|e| e.0 >= flood_from).collect();
        let (rmse, peak, n) = common::force_error(start, &truth, &during);
        let flood_ms = (flood_to - flood_from) / 1_000_000;
        eprintln!(
            "{PAYLOADS} payloads in {flood_ms} ms; during and 2 s after: force RMSE {rmse:.4} N against a {peak:.2} N peak over {n} estimates"
        );
        // 1 kHz estimates: at least 80 % of the ticks while flooded.
        let expected = (flood_ms + 2000) as f64;
        assert!(
            n as f64 > 0.8 * expected,
            "{n} estimates matched a complete truth over {expected} ms"
        );
        assert!(peak > 0.5, "the hand must load the robot: peak {peak} N");
        assert!(
            rmse < 0.05 * peak,
            "force RMSE {rmse} N against a {peak} N peak while flooded"
        );
        (flood_from, flood_to)
    });
    assert!(flood_to > flood_from);

    // Nobody exited; then each ends cleanly on Ctrl-C and reports its counts.
    for (what, p) in &mut procs {
        assert!(
            p.0.try_wait().unwrap().is_none(),
            "{what} exited during the flood"
        );
    }
    for (_, p) in &procs {
        common::interrupt(p);
    }
    for (what, p) in &mut procs {
        let status = p.0.wait().unwrap();
        assert!(status.success(), "{what} ended with {status}");
    }
    eprintln!("sent: {sent:?}");
    let est_malformed = common::report_count(&est_log, "rig estimator:", "malformed");
    let refused: u64 = [
        "off the clock bound",
        "replayed",
        "off the pivot travel",
        "on another joint's key",
    ]
    .iter()
    .map(|l| common::report_count(&est_log, "rig estimator:", l))
    .sum();
    assert_eq!(
        est_malformed, sent.samples_malformed,
        "estimator: malformed"
    );
    assert_eq!(refused, sent.samples_refused, "estimator: refused");
    let (mut malformed, mut rejected, mut accepted) = (0, 0, 0);
    for j in JOINTS {
        let log = dir.join(format!("{j}.log"));
        let report = format!("rig-joint {j}:");
        malformed += common::report_count(&log, &report, "malformed");
        rejected += common::report_count(&log, &report, "rejected");
        accepted += common::report_count(&log, &report, "commands accepted");
    }
    assert_eq!(malformed, sent.commands_malformed, "joints: malformed");
    assert_eq!(rejected, sent.commands_refused, "joints: rejected");
    assert_eq!(accepted, 0, "no command of the flood was obeyed");
    assert_eq!(
        common::report_count(&alloc_log, "rig allocator:", "malformed"),
        sent.allocator_malformed,
        "allocator: malformed"
    );
    assert_eq!(
        common::report_count(&alloc_log, "rig allocator:", "commands"),
        0,
        "the allocator, given no goal, commanded nothing"
    );
    std::fs::remove_dir_all(&dir).ok();
}
