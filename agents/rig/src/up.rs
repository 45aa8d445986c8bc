//! `rig up`: the whole simulated rig on one machine — one joint agent per joint, the
//! estimator host, the allocator host — each with its own Zenoh session, peers on loopback
//! (no router), until Ctrl-C or `--duration`. Then a one-screen summary: samples, estimates,
//! and the end-effector force estimate scored against the simulated truth.
//!
//! The roles run as tasks of this process but talk only through Zenoh, exactly as the
//! separate `rig-joint`, `rig estimator` and `rig allocator` processes do.

use std::path::PathBuf;
use std::time::Duration;

use rig_config::RigConfig;
use rig_joint::agent::BackendKind;
use rig_protocol::{
    AllocationRequest, AllocationResult, AllocationTarget, EeEstimate, JointEstimate, SimTruth,
    decode, decode_samples, encode,
};
use rig_runtime::{NetArgs, RunFor, now_ns, tokio_runtime, zenoh_err};

use crate::up_watch::Watch;
use crate::viz::no_viewer_in_connect;
use tokio::sync::watch;

use crate::error::CliError;
use crate::launch::Hub;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rig config (default: the example parallel robot, rig-config/examples/parallel.toml)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Run this many seconds, then print the summary (default: until Ctrl-C)
    #[command(flatten)]
    run_for: RunFor,
    /// Zenoh endpoints: the rig's hub (its estimator) listens on the first `--listen` (default:
    /// a free loopback port) so outside clients can join; `--connect` also joins a router or
    /// another machine's rig
    #[command(flatten)]
    net: NetArgs,
    /// Decoupled stiffness goal for the allocator, percent of the range (robots only)
    #[arg(long, default_value_t = 25.0, value_name = "P", value_parser = crate::allocate::percent_of_range, allow_negative_numbers = true)]
    percent: f64,
    /// Seed of the simulated sensors
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Undeclared effects of the simulated joints (the config does not know them): a TOML
    /// file of effect fields (agents/sim/SCENARIOS.md), e.g. `torque_offset_nm = 0.05`. With a
    /// torque sensor (rig-config/examples/bench.toml) the estimator's residual monitor
    /// publishes a diagnosis
    #[arg(long, value_name = "FILE")]
    sim_effects: Option<std::path::PathBuf>,
    /// The joints that carry --sim-effects (default: every joint), e.g. `--sim-effects-on j1`
    #[arg(
        long,
        value_name = "JOINT",
        requires = "sim_effects",
        value_delimiter = ','
    )]
    sim_effects_on: Vec<String>,
    #[command(flatten)]
    viz: crate::viz::VizArgs,
}

/// A Zenoh endpoint on a loopback port free now (TLS when `secure`).
pub(crate) fn free_loopback_endpoint(secure: bool) -> Result<String, CliError> {
    let proto = if secure { "tls" } else { "tcp" };
    Ok(format!(
        "{proto}/127.0.0.1:{}",
        rig_runtime::free_loopback_port()?
    ))
}

/// How long `rig up` waits for a role's liveliness token.
const UP_WITHIN: Duration = Duration::from_secs(10);

pub fn run(args: &Args) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&args.config)?;
    no_viewer_in_connect(&args.net)?;
    tokio_runtime(Some(2))?.block_on(up(cfg, args))
}

async fn up(cfg: RigConfig, args: &Args) -> Result<(), CliError> {
    let effects = match &args.sim_effects {
        Some(p) => rig_sim::effects::Effects::load(p)
            .map_err(|e| CliError::Invalid(format!("--sim-effects {e}")))?,
        None => rig_sim::effects::Effects::default(),
    };
    for n in &args.sim_effects_on {
        rig_joint::board::joint_index(&cfg, n)
            .map_err(|e| CliError::Invalid(format!("--sim-effects-on: {e}")))?;
    }
    let viz = match args.viz.sink(&cfg, false)? {
        Some(sink) => Some(crate::viz::VizThread::start(&cfg, &sink)?),
        None => None,
    };
    let hub = match args.net.listen.first() {
        Some(e) => e.clone(),
        None => free_loopback_endpoint(cfg.security.is_some())?,
    };
    let mut listen = vec![hub.clone()];
    listen.extend(args.net.listen.iter().skip(1).cloned());
    let start_ns = now_ns();
    let duration = args.run_for.duration;
    let stopped = |mut rx: watch::Receiver<bool>| async move {
        let _ = rx.wait_for(|s| *s).await;
    };
    // The estimator is the hub: it listens; everyone else connects to it.
    let hub_up = Hub::start(&cfg, listen, args.net.connect.clone(), UP_WITHIN).await?;
    let peer = hub_up.peer.clone();
    // The view joins before the joints, so it sees the first sample.
    // It stops last, to show the joints' last statuses.
    let (viz_stop_tx, viz_stop_rx) = watch::channel(false);
    let observer = viz.as_ref().map(|v| {
        let (cfg, net, v_tx) = (cfg.clone(), peer.clone(), v.sender());
        let stop = stopped(viz_stop_rx);
        tokio::spawn(async move { crate::viz::observe_with(&cfg, &net, v_tx, stop).await })
    });
    // The summary watches samples, truths and end-effector estimates from the first one.
    let (session, keys) = (hub_up.session.clone(), hub_up.keys.clone());
    let subs = (
        session
            .declare_subscriber(keys.all_samples())
            .await
            .map_err(zenoh_err)?,
        session
            .declare_subscriber(keys.all_sim_truths())
            .await
            .map_err(zenoh_err)?,
        session
            .declare_subscriber(keys.ee_estimate())
            .await
            .map_err(zenoh_err)?,
        session
            .declare_subscriber(keys.all_joint_estimates())
            .await
            .map_err(zenoh_err)?,
        session
            .declare_subscriber(keys.allocation_result())
            .await
            .map_err(zenoh_err)?,
    );
    eprintln!(
        "rig up: rig \"{}\" ({}, {} joints) on {hub}; {}",
        cfg.name,
        cfg.topology.name(),
        cfg.joints.len(),
        duration.map_or("Ctrl-C to stop".to_string(), |d| format!(
            "running {:.1} s",
            d.as_secs_f64()
        ))
    );
    let boards = cfg.joints.iter().map(|j| vec![j.name.clone()]).collect();
    // A board's joints carry the effects when one of them is named (or none is).
    let on = &args.sim_effects_on;
    let backend = |names: &[String]| BackendKind::Sim {
        seed: args.seed,
        effects: if on.is_empty() || names.iter().any(|n| on.contains(n)) {
            effects
        } else {
            rig_sim::effects::Effects::default()
        },
    };
    let launched = hub_up
        .start_roles(true, boards, backend, start_ns, None)
        .await?;
    let missing = &launched.missing;
    if !missing.is_empty() {
        eprintln!(
            "rig up: not up after {} s: {}",
            UP_WITHIN.as_secs(),
            missing.join(", ")
        );
    }
    // A continuous decoupled goal for the allocator, once every joint samples: a joint that
    // is up but still settling would hold the allocator's first commands until they are
    // older than the clock bound, and rightly refuse them as late.
    let home = cfg.geometry.map_or((0.0, 0.0), |g| g.home);
    let goal = AllocationRequest {
        id: 1,
        x_m: home.0,
        y_m: home.1,
        target: AllocationTarget::Percent(args.percent),
    };
    let mut goal_due = cfg.topology.is_robot();
    let mut w = Watch::new(&cfg, start_ns);
    let deadline = duration.map(|d| tokio::time::Instant::now() + d);
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    loop {
        let sleep_until =
            deadline.unwrap_or_else(|| tokio::time::Instant::now() + Duration::from_secs(3600));
        tokio::select! {
            _ = &mut ctrl_c => break,
            _ = tokio::time::sleep_until(sleep_until) => break,
            s = subs.0.recv_async() => if let Ok(s) = s && let Ok(ms) = decode_samples(&s.payload().to_bytes()) {
                for m in ms {
                    *w.samples.entry(m.joint).or_default() += 1;
                }
                if goal_due && w.samples.len() == cfg.joints.len() {
                    goal_due = false;
                    if let Ok(bytes) = encode(&goal) {
                        session.put(keys.stiffness_goal(), bytes).await.map_err(zenoh_err)?;
                    }
                }
            },
            s = subs.1.recv_async() => if let Ok(s) = s && let Ok(m) = decode::<SimTruth>(&s.payload().to_bytes()) {
                w.truth(&m);
            },
            s = subs.2.recv_async() => if let Ok(s) = s && let Ok(m) = decode::<EeEstimate>(&s.payload().to_bytes()) {
                w.estimate(&m);
            },
            s = subs.3.recv_async() => if let Ok(s) = s && let Ok(m) = decode::<JointEstimate>(&s.payload().to_bytes()) {
                w.joint_estimate(&m);
            },
            s = subs.4.recv_async() => if let Ok(s) = s && let Ok(m) = decode::<AllocationResult>(&s.payload().to_bytes()) {
                w.allocation(&m);
            },
        }
    }
    let reports = launched.stop(Duration::from_millis(200)).await?;
    let (joint_reports, est_report) = (reports.joints, reports.estimator);
    let alloc_report = reports.allocator.unwrap_or_default();
    let _ = viz_stop_tx.send(true);
    let viz_stats = match (observer, viz) {
        (Some(o), Some(v)) => {
            o.await??;
            Some(v.finish()?)
        }
        _ => None,
    };

    println!(
        "rig \"{}\" ran {:.1} s ({} topology, {} Hz)",
        cfg.name,
        now_ns().saturating_sub(start_ns) as f64 * 1e-9,
        cfg.topology.name(),
        cfg.rate_hz
    );
    println!(
        "{:<8} {:>9} {:>9} {:>10} {:>10} {:>20} {:>22} {:>12}",
        "joint",
        "samples",
        "skipped",
        "commands",
        "rejected",
        "residual RMS [N·m]",
        "stiffness vs truth",
        "clock [ms]"
    );
    for (name, r) in &joint_reports {
        // The live residual (measured − modelled torque) after the warm-up, where the joint
        // has a torque reference.
        let j = cfg.joints.iter().position(|j| &j.name == name);
        let residual = j
            .and_then(|j| w.residual_rms(j as u16))
            .map_or("—".to_string(), |r| format!("{r:.4}"));
        // The mean relative error of the joint's stiffness estimate against the simulated
        // spring's, after the warm-up.
        let stiffness = j
            .and_then(|j| w.stiffness_error(j as u16))
            .map_or("—".to_string(), |e| format!("{:+.1} %", 100.0 * e));
        // The board's clock against the estimator host's (one way: transit included).
        let clock = j
            .and_then(|j| est_report.clock_offsets_ns.get(j).copied().flatten())
            .map_or("—".to_string(), |o| format!("{:+.3}", o as f64 * 1e-6));
        println!(
            "{:<8} {:>9} {:>9} {:>10} {:>10} {:>20} {:>22} {:>12}",
            name,
            r.samples,
            r.skipped_ticks,
            r.commands_accepted,
            r.commands_rejected,
            residual,
            stiffness,
            clock
        );
    }
    let c = est_report.core;
    println!(
        "estimator: {} samples → {} joint estimates, {} end-effector estimates ({} withheld, {} late, {} malformed, {} refused)",
        c.samples,
        c.joint_estimates,
        c.ee_estimates,
        c.ee_withheld,
        c.late_dropped,
        est_report.malformed,
        c.refused_clock + c.refused_replay + c.refused_range + c.refused_key
    );
    println!(
        "sample age at the estimator: median {} µs, p99 {} µs, max {} µs",
        est_report.age_us.p50, est_report.age_us.p99, est_report.age_us.max
    );
    println!(
        "allocator: {} goals ({} refused for their age), {} requests, {} pivot commands sent ({} to no subscriber)",
        alloc_report.goals,
        alloc_report.stale_goals,
        alloc_report.requests,
        alloc_report.commands,
        alloc_report.unmatched
    );
    if let Some(line) = w.force_error() {
        println!("{line}");
    }
    if let Some(line) = w.operational_error() {
        println!("{line}");
    }
    if let Some(v) = viz_stats {
        println!(
            "viz: {} messages, {} drawn after decimation ({} skipped, {} errors)",
            v.messages, v.logged, v.skipped, v.errors
        );
    }
    Ok(())
}
