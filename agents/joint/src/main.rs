//! `rig-joint`: the joint-board agent.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use rig_joint::agent::{AgentOptions, run};
use rig_runtime::{NetOverrides, now_ns};

/// The joint-board agent of the VSA rig: publishes one joint's samples over Zenoh and accepts
/// commands only within the joint's limits.
#[derive(Debug, Parser)]
#[command(name = "rig-joint", version)]
struct Args {
    /// Rig config (TOML)
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The joint's name in the config, e.g. j1. A board that drives several joints serves
    /// them all from one agent: repeat the flag or list them, e.g. --joint j1,j2
    #[arg(long, required = true, value_delimiter = ',', value_name = "NAME")]
    joint: Vec<String>,
    /// Where readings come from: sim (dynamixel arrives with the hardware issue)
    #[arg(long, default_value = "sim")]
    backend: String,
    /// Zenoh endpoints to listen on (overrides the config), e.g. tcp/127.0.0.1:7447
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Zenoh endpoints to connect to (overrides the config)
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Start of the simulated world [ns since the UNIX epoch]; default: now
    #[arg(long)]
    start_ns: Option<u64>,
    /// Seed of the simulated sensors
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Stop after this many seconds (default: until Ctrl-C)
    #[arg(long)]
    duration: Option<f64>,
    /// Undeclared effects of the simulated joint, for testing what the estimator notices: a
    /// TOML file of effect fields (agents/sim/SCENARIOS.md), e.g. `torque_offset_nm = 0.05`
    #[arg(long, value_name = "FILE")]
    sim_effects: Option<std::path::PathBuf>,
}

fn main() -> ExitCode {
    let a = Args::parse();
    if a.backend != "sim" {
        eprintln!(
            "error: backend {:?} is not available yet; use --backend sim",
            a.backend
        );
        return ExitCode::from(2);
    }
    let cfg = match rig_config::load(&a.config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(1);
        }
    };
    let effects = match a
        .sim_effects
        .as_deref()
        .map(rig_sim::effects::Effects::load)
    {
        None => rig_sim::effects::Effects::default(),
        Some(Ok(e)) => e,
        Some(Err(e)) => {
            eprintln!("error: --sim-effects {e}");
            return ExitCode::from(1);
        }
    };
    let opts = AgentOptions {
        effects,
        cfg,
        joints: a.joint.clone(),
        net: NetOverrides {
            listen: a.listen,
            connect: a.connect,
        },
        start_ns: a.start_ns.unwrap_or_else(now_ns),
        seed: a.seed,
        duration: a
            .duration
            .filter(|d| d.is_finite() && *d > 0.0)
            .map(Duration::from_secs_f64),
    };
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::from(1);
        }
    };
    let result = rt.block_on(run(opts, async {
        let _ = tokio::signal::ctrl_c().await;
    }));
    match result {
        Ok(reports) => {
            for (name, r) in a.joint.iter().zip(reports) {
                eprintln!(
                    "rig-joint {name}: {} samples, {} skipped ticks, {} commands accepted, {} rejected, {} malformed",
                    r.samples,
                    r.skipped_ticks,
                    r.commands_accepted,
                    r.commands_rejected,
                    r.malformed
                );
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}
