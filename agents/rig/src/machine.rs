//! `rig launch`: one machine's share of the plan (`[[machine]]` in the rig config).
//!
//! - `--plan` prints who runs what and links where, and the command each machine runs.
//! - `--machine NAME` starts that machine's **hub** — a Zenoh router in this process that
//!   listens and connects as the plan says, plus a loopback endpoint for the machine's roles —
//!   and then each of its roles as a process of its own, exactly the command a lab would type:
//!   `rig record` first (so it holds every message), `rig estimator`, `rig allocator`,
//!   `rig-joint` for the machine's joints (one agent serving them all, as one board does) and
//!   `rig viz`, each a Zenoh **client** of the hub. Routers forward between their clients and
//!   to the other machines' hubs, so a chain of links joins every role to every other.
//!
//! It waits for the roles: until `--duration` (passed to each) or Ctrl-C (passed on to each as
//! an interrupt). When a role fails, the others are interrupted, and the error names every
//! role that failed with its exit status.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Duration;

use rig_config::{Identity, Machine, RigConfig, Role, ZenohMode};
use rig_runtime::{NetOverrides, RunFor, session_config, tokio_runtime, zenoh};

use crate::error::CliError;
use crate::up::free_loopback_endpoint;
use crate::validate::or_nothing;

/// Where a machine's joints read from (`rig-joint --backend`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    /// Simulated joints (no hardware).
    Sim,
    /// The joint board's Dynamixel servos and encoder bridge (the config's ports).
    Dynamixel,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rig config (TOML) with a plan: `[[machine]]` tables (docs/DEPLOY.md)
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Print the plan: each machine's roles, what it listens on and connects to
    #[arg(long, conflicts_with = "machine")]
    plan: bool,
    /// Start this machine's hub and roles, by its `[[machine]]` name
    #[arg(long, value_name = "NAME", required_unless_present = "plan")]
    machine: Option<String>,
    /// Where this machine's joints read from
    #[arg(long, value_enum, default_value_t = Backend::Sim)]
    backend: Backend,
    /// Start of the simulated world [ns since the UNIX epoch], the same on every machine so
    /// that their simulated joints share one world; default: each joint agent's start
    #[arg(long, value_name = "NS")]
    start_ns: Option<u64>,
    /// The recorder's output file (a machine that runs `recorder`); default
    /// `<rig>-<machine>.mcap` in the working directory
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    #[command(flatten)]
    run_for: RunFor,
}

pub fn run(a: &Args) -> Result<(), CliError> {
    let cfg = rig_config::load(&a.config)?;
    if cfg.machines.is_empty() {
        return Err(CliError::Invalid(format!(
            "{} has no plan: add [[machine]] tables saying which machine runs which roles (docs/DEPLOY.md), or run everything here with `rig up --config {}`",
            a.config.display(),
            a.config.display()
        )));
    }
    let Some(name) = &a.machine else {
        print!("{}", crate::validate::plan(&cfg));
        for m in &cfg.machines {
            println!(
                "on {}: rig launch --config {} --machine {}",
                m.name,
                a.config.display(),
                m.name
            );
        }
        return Ok(());
    };
    let Some(machine) = cfg.machine(name) else {
        let names: Vec<&str> = cfg.machines.iter().map(|m| m.name.as_str()).collect();
        return Err(CliError::Invalid(format!(
            "--machine {name}: the plan of {} has no such machine; it has {}",
            a.config.display(),
            names.join(", ")
        )));
    };
    tokio_runtime(Some(1))?.block_on(launch(&cfg, machine, a))
}

/// The hub's Zenoh config: a router listening on the plan's endpoints and `local`, connecting
/// to the plan's; with `[security]` it presents the machine's certificate and checks every
/// message against its sender's, its own roles' included.
fn hub_config(cfg: &RigConfig, m: &Machine, local: &str) -> Result<zenoh::Config, CliError> {
    let net = NetOverrides {
        mode: Some(ZenohMode::Router),
        listen: m
            .listen
            .iter()
            .cloned()
            .chain([local.to_string()])
            .collect(),
        connect: m.connect.clone(),
        identity: None,
    };
    Ok(session_config(
        cfg,
        &net,
        &Identity::Machine(m.name.clone()),
    )?)
}

/// The command line of one role, joined to the hub at `local` as a client.
fn role_command(
    cfg: &RigConfig,
    m: &Machine,
    role: &Role,
    local: &str,
    a: &Args,
) -> Result<Option<(String, Command)>, CliError> {
    let mut c = Command::new(std::env::current_exe()?);
    match role {
        // A machine's joints are served by one agent (below), not one per role.
        Role::Joint(_) => return Ok(None),
        Role::Estimator => c.arg("estimator"),
        Role::Allocator => c.arg("allocator"),
        Role::Recorder => {
            let out = a
                .out
                .clone()
                .unwrap_or_else(|| PathBuf::from(format!("{}-{}.mcap", cfg.name, m.name)));
            c.arg("record").arg("--out").arg(out)
        }
        Role::Viz => c.args(["viz", "--viz"]),
    };
    c.arg("--config").arg(&a.config);
    joined(&mut c, cfg, m, local, a);
    Ok(Some((role.name().to_string(), c)))
}

/// The machine's joint agent: `rig-joint` beside this executable, serving all its joints.
fn joint_command(
    cfg: &RigConfig,
    m: &Machine,
    local: &str,
    a: &Args,
) -> Result<Option<(String, Command)>, CliError> {
    let joints: Vec<&str> = m
        .roles
        .iter()
        .filter_map(|r| match r {
            Role::Joint(j) => Some(j.as_str()),
            _ => None,
        })
        .collect();
    if joints.is_empty() {
        return Ok(None);
    }
    let exe = std::env::current_exe()?;
    let bin = exe
        .parent()
        .unwrap_or(Path::new("."))
        .join(format!("rig-joint{}", std::env::consts::EXE_SUFFIX));
    if !bin.exists() {
        return Err(CliError::Invalid(format!(
            "machine {} runs joints {}, but there is no rig-joint beside {} (build it: cargo build --release -p rig-joint)",
            m.name,
            joints.join(", "),
            exe.display()
        )));
    }
    let mut c = Command::new(bin);
    c.arg("--config")
        .arg(&a.config)
        .arg("--joint")
        .arg(joints.join(","))
        .arg("--backend")
        .arg(match a.backend {
            Backend::Sim => "sim",
            Backend::Dynamixel => "dynamixel",
        });
    if let Some(ns) = a.start_ns {
        c.arg("--start-ns").arg(ns.to_string());
    }
    joined(&mut c, cfg, m, local, a);
    Ok(Some((format!("joints {}", joints.join(",")), c)))
}

/// A client of the hub at `local`, for the run's duration; under `[security]` it presents the
/// machine's certificate.
fn joined(c: &mut Command, cfg: &RigConfig, m: &Machine, local: &str, a: &Args) {
    c.args(["--mode", "client", "--connect", local]);
    if cfg.security.is_some() {
        c.arg("--identity")
            .arg(Identity::Machine(m.name.clone()).name());
    }
    if let Some(d) = a.run_for.duration {
        c.arg("--duration").arg(d.as_secs_f64().to_string());
    }
    c.stdin(Stdio::null());
}

/// Sends SIGINT to a role (what Ctrl-C in its terminal does), so it stops cleanly.
fn interrupt(child: &Child) {
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
}

async fn launch(cfg: &RigConfig, m: &Machine, a: &Args) -> Result<(), CliError> {
    let local = free_loopback_endpoint(cfg.security.is_some())?;
    let hub = zenoh::open(hub_config(cfg, m, &local)?)
        .await
        .map_err(|e| CliError::Rig(format!("machine {}: its hub did not open: {e}", m.name)))?;
    eprintln!(
        "rig launch: machine {} — hub listening on {} (roles on {local}), connecting to {}",
        m.name,
        or_nothing(&m.listen),
        or_nothing(&m.connect)
    );
    // The recorder first, the joints last: each hears those started after it from their start.
    let mut order: Vec<&Role> = m.roles.iter().collect();
    order.sort_by_key(|r| match r {
        Role::Recorder => 0,
        Role::Viz => 1,
        Role::Estimator => 2,
        Role::Allocator => 3,
        Role::Joint(_) => 4,
    });
    let mut commands = Vec::new();
    for r in order {
        if let Some(c) = role_command(cfg, m, r, &local, a)? {
            commands.push(c);
        }
    }
    if let Some(c) = joint_command(cfg, m, &local, a)? {
        commands.push(c);
    }
    let mut children: Vec<(String, Child)> = Vec::new();
    for (what, mut c) in commands {
        match c.spawn() {
            Ok(child) => children.push((what, child)),
            Err(e) => {
                for (_, ch) in &children {
                    interrupt(ch);
                }
                for (_, ch) in &mut children {
                    let _ = ch.wait();
                }
                return Err(CliError::Rig(format!(
                    "machine {}: {what} did not start: {e}",
                    m.name
                )));
            }
        }
        // Give a role a moment to join before the next one (the recorder and the estimator
        // then hear the joints' first samples).
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    let mut done: Vec<(String, ExitStatus)> = Vec::new();
    let mut interrupted = false;
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    while done.len() < children.len() {
        tokio::select! {
            _ = &mut ctrl_c, if !interrupted => {
                interrupted = true;
                for (_, ch) in &children {
                    interrupt(ch);
                }
            }
            _ = tokio::time::sleep(Duration::from_millis(100)) => {}
        }
        let mut failed_now = false;
        for (what, ch) in children.iter_mut() {
            if done.iter().any(|(w, _)| w == what) {
                continue;
            }
            if let Ok(Some(status)) = ch.try_wait() {
                failed_now |= !status.success();
                done.push((what.clone(), status));
            }
        }
        if failed_now && !interrupted {
            // One role failed: stop the others, as a lab would.
            interrupted = true;
            for (_, other) in &children {
                interrupt(other);
            }
        }
    }
    let _ = hub.close().await;
    let failed: Vec<String> = done
        .iter()
        .filter(|(_, s)| !s.success())
        .map(|(w, s)| format!("{w} ({s})"))
        .collect();
    if failed.is_empty() {
        eprintln!(
            "rig launch: machine {}: {} role process(es) ended cleanly",
            m.name,
            done.len()
        );
        Ok(())
    } else {
        Err(CliError::Rig(format!(
            "machine {}: {} failed; the other roles were stopped",
            m.name,
            failed.join(", ")
        )))
    }
}
