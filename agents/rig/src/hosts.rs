//! `rig estimator` and `rig allocator`: the two hosts as processes of their own, launched once
//! per machine. Their cores are `rig_estimator::core` and `rig_allocator::core`.

use std::path::PathBuf;
use std::time::Duration;

use rig_runtime::{NetArgs, NetOverrides, RunFor, tokio_runtime};

use crate::error::CliError;

#[derive(Debug, clap::Args)]
pub struct HostArgs {
    /// Rig config (TOML)
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    #[command(flatten)]
    net: NetArgs,
    #[command(flatten)]
    run_for: RunFor,
}

fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    Ok(tokio_runtime(Some(2))?)
}

fn parts(
    a: &HostArgs,
) -> Result<(rig_config::RigConfig, NetOverrides, Option<Duration>), CliError> {
    let cfg = rig_config::load(&a.config)?;
    Ok((cfg, a.net.overrides(), a.run_for.duration))
}

async fn ctrl_c() {
    let _ = tokio::signal::ctrl_c().await;
}

pub fn estimator(a: &HostArgs) -> Result<(), CliError> {
    let (cfg, net, duration) = parts(a)?;
    let cfg_names: Vec<String> = cfg.joints.iter().map(|j| j.name.clone()).collect();
    let r = runtime()?.block_on(rig_estimator::edge::run(
        rig_estimator::edge::EstimatorOptions { cfg, net, duration },
        ctrl_c(),
    ))?;
    let c = r.core;
    eprintln!(
        "rig estimator: {} samples, {} joint estimates, {} end-effector estimates ({} withheld), {} malformed; refused: {} off the clock bound, {} replayed, {} off the pivot travel, {} on another joint's key",
        c.samples,
        c.joint_estimates,
        c.ee_estimates,
        c.ee_withheld,
        r.malformed,
        c.refused_clock,
        c.refused_replay,
        c.refused_range,
        c.refused_key
    );
    // Each board's clock against this host's (one way: the smallest transit included).
    let clocks: Vec<String> = r
        .clock_offsets_ns
        .iter()
        .zip(&cfg_names)
        .filter_map(|(o, n)| o.map(|o| format!("{n} {:+.3} ms", o as f64 * 1e-6)))
        .collect();
    if !clocks.is_empty() {
        eprintln!(
            "rig estimator: board clocks against this host: {}",
            clocks.join(", ")
        );
    }
    Ok(())
}

pub fn allocator(a: &HostArgs) -> Result<(), CliError> {
    let (cfg, net, duration) = parts(a)?;
    let r = runtime()?.block_on(rig_allocator::edge::run(
        rig_allocator::edge::AllocatorOptions { cfg, net, duration },
        ctrl_c(),
    ))?;
    eprintln!(
        "rig allocator: {} requests, {} goals, {} commands ({} to no subscriber), {} malformed, {} goals refused for their age, {} unstamped",
        r.requests, r.goals, r.commands, r.unmatched, r.malformed, r.stale_goals, r.unstamped_goals
    );
    Ok(())
}
