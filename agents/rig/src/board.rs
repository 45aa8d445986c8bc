//! The hardware path from the command line: `rig virtual-board` (a joint board's servos and
//! encoder bridge without hardware) and `rig bench bus` (how long one read cycle of the
//! `dynamixel` backend takes, against what the wire allows).

use std::path::PathBuf;
use std::time::Instant;

use rig_config::RigConfig;
use rig_dynamixel::timing::wire_s;
use rig_joint::board::{JointBoard, SafeState, joint_index};
use rig_joint::hardware::{BoardPlan, DynamixelBoard, PortOverrides};
use rig_joint::virtual_board::VirtualBoard;
use rig_runtime::now_ns;
use serde_json::json;

use crate::error::CliError;

fn joints(cfg: &RigConfig, names: &[String]) -> Result<Vec<usize>, CliError> {
    if names.is_empty() {
        return Ok((0..cfg.joints.len()).collect());
    }
    names.iter().map(|n| Ok(joint_index(cfg, n)?)).collect()
}

/// Arguments of `rig virtual-board` (its help is on the subcommand in main.rs).
#[derive(Debug, clap::Args)]
pub struct VirtualArgs {
    /// Rig config (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Joints on the board (default: every joint of the config)
    #[arg(long, value_delimiter = ',', value_name = "NAME")]
    joint: Vec<String>,
    /// Start of the simulated world [ns since the UNIX epoch]; default: now
    #[arg(long)]
    start_ns: Option<u64>,
    /// Seed of the simulated plant
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    run_for: rig_runtime::RunFor,
    /// Print the ports as one JSON object {"bus", "bridge"}
    #[arg(long)]
    json: bool,
}

pub fn virtual_board(a: &VirtualArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let js = joints(&cfg, &a.joint)?;
    let board = VirtualBoard::start(&cfg, &js, a.start_ns.unwrap_or_else(now_ns), a.seed)?;
    if a.json {
        println!(
            "{}",
            json!({"bus": board.bus_path, "bridge": board.bridge_path})
        );
    } else {
        println!("bus {}", board.bus_path.display());
        println!("bridge {}", board.bridge_path.display());
        eprintln!("virtual board of {} joint(s) up; Ctrl-C to stop", js.len());
    }
    // Whoever reads our stdout (a script, a test) gets the ports now.
    use std::io::Write;
    std::io::stdout().flush()?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(async {
        let until = async {
            match a.run_for.duration {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = until => {}
        }
    });
    drop(board);
    Ok(())
}

/// Arguments of `rig bench bus` (its help is on the subcommand in bench.rs): time the
/// `dynamixel` backend's read cycle and set it against the wire's limit at the config's bauds.
#[derive(Debug, clap::Args)]
pub struct BusArgs {
    /// Rig config (default: the example parallel robot: 4 joints on one bus and one bridge)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Joints on the board (default: every joint of the config)
    #[arg(long, value_delimiter = ',', value_name = "NAME")]
    joint: Vec<String>,
    /// Servo bus port of real hardware (default: a virtual board)
    #[arg(long, value_name = "PATH")]
    bus: Option<PathBuf>,
    /// Encoder bridge port of real hardware
    #[arg(long, value_name = "PATH")]
    bridge: Option<PathBuf>,
    /// Read cycles timed (after 100 warm-up cycles)
    #[arg(long, default_value_t = 5000, value_parser = clap::value_parser!(u32).range(1..))]
    cycles: u32,
    /// Print one JSON object instead of the table
    #[arg(long)]
    json: bool,
}

pub fn bench_bus(a: &BusArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let js = joints(&cfg, &a.joint)?;
    let (virt, ports) = match (&a.bus, &a.bridge) {
        (None, None) => {
            let v = VirtualBoard::start(&cfg, &js, now_ns(), 1)?;
            let ports = PortOverrides {
                bus: Some(v.bus_path.clone()),
                bridge: Some(v.bridge_path.clone()),
            };
            (Some(v), ports)
        }
        (bus, bridge) => (
            None,
            PortOverrides {
                bus: bus.clone(),
                bridge: bridge.clone(),
            },
        ),
    };
    let mut board = DynamixelBoard::open(&BoardPlan::from_config(&cfg, &js, &ports)?)?;
    let period = 1.0 / cfg.rate_hz;
    for _ in 0..100 {
        board.read_cycle(period)?;
    }
    let pb = crate::progress::bar(u64::from(a.cycles), "bus cycles");
    let mut us = Vec::with_capacity(a.cycles as usize);
    let t0 = Instant::now();
    for _ in 0..a.cycles {
        let t = Instant::now();
        board.read_cycle(period)?;
        us.push(t.elapsed().as_secs_f64() * 1e6);
        pb.inc(1);
    }
    let total = t0.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let stats = board.bus_stats();
    let loads = board.wire_per_cycle();
    let safe = board.safe_state();
    drop(board);
    let kind = if virt.is_some() {
        "virtual"
    } else {
        "hardware"
    };
    drop(virt);
    if let SafeState::TorqueOffFailed(failed) = safe {
        return Err(CliError::Rig(format!(
            "torque off failed: {}",
            failed.join("; ")
        )));
    }
    let cycle = rig_estimator::histogram::LatencySummary::of(us.iter().map(|&u| u.round() as u64));
    // The wire: each line's bytes at its configured baud (the virtual lines have no baud of
    // their own).
    let wire: Vec<_> = loads
        .iter()
        .map(|l| {
            json!({
                "line": l.line,
                "baud": l.baud,
                "bytes": l.bytes,
                "replies": l.replies,
                "transactions": l.transactions,
                "bridge": l.bridge,
                "wire_us": wire_s(l.bytes, l.baud) * 1e6,
            })
        })
        .collect();
    // The buses are read one after the other, the bridges likewise, both groups at once.
    let wire_us = rig_joint::hardware::wire_s_per_cycle(&loads) * 1e6;
    let transactions: usize = loads.iter().map(|l| l.transactions).sum();
    let out = json!({
        "board": kind,
        "joints": js.len(),
        "cycles": us.len(),
        "cycle_us": {"mean": total / us.len().max(1) as f64 * 1e6, "p50": cycle.p50, "p99": cycle.p99, "max": cycle.max},
        "bus": {"transfers": stats.transfers, "retries": stats.retries, "failures": stats.failures},
        "wire": wire,
        "wire_us": wire_us,
        "wire_limit_hz": 1e6 / wire_us,
        "transactions_per_cycle": transactions,
        "rate_hz": cfg.rate_hz,
    });
    if a.json {
        println!("{out}");
        return Ok(());
    }
    println!(
        "{} board, {} joints, {} cycles: mean {:.0} µs, p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs",
        kind,
        js.len(),
        us.len(),
        total / us.len().max(1) as f64 * 1e6,
        cycle.p50,
        cycle.p99,
        cycle.max
    );
    println!(
        "bus: {} transfers, {} retries, {} failures",
        stats.transfers, stats.retries, stats.failures
    );
    for l in &loads {
        println!(
            "wire {}: {} bytes at {} baud = {:.0} µs, {} replies, {} round trips",
            l.line,
            l.bytes,
            l.baud,
            wire_s(l.bytes, l.baud) * 1e6,
            l.replies,
            l.transactions
        );
    }
    println!(
        "theoretical limit: {:.0} µs a cycle on the wire (buses and bridges at once) = {:.0} Hz (rate_hz {}); add each reply's Return Delay Time and each round trip's USB latency",
        wire_us,
        1e6 / wire_us,
        cfg.rate_hz
    );
    let cycles_s: Vec<f64> = us.iter().map(|u| u * 1e-6).collect();
    match rig_joint::hardware::pace::verdict(cfg.rate_hz, wire_us * 1e-6, &cycles_s) {
        Some(too_fast) => println!("{too_fast}"),
        None => println!(
            "rate_hz {} fits: the median cycle is {:.0} µs of the tick's {:.0} µs",
            cfg.rate_hz,
            cycle.p50,
            1e6 / cfg.rate_hz
        ),
    }
    Ok(())
}
