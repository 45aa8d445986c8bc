//! `rig pivot`: hold one lever joint's pivot at a position, as an operator does on the bench
//! while calibrating (paper B holds the pivot at a few positions and loads the link by hand).
//!
//! It publishes the joint's command (pivot goal, torque on) ten times a second — the joint's
//! watchdog wants a heartbeat — until Ctrl-C or `--duration`; then it stops, and the joint's
//! watchdog makes it safe.

use std::path::PathBuf;
use std::time::Duration;

use rig_config::JointKind;
use rig_protocol::{JointCommand, Keys, encode};
use rig_runtime::{NetArgs, RunFor, now_ns, open, tokio_runtime, zenoh_err};

use crate::error::CliError;

/// Arguments of `rig pivot`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rig config (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The lever joint whose pivot to hold, by name
    #[arg(long, value_name = "NAME")]
    joint: String,
    /// Where to hold it [mm from the pivot travel's zero], within the joint's travel
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    mm: f64,
    #[command(flatten)]
    run_for: RunFor,
    #[command(flatten)]
    net: NetArgs,
}

/// How often the goal is sent again (the joint's watchdog wants a heartbeat).
const HEARTBEAT: Duration = Duration::from_millis(100);

pub fn run(a: &Args) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let joint = &cfg.joints[rig_joint::board::joint_index(&cfg, &a.joint)
        .map_err(|e| CliError::Invalid(format!("--joint: {e}")))?];
    let JointKind::Lever { vsa, .. } = &joint.kind else {
        return Err(CliError::Invalid(format!(
            "--joint {}: an AWAS joint has no pivot (its stiffness motor is torque-driven)",
            a.joint
        )));
    };
    let goal_m = a.mm * 1e-3;
    if !(goal_m.is_finite() && (vsa.d_min..=vsa.d_max).contains(&goal_m)) {
        return Err(CliError::Invalid(format!(
            "--mm {}: outside joint {}'s pivot travel {:.2}..{:.2} mm",
            a.mm,
            a.joint,
            vsa.d_min * 1e3,
            vsa.d_max * 1e3
        )));
    }
    let rt = tokio_runtime(Some(1))?;
    rt.block_on(async {
        let keys = Keys::new(&cfg.name)?;
        let session = open(&cfg, &a.net.overrides(), &rig_config::Identity::Operator).await?;
        let publisher = session
            .declare_publisher(keys.joint_command(&joint.name)?)
            .await
            .map_err(zenoh_err)?;
        eprintln!(
            "rig pivot: holding joint {}'s pivot at {:.2} mm (Ctrl-C to stop; then the joint's watchdog makes it safe)",
            joint.name, a.mm
        );
        let deadline = a
            .run_for
            .duration
            .map(|d| tokio::time::Instant::now() + d);
        let mut beat = tokio::time::interval(HEARTBEAT);
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        let mut seq = 0u64;
        loop {
            let far = tokio::time::Instant::now() + Duration::from_secs(3600);
            tokio::select! {
                _ = &mut ctrl_c => break,
                _ = tokio::time::sleep_until(deadline.unwrap_or(far)) => break,
                _ = beat.tick() => {
                    seq += 1;
                    let cmd = JointCommand {
                        joint: joint.index as u16,
                        seq,
                        t_ns: now_ns(),
                        motor_goal_rad: None,
                        pivot_goal_m: Some(goal_m),
                        stiffness_motor_goal_rad: None,
                        torque_enable: true,
                    };
                    let bytes = encode(&cmd).map_err(|e| CliError::Invalid(e.to_string()))?;
                    publisher.put(bytes).await.map_err(zenoh_err)?;
                }
            }
        }
        eprintln!("rig pivot: sent {seq} commands");
        Ok::<_, CliError>(())
    })
}
