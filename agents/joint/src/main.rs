//! `rig-joint`: the joint-board agent.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, ValueEnum};
use rig_joint::agent::{AgentOptions, BackendKind, run};
use rig_joint::hardware::PortOverrides;
use rig_runtime::{NetArgs, RunFor, now_ns, tokio_runtime};

/// Where readings come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Backend {
    /// The simulated joints
    Sim,
    /// Dynamixel servos on the config's bus and the deflection encoders on its serial bridge
    Dynamixel,
}

/// The joint-board agent of the VSA rig: publishes one joint's samples over Zenoh and accepts
/// commands only within the joint's limits.
///
/// With `--backend dynamixel` it checks each servo's model, holds every servo where it is and
/// turns torque on; torque goes off on exit (Ctrl-C, SIGTERM, --duration), on the watchdog and
/// on a bus fault (which also ends the agent with a `fault` status naming the servo and bus).
/// Without hardware: `rig virtual-board --config F` prints a bus and a bridge to pass here.
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
    /// Where readings come from
    #[arg(long, value_enum, default_value_t = Backend::Sim)]
    backend: Backend,
    /// Servo bus port instead of the config's `servo.bus` (dynamixel backend), e.g. /dev/ttyUSB0
    #[arg(long, value_name = "PATH")]
    bus: Option<PathBuf>,
    /// Encoder bridge port instead of the config's `encoder.device` (dynamixel backend)
    #[arg(long, value_name = "PATH")]
    bridge: Option<PathBuf>,
    #[command(flatten)]
    net: NetArgs,
    /// Start of the simulated world [ns since the UNIX epoch]; default: now
    #[arg(long)]
    start_ns: Option<u64>,
    /// Seed of the simulated sensors
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    run_for: RunFor,
    /// Undeclared effects of the simulated joint, for testing what the estimator notices: a
    /// TOML file of effect fields (agents/sim/SCENARIOS.md), e.g. `torque_offset_nm = 0.05`
    #[arg(long, value_name = "FILE")]
    sim_effects: Option<std::path::PathBuf>,
}

/// The simulated board's options; a build without the `sim` feature refuses them by name.
fn sim_backend(a: &Args) -> Result<BackendKind, String> {
    #[cfg(feature = "sim")]
    {
        let effects = match a
            .sim_effects
            .as_deref()
            .map(rig_sim::effects::Effects::load)
        {
            None => rig_sim::effects::Effects::default(),
            Some(Ok(e)) => e,
            Some(Err(e)) => return Err(format!("--sim-effects {e}")),
        };
        Ok(BackendKind::Sim {
            seed: a.seed,
            effects,
        })
    }
    #[cfg(not(feature = "sim"))]
    {
        let _ = a;
        Err("this rig-joint was built without the simulator (feature `sim`): use --backend dynamixel".into())
    }
}

fn main() -> ExitCode {
    let a = Args::parse();
    if a.backend == Backend::Sim && (a.bus.is_some() || a.bridge.is_some()) {
        eprintln!(
            "error: --bus and --bridge are ports of the dynamixel backend; add --backend dynamixel"
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
    let backend = match a.backend {
        Backend::Sim => match sim_backend(&a) {
            Ok(b) => b,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(1);
            }
        },
        Backend::Dynamixel if a.sim_effects.is_some() => {
            eprintln!(
                "error: --sim-effects are effects of the simulated joints; drop it with --backend dynamixel"
            );
            return ExitCode::from(2);
        }
        Backend::Dynamixel => BackendKind::Dynamixel(PortOverrides {
            bus: a.bus.clone(),
            bridge: a.bridge.clone(),
        }),
    };
    let opts = AgentOptions {
        backend,
        cfg,
        joints: a.joint.clone(),
        net: a.net.overrides(),
        start_ns: a.start_ns.unwrap_or_else(now_ns),
        duration: a.run_for.duration,
    };
    let rt = match tokio_runtime(Some(2)) {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::from(1);
        }
    };
    // Ctrl-C or SIGTERM (systemd, kill) end the agent cleanly: torque off, statuses sent.
    let result = rt.block_on(run(opts, async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
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
