//! `rig` — the VSA rig's command line.
//!
//! Where things come from, one hop away:
//! - `rig up` → [`up`]: every role of a simulated rig over Zenoh — joint agents
//!   (`rig_joint`), the estimator host (`rig_estimator`: its core turns samples into torques
//!   and the end-effector force), the allocator host (`rig_allocator`);
//! - `rig estimator`, `rig allocator` → [`hosts`]: those hosts as processes of their own;
//! - `rig record`, `rig replay` → [`record`] (MCAP of JSON channels, `rig_protocol::json`;
//!   `--estimate` runs `rig_estimator::core`); `rig export` → [`export`] (CSV per topic);
//! - `rig validate` → [`validate`] → `rig_config::load`;
//! - `rig allocate` → [`allocate`] → `rig_model::planar` (S matrix at the pose) and
//!   `rig_model::allocation` (bounded least squares, tie-break) and `rig_model::lever`
//!   (stiffness → pivot position);
//! - `rig sim` → [`sim`] → `rig_sim::scenario` (plants, sensors, undeclared effects);
//! - `rig viz`, `rig up --viz`, `rig replay --viz` → [`viz`] → `rig_viz` (the Rerun view);
//! - `rig bench` → [`bench`]: raw Zenoh round trip, the estimator host's latency and
//!   throughput, with the same agents and host `rig up` runs;
//! - `rig identify` → [`identify`] → `rig_model::identify` (residual → missing effect →
//!   augmented model, before/after on held-out data); files in [`identify_data`], plots in
//!   [`identify_plots`];
//! - `rig scan` → [`scan`] → `rig_dynamixel::scan` (Dynamixel protocols 2.0 and 1.0);
//! - `rig virtual-board`, `rig bench bus` → [`board`] → `rig_joint::virtual_board` (virtual
//!   servos and encoder bridge fed by the simulated plant) and `rig_joint::hardware` (the
//!   `dynamixel` backend's read cycle), `rig_dynamixel::timing` (the wire's limit);
//! - `rig reproduce` → [`reproduce`] → `rig_sim::reproduce` (the papers' experiments); the
//!   end-effector force there comes from `rig_model::estimator::RobotEstimator`.

mod allocate;
mod bench;
mod board;
mod calibrate;
mod certs;
mod config;
mod config_edit;
mod error;
mod export;
mod hosts;
mod identify;
mod identify_data;
mod identify_plots;
mod launch;
mod machine;
mod pivot;
mod progress;
mod record;
mod reproduce;
mod scan;
mod sim;
mod up;
mod up_watch;
mod validate;
mod viz;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The VSA rig: variable stiffness actuators on planar robots, from config to allocation.
///
/// Every rig is described by one TOML file (see rig-config/examples/). Units on the command
/// line carry their name: millimetres for positions, N/m for operational stiffness.
#[derive(Debug, Parser)]
#[command(name = "rig", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the whole simulated rig on this machine: joint agents, estimator and allocator
    /// over Zenoh on loopback, until Ctrl-C or --duration; then a summary scored against the
    /// simulated truth.
    Up(up::Args),
    /// Start this machine's share of the config's plan (`[[machine]]`): a Zenoh hub that
    /// links to the other machines, then its roles (joints, estimator, allocator, recorder,
    /// viz) as processes joined to it; or print the plan with --plan (docs/DEPLOY.md):
    ///
    ///   rig launch --config lab.toml --plan
    ///   rig launch --config lab.toml --machine chain1
    #[command(verbatim_doc_comment)]
    Launch(machine::Args),
    /// Run the estimator host: samples in, joint torques, stiffness, end-effector force out.
    Estimator(hosts::HostArgs),
    /// Run the allocator host: allocation queries and stiffness goals in, pivot commands out.
    Allocator(hosts::HostArgs),
    /// Record every message of a running rig (rig/<rig>/**) into an MCAP file.
    Record(record::RecordArgs),
    /// Republish an MCAP recording; with --estimate run the estimator offline over it and
    /// compare with the live estimates it holds; with --viz (--spawn, --save) draw it in Rerun.
    Replay(record::ReplayArgs),
    /// Write a recording as one CSV file per topic, columns named with their units, for
    /// pandas and spreadsheets:
    ///
    ///   rig export run.mcap --to csv run/
    #[command(verbatim_doc_comment)]
    Export(export::Args),
    /// Check rig config files; print a summary, or every problem with file, line and field.
    ///
    /// Exit status: 0 when every file is valid, 1 otherwise.
    Validate(validate::Args),
    /// Make the lab's CA and one TLS certificate per identity of a rig (each joint's board,
    /// estimator, allocator, operator, recorder, viz, each machine of the plan), for
    /// `[security]`: mutual TLS and access control (docs/SECURITY.md).
    ///
    ///   rig certs --config lab.toml --out certs/
    #[command(verbatim_doc_comment)]
    Certs(certs::Args),
    /// Choose joint stiffnesses that give a wanted operational stiffness at a pose
    /// (paper B eq. 31), and the pivot positions that set them.
    ///
    /// Exit status: 0 when the target is met, 3 when it cannot be (pose unreachable, target
    /// outside the range, or not reachable exactly: the best compromise is still printed),
    /// 1 for a bad config.
    Allocate(allocate::Args),
    /// Run a simulation scenario (TOML) and write its sensor stream as CSV or MCAP.
    ///
    /// Scenarios pick a plant (lever-bench, awas, serial, parallel), the excitation, the
    /// sensors and any undeclared effects; see agents/sim/scenarios/ for examples.
    Sim(sim::Args),
    /// Reproduce a paper's experiments in simulation and print our numbers beside its own.
    Reproduce(reproduce::Args),
    /// Close the loop with measured data: fit a declared model, trace its residual to the
    /// effects it lacks, add those that pay off, report the held-out error before and after.
    Identify(identify::Args),
    /// Hold one lever joint's pivot at a position (a command with torque on, ten times a
    /// second) until Ctrl-C or --duration, as on the bench while calibrating:
    ///
    ///   rig pivot --config bench.toml --joint j1 --mm 9 --connect tcp/192.0.2.10:7447
    #[command(verbatim_doc_comment)]
    Pivot(pivot::Args),
    /// Fit a lever joint's restoring-torque table (paper B eq. 7 at each pivot position the
    /// data holds) from bench data with a torque reference; score it against the config's on
    /// held-out data; write it into the config with --write (comments kept) or --out.
    Calibrate(calibrate::Args),
    /// List the Dynamixel servos on a serial bus: ID, model number, model.
    Scan(scan::Args),
    /// Stand in for a joint board's hardware: virtual servos and encoder bridge on
    /// pseudo-terminals, driven by the simulated plant, for `rig-joint --backend dynamixel`.
    ///
    /// The servos have the config's IDs and models (control tables in memory, both
    /// protocols); their positions and the encoders' counts come from the same simulated world
    /// as the sim backend's. Prints the two ports, then serves them until Ctrl-C:
    ///
    ///   rig virtual-board --config rig-config/examples/parallel.toml
    ///   rig-joint --config rig-config/examples/parallel.toml --joint j1,j2,j3,j4 \
    ///       --backend dynamixel --bus /dev/pts/N --bridge /dev/pts/M
    #[command(verbatim_doc_comment)]
    VirtualBoard(board::VirtualArgs),
    /// Show a running rig live in Rerun: hysteresis loops, stiffness, end-effector force,
    /// allocations (spawns the viewer when `rerun` is on PATH, else saves an .rrd).
    Viz(viz::Args),
    /// Measure the rig on this machine: Zenoh round trip and sample→estimate latency
    /// (`latency`), how many joints one estimator host keeps up with (`throughput`), or the
    /// Dynamixel board's read cycle against the wire's limit (`bus`).
    Bench(bench::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Up(a) => up::run(&a),
        Command::Launch(a) => machine::run(&a),
        Command::Estimator(a) => hosts::estimator(&a),
        Command::Allocator(a) => hosts::allocator(&a),
        Command::Record(a) => record::record(&a),
        Command::Pivot(a) => pivot::run(&a),
        Command::Replay(a) => record::replay(&a),
        Command::Export(a) => export::run(&a),
        Command::Validate(a) => validate::run(&a),
        Command::Certs(a) => certs::run(&a),
        Command::Allocate(a) => allocate::run(&a),
        Command::Sim(a) => sim::run(&a),
        Command::Reproduce(a) => reproduce::run(&a),
        Command::Identify(a) => identify::run(&a),
        Command::Calibrate(a) => calibrate::run(&a),
        Command::Scan(a) => scan::run(&a),
        Command::VirtualBoard(a) => board::virtual_board(&a),
        Command::Bench(a) => bench::run(&a),
        Command::Viz(a) => viz::run(&a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            e.exit_code()
        }
    }
}
