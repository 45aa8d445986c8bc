//! `rig estimator` and `rig allocator`: the two hosts as processes of their own, launched once
//! per machine. Their cores are `rig_estimator::core` and `rig_allocator::core`.

use std::path::PathBuf;
use std::time::Duration;

use rig_runtime::NetOverrides;

use crate::error::CliError;

#[derive(Debug, clap::Args)]
pub struct HostArgs {
    /// Rig config (TOML)
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Zenoh endpoints to listen on (overrides the config)
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Zenoh endpoints to connect to (overrides the config)
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Stop after this many seconds (default: until Ctrl-C)
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
}

fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?)
}

fn parts(
    a: &HostArgs,
) -> Result<(rig_config::RigConfig, NetOverrides, Option<Duration>), CliError> {
    let cfg = rig_config::load(&a.config)?;
    let net = NetOverrides {
        listen: a.listen.clone(),
        connect: a.connect.clone(),
    };
    Ok((
        cfg,
        net,
        a.duration
            .filter(|d| d.is_finite() && *d > 0.0)
            .map(Duration::from_secs_f64),
    ))
}

async fn ctrl_c() {
    let _ = tokio::signal::ctrl_c().await;
}

pub fn estimator(a: &HostArgs) -> Result<(), CliError> {
    let (cfg, net, duration) = parts(a)?;
    let r = runtime()?
        .block_on(rig_estimator::edge::run(
            rig_estimator::edge::EstimatorOptions { cfg, net, duration },
            ctrl_c(),
        ))
        .map_err(|e| CliError::Unsupported(e.to_string()))?;
    let c = r.core;
    eprintln!(
        "rig estimator: {} samples, {} joint estimates, {} end-effector estimates ({} withheld), {} malformed",
        c.samples, c.joint_estimates, c.ee_estimates, c.ee_withheld, r.malformed
    );
    Ok(())
}

pub fn allocator(a: &HostArgs) -> Result<(), CliError> {
    let (cfg, net, duration) = parts(a)?;
    let r = runtime()?
        .block_on(rig_allocator::edge::run(
            rig_allocator::edge::AllocatorOptions { cfg, net, duration },
            ctrl_c(),
        ))
        .map_err(|e| CliError::Unsupported(e.to_string()))?;
    eprintln!(
        "rig allocator: {} requests, {} goals, {} commands, {} malformed",
        r.requests, r.goals, r.commands, r.malformed
    );
    Ok(())
}
