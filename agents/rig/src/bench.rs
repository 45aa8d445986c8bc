//! `rig bench`: how fast the rig is on this machine, measured, never assumed.
//!
//! - `rig bench latency`: first the raw Zenoh round trip between two sessions on loopback
//!   (ping–pong with a sample-sized payload, as Zenoh's own `z_ping`/`z_pong`), then the
//!   simulated rig (one agent per joint, the estimator host, an observer of the estimates)
//!   and the estimator host's latency: from the Zenoh timestamp of the sample that completed
//!   a tick (when its agent published it) to the moment every estimate of that tick has been
//!   published — one Zenoh hop plus the estimation. The targets (issue 16): the rig adds at
//!   most 15 µs to half a round trip at the median, and its p99 is at most 250 µs.
//! - `rig bench throughput --joints N`: one joint board serving N simulated joints at the
//!   rate (a bench topology: independent lever joints) against one estimator host; samples
//!   per second received, samples lost, ticks the board could not keep up with.
//! - `rig bench footprint`: the joint agent's memory — the `rig-joint` binary as its own
//!   process serving the config's joints against an estimator host, its resident set read
//!   from `/proc` ten times a second.
//! - `rig bench bus`: the `dynamixel` backend's read cycle ([`crate::board`]).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use rig_config::{RigConfig, Topology};
use rig_estimator::edge::EstimatorReport;
use rig_estimator::histogram::LatencySummary;
use rig_joint::agent::{AgentReport, BackendKind};
use rig_protocol::{BoardSample, JointSample, encode};
use rig_runtime::cli::positive_seconds;
use rig_runtime::zenoh::{self, Wait};
use rig_runtime::{NetOverrides, now_ns, published_ns, tokio_runtime, zenoh_config};
use serde::Serialize;

use crate::error::CliError;
use crate::launch::Hub;
use crate::up::free_loopback_endpoint;

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, clap::Subcommand)]
enum What {
    /// Raw Zenoh round trip on this machine, then the rig's sample→estimate latency at the
    /// config's joints and rate (default: the parallel example, 4 joints × 1 kHz).
    ///
    /// The raw trips run back to back, then one per tick of the rig's rate (both sessions
    /// sleep between messages, as the rig's do). Each trip's one way — the ping's Zenoh
    /// timestamp to the echo's callback — is read exactly as the rig's transport part is, so
    /// the two compare on one clock.
    Latency(LatencyArgs),
    /// N simulated joints at the rate on one board against one estimator host.
    Throughput(ThroughputArgs),
    /// The joint agent's memory: `rig-joint` (built next to `rig`) serving the config's
    /// joints on one board against an estimator host; its resident set (VmRSS) after the
    /// start, at the end and at its peak (VmHWM), read from /proc (Linux).
    Footprint(FootprintArgs),
    /// The dynamixel backend's read cycle (servos and encoders of every joint) against the
    /// wire's theoretical limit; on a virtual board unless --bus/--bridge name hardware.
    ///
    /// On a virtual board the figure is our software and the kernel's pseudo-terminals, no
    /// wire; on the rig it includes the wire, the servos' Return Delay Time and the USB
    /// adapter's latency timer (docs/HARDWARE.md). Example on paper B's rig:
    /// rig bench bus --bus /dev/ttyUSB0 --bridge /dev/ttyACM0 --json
    Bus(crate::board::BusArgs),
}

#[derive(Debug, clap::Args)]
struct LatencyArgs {
    /// Rig config (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<std::path::PathBuf>,
    /// How long the rig runs [s]
    #[arg(long, default_value = "60", value_name = "SECONDS", value_parser = positive_seconds, allow_negative_numbers = true)]
    duration: Duration,
    /// How the joints are served: `one` board for all (paper B's wiring: one bus drives
    /// every servo) or a board `per-joint` (as `rig up` runs them)
    #[arg(long, value_enum, default_value_t = Boards::One)]
    boards: Boards,
    /// Round trips timed for the raw Zenoh figure (after 500 warm-up ones), back to back and
    /// then again one per tick of the rig's rate
    #[arg(long, default_value_t = 10_000)]
    pings: usize,
    /// Also time raw round trips of other payload sizes — a board message of the config's
    /// joints (kind 9, what one board sends per tick), 1 KiB, 64 KiB — as the peers' tables do
    /// (dora, zenoh's z_ping); the sizes are sent in turn, --pings of each
    #[arg(long)]
    sweep: bool,
    /// Print one JSON object instead of the table
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
enum Boards {
    One,
    PerJoint,
}

#[derive(Debug, clap::Args)]
struct ThroughputArgs {
    /// Simulated joints on the board (1 to 1024, as many as one board message carries)
    #[arg(long, default_value_t = 64)]
    joints: usize,
    /// Sample rate of every joint [Hz]
    #[arg(long, default_value_t = 1000.0, value_name = "HZ")]
    rate_hz: f64,
    /// How long the board runs [s]
    #[arg(long, default_value = "10", value_name = "SECONDS", value_parser = positive_seconds, allow_negative_numbers = true)]
    duration: Duration,
    /// Print one JSON object instead of the table
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct FootprintArgs {
    /// Rig config (default: the example parallel robot: 4 joints × 1 kHz)
    #[arg(long, value_name = "FILE")]
    config: Option<std::path::PathBuf>,
    /// How long the joint agent runs [s]
    #[arg(long, default_value = "30", value_name = "SECONDS", value_parser = positive_seconds, allow_negative_numbers = true)]
    duration: Duration,
    /// Print one JSON object instead of the table
    #[arg(long)]
    json: bool,
}

pub fn run(args: &Args) -> Result<(), CliError> {
    match &args.what {
        What::Latency(a) => latency(a),
        What::Throughput(a) => throughput(a),
        What::Footprint(a) => footprint(a),
        What::Bus(a) => crate::board::bench_bus(a),
    }
}

#[derive(Debug, Serialize)]
struct LatencyReport {
    /// Raw round trips back to back (the next ping as soon as the echo is back) [µs].
    zenoh_rtt_us: LatencySummary,
    /// The same round trips, one started on each tick of the rig's rate [µs]: both sessions
    /// sleep between messages as the rig's do, so every hop wakes a sleeping thread.
    zenoh_rtt_paced_us: LatencySummary,
    /// One way of the back-to-back trips: the ping's Zenoh timestamp to the echo callback's
    /// start [µs], measured as `rig_transport_us` is.
    zenoh_one_way_us: LatencySummary,
    /// One way of the trips one per tick [µs]: the raw figure beside `rig_transport_us`.
    zenoh_one_way_paced_us: LatencySummary,
    rig_latency_us: LatencySummary,
    /// Worst rig latency seen [µs].
    rig_latency_max_us: u64,
    /// Latency to the last estimate of the tick (each joint's) [µs].
    rig_all_published_us: LatencySummary,
    /// Latency to the moment the tick's first estimate was handed to Zenoh (its put called)
    /// [µs]: `rig_latency_us` less the put, which is mostly Zenoh waking its transmit thread
    /// (counted again in the next hop's one way, as the raw one way counts the ping's).
    rig_handed_us: LatencySummary,
    /// The transport part of the rig latency: the completing sample's publication to its
    /// arrival in the estimator host [µs].
    rig_transport_us: LatencySummary,
    /// Samples the joint agents published, and those the estimator never received.
    sent: u64,
    lost: u64,
    joints: usize,
    boards: Boards,
    rate_hz: f64,
    duration_s: f64,
    /// Estimates the observer session received.
    estimates_observed: u64,
    /// Ticks the agents skipped because their timer woke too late.
    skipped_ticks: u64,
    /// With --sweep: the raw round trip at each payload size.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    sweep: Vec<SweepPoint>,
}

#[derive(Debug, Serialize)]
struct SweepPoint {
    payload_bytes: usize,
    zenoh_rtt_us: LatencySummary,
}

#[derive(Debug, Serialize)]
struct ThroughputReport {
    joints: usize,
    rate_hz: f64,
    /// Samples the estimator received per second of the run.
    samples_per_s: f64,
    /// Samples published and never received by the estimator.
    lost: u64,
    sent: u64,
    /// Ticks the board skipped because it could not keep up.
    skipped_ticks: u64,
    /// Estimates the estimator published per second.
    estimates_per_s: f64,
    /// Sample age at the estimator (now − acquisition time) [µs].
    age_us: LatencySummary,
    /// The estimator host's sample→estimate latency [µs] (see `rig bench latency`).
    latency_us: LatencySummary,
    duration_s: f64,
    /// This process's resident set (the estimator host and the load generator) 2 s after
    /// the start and at the end [kB]: flat over a long run means no growth.
    rss_start_kb: Option<u64>,
    rss_end_kb: Option<u64>,
    /// CPU of this whole process (estimator host, load generator, Zenoh) per sample received
    /// [µs], measured from 2 s after the start (Linux).
    cpu_us_per_sample: Option<f64>,
    /// Each thread's CPU over that window, in cores (1.0: one core all the time), busiest
    /// first: where it saturates. The threads under 0.005 cores each come last as one entry,
    /// `other threads (N)`, so the list adds up to `cpu_us_per_sample`.
    threads: Vec<ThreadCpu>,
}

/// Each thread's CPU in cores, busiest first; the threads under 0.005 cores each are summed
/// into one last entry, `other threads (N)`, so that the list adds up to the whole process.
fn by_thread(used: &BTreeMap<String, u64>, window: Duration) -> Vec<ThreadCpu> {
    let secs = window.as_secs_f64().max(1e-9);
    let (mut named, mut rest) = (Vec::new(), (0usize, 0.0));
    for (name, ns) in used {
        let cores = *ns as f64 * 1e-9 / secs;
        if cores >= 0.005 {
            named.push(ThreadCpu {
                name: name.clone(),
                cores,
            });
        } else if cores > 0.0 {
            rest = (rest.0 + 1, rest.1 + cores);
        }
    }
    named.sort_by(|a, b| b.cores.total_cmp(&a.cores));
    if rest.0 > 0 {
        named.push(ThreadCpu {
            name: format!("other threads ({})", rest.0),
            cores: rest.1,
        });
    }
    named
}

#[derive(Debug, Serialize)]
struct ThreadCpu {
    name: String,
    cores: f64,
}

fn zerr<E: Into<zenoh::Error>>(e: E) -> CliError {
    CliError::Network(rig_runtime::zenoh_err(e))
}

/// What [`zenoh_rtt`] timed, one entry per timed ping [µs].
struct Trips {
    /// The ping's put to its echo's arrival back, on this thread's monotonic clock.
    rtt: Vec<u64>,
    /// The ping's Zenoh timestamp (taken in its put) to the echo callback's start: one way,
    /// measured exactly as the rig's transport part (`rig_transport_us`) is.
    one_way: Vec<u64>,
}

/// Raw round trips between two Zenoh sessions on loopback, blocking API, `pings` timed per
/// payload: back to back, or with `pace` each started on its own tick (`start + i·pace`).
/// Several payloads are sent in turn, ten pings of each at a time, so every size is timed
/// under the same load and the sizes' figures compare; one [`Trips`] per payload, in order.
/// The payloads' lengths must differ (the echo side tells them apart by length).
fn zenoh_rtt(
    cfg: &RigConfig,
    pings: usize,
    payloads: &[Vec<u8>],
    pace: Option<Duration>,
) -> Result<Vec<Trips>, CliError> {
    let n = payloads.len();
    let mut lengths: Vec<usize> = payloads.iter().map(Vec::len).collect();
    lengths.sort_unstable();
    lengths.dedup();
    if n == 0 || lengths.len() != n {
        return Err(CliError::Invalid(format!(
            "round trips: {n} payloads, {} distinct lengths (each payload needs its own length)",
            lengths.len()
        )));
    }
    // Plain TCP on loopback between two bare sessions: the transport's own figure.
    let hub = free_loopback_endpoint(false)?;
    let bare = rig_config::ZenohConfig {
        mode: cfg.zenoh.mode,
        listen: vec![],
        connect: vec![],
    };
    let config = |net: NetOverrides| zenoh_config(&bare, &net).map_err(CliError::from);
    let a = zenoh::open(config(NetOverrides {
        listen: vec![hub.clone()],
        ..Default::default()
    })?)
    .wait()
    .map_err(zerr)?;
    let b = zenoh::open(config(NetOverrides {
        connect: vec![hub],
        ..Default::default()
    })?)
    .wait()
    .map_err(zerr)?;
    let keys = rig_protocol::Keys::new(&cfg.name)?;
    let id = std::process::id().to_string();
    let (ping_key, pong_key) = (keys.bench(&id, "ping")?, keys.bench(&id, "pong")?);
    let pong = b
        .declare_publisher(pong_key.clone())
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .map_err(zerr)?;
    // Every ping's one-way time with its payload's length, read where the rig's estimator
    // reads its samples' (the callback's start against the Zenoh timestamp), the warm-up ones
    // first.
    const WARM_UP: usize = 500;
    // Pings of one payload in a row before the next payload's. Ten in a row: this shared
    // machine flips between a fast and a slow state every few to hundred milliseconds (block
    // medians of 55–60 µs or about 1 ms, 2026-12-02), so each size must see both alike;
    // one at a time would time a small ping in the wake of a large one.
    const BLOCK: usize = 10;
    let one_way = Arc::new(std::sync::Mutex::new(Vec::with_capacity(
        pings * n + WARM_UP + 100,
    )));
    let arrivals = one_way.clone();
    let _echo = b
        .declare_subscriber(ping_key.clone())
        .callback(move |s| {
            let now = now_ns();
            let _ = pong.put(s.payload().clone()).wait();
            if let (Some(t), Ok(mut v)) = (published_ns(&s), arrivals.lock()) {
                v.push((s.payload().len(), now.saturating_sub(t) / 1000));
            }
        })
        .wait()
        .map_err(zerr)?;
    let replies = a.declare_subscriber(pong_key).wait().map_err(zerr)?;
    let ping = a
        .declare_publisher(ping_key)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .map_err(zerr)?;
    // Until the first echo comes back the peers are not linked yet.
    let linked = Instant::now();
    loop {
        ping.put(payloads[0].clone()).wait().map_err(zerr)?;
        if replies
            .recv_timeout(Duration::from_millis(50))
            .map_err(zerr)?
            .is_some()
        {
            break;
        }
        if linked.elapsed() > Duration::from_secs(10) {
            return Err(CliError::Unsupported(
                "zenoh: two sessions on loopback did not link within 10 s".into(),
            ));
        }
    }
    while replies.try_recv().map_err(zerr)?.is_some() {}
    // The order of the pings: each payload's in blocks of BLOCK, the payloads in turn, the
    // warm-up first (untimed), then `pings` of each timed.
    let blocks = |each: usize, timed: bool| {
        (0..each.div_ceil(BLOCK)).flat_map(move |r| {
            (0..n).flat_map(move |which| {
                std::iter::repeat_n((which, timed), BLOCK.min(each - r * BLOCK))
            })
        })
    };
    let plan = blocks(WARM_UP.div_ceil(n), false).chain(blocks(pings, true));
    let mut rtt = vec![Vec::with_capacity(pings); n];
    let start = Instant::now();
    for (i, (which, timed)) in plan.enumerate() {
        if let Some(period) = pace {
            let due = start + period * i as u32;
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        let t0 = Instant::now();
        ping.put(payloads[which].clone()).wait().map_err(zerr)?;
        match replies.recv_timeout(Duration::from_secs(1)).map_err(zerr)? {
            Some(_) if timed => rtt[which].push(t0.elapsed().as_micros() as u64),
            Some(_) => {}
            None => {
                return Err(CliError::Unsupported(
                    "zenoh: a ping got no echo within 1 s".into(),
                ));
            }
        }
    }
    drop(ping);
    let _ = a.close().wait();
    let _ = b.close().wait();
    // Each timed ping had its echo, so the last `pings · n` arrivals are the timed ones.
    let arrived = one_way.lock().map(|v| v.clone()).unwrap_or_default();
    let timed = &arrived[arrived.len().saturating_sub(pings * n)..];
    Ok(payloads
        .iter()
        .zip(rtt)
        .map(|(p, rtt)| Trips {
            rtt,
            one_way: timed
                .iter()
                .filter(|(len, _)| *len == p.len())
                .map(|(_, us)| *us)
                .collect(),
        })
        .collect())
}

/// What a rig run produced.
struct RigRun {
    agents: Vec<AgentReport>,
    estimator: EstimatorReport,
    observed: u64,
    /// This process's resident set (estimator host, boards, observer) 2 s after the start
    /// and at the end of the run [kB] (None where /proc cannot be read).
    rss_kb: Option<(u64, u64)>,
    /// CPU time of each thread (by name) from 2 s after the start to the last reading while
    /// the boards ran, and that window's length.
    cpu: Option<(BTreeMap<String, u64>, Duration)>,
}

/// CPU time each of this process's threads has used [ns], summed by thread name (Zenoh's
/// `rx-0`, `tx-0`, tokio's workers…), from `/proc/self/task/*/schedstat` (Linux; empty
/// elsewhere).
fn threads_cpu_ns() -> BTreeMap<String, u64> {
    let mut by_name = BTreeMap::new();
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return by_name;
    };
    for task in tasks.flatten() {
        let dir = task.path();
        let (Ok(comm), Ok(stat)) = (
            std::fs::read_to_string(dir.join("comm")),
            std::fs::read_to_string(dir.join("schedstat")),
        ) else {
            continue;
        };
        if let Some(ns) = stat
            .split_whitespace()
            .next()
            .and_then(|v| v.parse::<u64>().ok())
        {
            *by_name.entry(comm.trim().to_string()).or_default() += ns;
        }
    }
    by_name
}

/// Runs the estimator host (the hub) and the joint boards for `duration`; an observer
/// session counts the estimates. Each board is a list of joints served by one agent.
fn run_rig(
    cfg: &RigConfig,
    boards: Vec<Vec<String>>,
    duration: Duration,
    label: &str,
) -> Result<RigRun, CliError> {
    let rt = tokio_runtime(Some(2))?;
    rt.block_on(async {
        let hub = Hub::start(
            cfg,
            vec![free_loopback_endpoint(cfg.security.is_some())?],
            vec![],
            Duration::from_secs(10),
        )
        .await?;
        // An observer of every estimate, as a viewer or a recorder would be, declared before
        // the joints start.
        let observed = Arc::new(AtomicU64::new(0));
        let mut estimate_keys = vec![hub.keys.ee_estimate()];
        for j in &cfg.joints {
            estimate_keys.push(hub.keys.joint_estimate(&j.name)?);
        }
        let mut subs = Vec::new();
        for key in estimate_keys {
            let counter = observed.clone();
            subs.push(
                hub.session
                    .declare_subscriber(key)
                    .callback(move |_| {
                        counter.fetch_add(1, Ordering::Relaxed);
                    })
                    .await
                    .map_err(zerr)?,
            );
        }
        let rig = hub
            .start_roles(
                false,
                boards,
                |_| BackendKind::default(),
                now_ns(),
                Some(duration),
            )
            .await?;
        let pb = crate::progress::bar(duration.as_secs().max(1), label);
        let t0 = Instant::now();
        let (mut rss_start, mut rss_end) = (None, None);
        let (mut cpu_start, mut cpu_end) = (None, None);
        while rig.boards_running() {
            tokio::time::sleep(Duration::from_millis(200)).await;
            pb.set_position(t0.elapsed().as_secs().min(duration.as_secs()));
            let rss = resident_kb(std::process::id()).map(|(rss, _)| rss);
            if rss_start.is_none() && t0.elapsed() >= Duration::from_secs(2) {
                rss_start = rss;
                cpu_start = Some((threads_cpu_ns(), Instant::now()));
            }
            rss_end = rss.or(rss_end);
            if cpu_start.is_some() {
                cpu_end = Some((threads_cpu_ns(), Instant::now()));
            }
        }
        pb.finish_and_clear();
        // The last samples arrive before the estimator stops.
        let reports = rig.stop(Duration::from_millis(500)).await?;
        Ok(RigRun {
            agents: reports.joints.into_iter().map(|(_, r)| r).collect(),
            estimator: reports.estimator,
            observed: observed.load(Ordering::Relaxed),
            rss_kb: rss_start.zip(rss_end),
            cpu: cpu_start.zip(cpu_end).map(|((a, t_a), (b, t_b))| {
                let used = b
                    .into_iter()
                    .map(|(name, ns)| {
                        let before = a.get(&name).copied().unwrap_or(0);
                        (name, ns.saturating_sub(before))
                    })
                    .collect();
                (used, t_b - t_a)
            }),
        })
    })
}

fn latency(a: &LatencyArgs) -> Result<(), CliError> {
    let duration = a.duration;
    if a.pings == 0 {
        return Err(CliError::Invalid("--pings: at least one round trip".into()));
    }
    let cfg = crate::config::load_or_parallel(&a.config)?;
    // The ping payload is a real encoded sample, so both figures move the same bytes.
    let sample = JointSample {
        joint: 0,
        seq: 1,
        t_acq_ns: now_ns(),
        motor_rad: 0.1,
        deflection_rad: 0.01,
        pivot_m: Some(0.01),
        torque_nm: None,
        motor_torque_nm: None,
        stiffness_motor_rad: None,
    };
    let payload = encode(&sample)?;
    // One board's tick of every joint of the config, each sample as above.
    let board = encode(&BoardSample {
        samples: (0..cfg.joints.len().clamp(1, rig_protocol::MAX_BOARD_JOINTS) as u16)
            .map(|joint| JointSample { joint, ..sample })
            .collect(),
    })?;
    eprintln!(
        "rig bench latency: {} raw Zenoh round trips, then the rig ({} joints × {} Hz) for {:.0} s",
        a.pings,
        cfg.joints.len(),
        cfg.rate_hz,
        duration.as_secs_f64()
    );
    let one = |trips: Vec<Trips>| {
        trips
            .into_iter()
            .next()
            .ok_or_else(|| CliError::Invalid("round trips: none timed".into()))
    };
    let back_to_back = one(zenoh_rtt(
        &cfg,
        a.pings,
        std::slice::from_ref(&payload),
        None,
    )?)?;
    // The same round trips one per tick of the rig's rate: both sessions sleep between
    // messages, as the agents and the estimator host do.
    let tick = Duration::from_secs_f64(1.0 / cfg.rate_hz);
    let paced = one(zenoh_rtt(&cfg, a.pings, &[payload], Some(tick))?)?;
    let mut sweep = Vec::new();
    if a.sweep {
        // The sizes in turn in one session pair, so a load that comes and goes on the machine
        // falls on each size alike.
        let sizes = [board, vec![0x5a; 1024], vec![0x5a; 64 * 1024]];
        let trips = zenoh_rtt(&cfg, a.pings, &sizes, None)?;
        for (bytes, trips) in sizes.iter().zip(trips) {
            sweep.push(SweepPoint {
                payload_bytes: bytes.len(),
                zenoh_rtt_us: LatencySummary::of(trips.rtt),
            });
        }
    }
    let names = cfg.joints.iter().map(|j| j.name.clone());
    let boards = match a.boards {
        Boards::One => vec![names.collect()],
        Boards::PerJoint => names.map(|n| vec![n]).collect(),
    };
    let r = run_rig(&cfg, boards, duration, "rig running")?;
    let sent: u64 = r.agents.iter().map(|a| a.samples).sum();
    let received = r.estimator.core.samples;
    let report = LatencyReport {
        zenoh_rtt_us: LatencySummary::of(back_to_back.rtt),
        zenoh_rtt_paced_us: LatencySummary::of(paced.rtt),
        zenoh_one_way_us: LatencySummary::of(back_to_back.one_way),
        zenoh_one_way_paced_us: LatencySummary::of(paced.one_way),
        rig_latency_us: r.estimator.latency_us,
        rig_latency_max_us: r.estimator.latency_us.max,
        rig_all_published_us: r.estimator.all_published_us,
        rig_handed_us: r.estimator.handed_us,
        rig_transport_us: r.estimator.transport_us,
        sent,
        lost: sent.saturating_sub(received),
        joints: cfg.joints.len(),
        boards: a.boards,
        rate_hz: cfg.rate_hz,
        duration_s: duration.as_secs_f64(),
        estimates_observed: r.observed,
        skipped_ticks: r.agents.iter().map(|a| a.skipped_ticks).sum(),
        sweep,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report).map_err(io)?);
    } else {
        let half = report.zenoh_rtt_us.p50 as f64 / 2.0;
        println!(
            "raw Zenoh round trip      p50 {:>6} µs   p99 {:>6} µs",
            report.zenoh_rtt_us.p50, report.zenoh_rtt_us.p99
        );
        println!(
            "  one per tick ({:.0} Hz)   p50 {:>6} µs   p99 {:>6} µs",
            report.rate_hz, report.zenoh_rtt_paced_us.p50, report.zenoh_rtt_paced_us.p99
        );
        println!(
            "raw one way (timestamp)   p50 {:>6} µs   p99 {:>6} µs   one per tick: p50 {} µs, p99 {} µs",
            report.zenoh_one_way_us.p50,
            report.zenoh_one_way_us.p99,
            report.zenoh_one_way_paced_us.p50,
            report.zenoh_one_way_paced_us.p99
        );
        println!(
            "rig sample→estimate       p50 {:>6} µs   p99 {:>6} µs   max {} µs",
            report.rig_latency_us.p50, report.rig_latency_us.p99, report.rig_latency_max_us
        );
        println!(
            "  of which transport      p50 {:>6} µs   p99 {:>6} µs   ({:+} µs over the raw one way per tick)",
            report.rig_transport_us.p50,
            report.rig_transport_us.p99,
            report.rig_transport_us.p50 as i64 - report.zenoh_one_way_paced_us.p50 as i64
        );
        println!(
            "  to the first put        p50 {:>6} µs   p99 {:>6} µs   (the put itself: p50 {:+} µs)",
            report.rig_handed_us.p50,
            report.rig_handed_us.p99,
            report.rig_latency_us.p50 as i64 - report.rig_handed_us.p50 as i64
        );
        println!(
            "  every estimate out      p50 {:>6} µs   p99 {:>6} µs",
            report.rig_all_published_us.p50, report.rig_all_published_us.p99
        );
        println!(
            "rig p50 − half round trip {:>+6.0} µs (target ≤ +15 µs); p99 target ≤ 250 µs",
            report.rig_latency_us.p50 as f64 - half
        );
        println!(
            "rig p50 − half paced trip {:>+6.0} µs",
            report.rig_latency_us.p50 as f64 - report.zenoh_rtt_paced_us.p50 as f64 / 2.0
        );
        println!(
            "samples sent {}, lost {}; {} estimates observed; {} ticks skipped by the agents",
            report.sent, report.lost, report.estimates_observed, report.skipped_ticks
        );
        for p in &report.sweep {
            println!(
                "raw round trip, {:>6} B   p50 {:>6} µs   p99 {:>6} µs",
                p.payload_bytes, p.zenoh_rtt_us.p50, p.zenoh_rtt_us.p99
            );
        }
    }
    Ok(())
}

fn io(e: serde_json::Error) -> CliError {
    CliError::Io(std::io::Error::other(e))
}

/// A bench rig of `n` copies of the parallel example's first joint.
fn bench_config(n: usize, rate_hz: f64) -> Result<RigConfig, CliError> {
    if !(1..=rig_config::MAX_BENCH_JOINTS).contains(&n) {
        return Err(CliError::Invalid(format!(
            "--joints: {n} is outside 1 to {}",
            rig_config::MAX_BENCH_JOINTS
        )));
    }
    if !(rate_hz.is_finite() && (1.0..=20_000.0).contains(&rate_hz)) {
        return Err(CliError::Invalid(format!(
            "--rate-hz: {rate_hz} Hz is outside [1, 20000] Hz"
        )));
    }
    let mut cfg = rig_config::examples::load("parallel")?;
    let template = cfg.joints[0].clone();
    cfg.name = "bench".into();
    cfg.topology = Topology::Bench;
    cfg.geometry = None;
    cfg.rate_hz = rate_hz;
    cfg.joints = (0..n)
        .map(|i| {
            let mut j = template.clone();
            j.name = format!("b{i:02}");
            j.index = i;
            j.servo = None;
            j
        })
        .collect();
    Ok(cfg)
}

fn throughput(a: &ThroughputArgs) -> Result<(), CliError> {
    let duration = a.duration;
    let cfg = bench_config(a.joints, a.rate_hz)?;
    eprintln!(
        "rig bench throughput: {} joints × {} Hz on one board against one estimator host, {:.0} s",
        a.joints,
        a.rate_hz,
        duration.as_secs_f64()
    );
    let board: Vec<String> = cfg.joints.iter().map(|j| j.name.clone()).collect();
    let r = run_rig(&cfg, vec![board], duration, "board running")?;
    let sent: u64 = r.agents.iter().map(|a| a.samples).sum();
    let e = &r.estimator;
    let secs = (e.window_ns as f64 * 1e-9).max(1e-9);
    let report = ThroughputReport {
        joints: a.joints,
        rate_hz: a.rate_hz,
        samples_per_s: e.core.samples as f64 / secs,
        lost: sent.saturating_sub(e.core.samples),
        sent,
        // One board: every joint it serves skips the same ticks.
        skipped_ticks: r.agents.first().map_or(0, |a| a.skipped_ticks),
        estimates_per_s: e.core.joint_estimates as f64 / secs,
        age_us: e.age_us,
        latency_us: e.latency_us,
        duration_s: duration.as_secs_f64(),
        rss_start_kb: r.rss_kb.map(|r| r.0),
        rss_end_kb: r.rss_kb.map(|r| r.1),
        cpu_us_per_sample: r.cpu.as_ref().and_then(|(used, window)| {
            let samples = e.core.samples as f64 / secs * window.as_secs_f64();
            (samples > 0.0).then(|| used.values().sum::<u64>() as f64 * 1e-3 / samples)
        }),
        threads: r
            .cpu
            .as_ref()
            .map_or_else(Vec::new, |(used, window)| by_thread(used, *window)),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report).map_err(io)?);
    } else {
        println!(
            "{} joints × {} Hz: {:.0} samples/s received (of {:.0} wanted), {} lost of {} sent, {} ticks skipped",
            report.joints,
            report.rate_hz,
            report.samples_per_s,
            report.joints as f64 * report.rate_hz,
            report.lost,
            report.sent,
            report.skipped_ticks
        );
        println!(
            "estimates {:.0}/s; sample age at the estimator p50 {} µs, p99 {} µs; sample→estimate p50 {} µs, p99 {} µs",
            report.estimates_per_s,
            report.age_us.p50,
            report.age_us.p99,
            report.latency_us.p50,
            report.latency_us.p99
        );
        if let (Some(a), Some(b)) = (report.rss_start_kb, report.rss_end_kb) {
            println!(
                "memory of this process (estimator host and load generator): {:.1} MB after 2 s, {:.1} MB at the end",
                a as f64 / 1024.0,
                b as f64 / 1024.0
            );
        }
        if let Some(us) = report.cpu_us_per_sample {
            let threads: Vec<String> = report
                .threads
                .iter()
                .map(|t| format!("{} {:.2}", t.name, t.cores))
                .collect();
            println!(
                "CPU of this process {us:.2} µs per sample; by thread, in cores: {}",
                threads.join(", ")
            );
        }
    }
    Ok(())
}

/// A process's resident set and its peak [kB], from `/proc/<pid>/status` (Linux).
fn resident_kb(pid: u32) -> Option<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

#[derive(Debug, Serialize)]
struct FootprintReport {
    joints: usize,
    rate_hz: f64,
    duration_s: f64,
    /// Resident set 2 s after the start, at the last reading, and the peak [kB].
    rss_start_kb: u64,
    rss_end_kb: u64,
    rss_peak_kb: u64,
    /// Samples the estimator host received from the agent.
    samples_received: u64,
}

fn footprint(a: &FootprintArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let exe = std::env::current_exe()?.with_file_name("rig-joint");
    if !exe.exists() {
        return Err(CliError::Unsupported(format!(
            "{} not found: the joint agent is measured as its own binary; build it with \
             `cargo build --release -p rig-joint`",
            exe.display()
        )));
    }
    // The agent reads its config from a file: the one given, or the built-in example.
    let example;
    let config_path = match &a.config {
        Some(p) => p.clone(),
        None => {
            example =
                std::env::temp_dir().join(format!("rig-footprint-{}.toml", std::process::id()));
            std::fs::write(&example, rig_config::examples::PARALLEL)?;
            example.clone()
        }
    };
    let joints: Vec<String> = cfg.joints.iter().map(|j| j.name.clone()).collect();
    eprintln!(
        "rig bench footprint: rig-joint serving {} ({} Hz) against an estimator host, {:.0} s",
        joints.join(","),
        cfg.rate_hz,
        a.duration.as_secs_f64()
    );
    let rt = tokio_runtime(Some(2))?;
    let result = rt.block_on(async {
        let endpoint = free_loopback_endpoint(cfg.security.is_some())?;
        let hub = Hub::start(
            &cfg,
            vec![endpoint.clone()],
            vec![],
            Duration::from_secs(10),
        )
        .await?;
        let mut child = std::process::Command::new(&exe)
            .arg("--config")
            .arg(&config_path)
            .arg("--joint")
            .arg(joints.join(","))
            .args(["--connect", &endpoint])
            .arg("--duration")
            .arg(format!("{}", a.duration.as_secs_f64()))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()?;
        let pid = child.id();
        let pb = crate::progress::bar(a.duration.as_secs().max(1), "joint agent running");
        let t0 = Instant::now();
        let (mut start, mut end, mut peak) = (None, 0, 0);
        let exited = loop {
            if let Some(status) = child.try_wait()? {
                break status;
            }
            if let Some((rss, hwm)) = resident_kb(pid) {
                if start.is_none() && t0.elapsed() >= Duration::from_secs(2) {
                    start = Some(rss);
                }
                (end, peak) = (rss, hwm);
            }
            pb.set_position(t0.elapsed().as_secs().min(a.duration.as_secs()));
            // Often enough that the host stops soon after the agent (before it calls the
            // joints stale), cheap enough not to load the machine.
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        pb.finish_and_clear();
        let estimator = hub.stop().await?;
        if !exited.success() {
            let mut err = String::new();
            if let Some(mut e) = child.stderr.take() {
                let _ = std::io::Read::read_to_string(&mut e, &mut err);
            }
            return Err(CliError::Rig(format!(
                "rig-joint ended with {exited}: {err}"
            )));
        }
        let Some(start) = start else {
            return Err(CliError::Rig(
                "no reading of the agent's memory (is /proc mounted? Linux only)".into(),
            ));
        };
        Ok(FootprintReport {
            joints: joints.len(),
            rate_hz: cfg.rate_hz,
            duration_s: a.duration.as_secs_f64(),
            rss_start_kb: start,
            rss_end_kb: end,
            rss_peak_kb: peak,
            samples_received: estimator.core.samples,
        })
    });
    if a.config.is_none() {
        let _ = std::fs::remove_file(&config_path);
    }
    let report = result?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report).map_err(io)?);
    } else {
        println!(
            "rig-joint, {} joints × {} Hz for {:.0} s: resident {:.1} MB after 2 s, {:.1} MB at the end, peak {:.1} MB; {} samples received",
            report.joints,
            report.rate_hz,
            report.duration_s,
            report.rss_start_kb as f64 / 1024.0,
            report.rss_end_kb as f64 / 1024.0,
            report.rss_peak_kb as f64 / 1024.0,
            report.samples_received
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threads_under_half_a_percent_of_a_core_are_summed_into_one_last_entry() {
        // Over 2 s: 1 s of CPU is half a core; 4 ms and 6 ms are 0.002 and 0.003 cores.
        let used: BTreeMap<String, u64> = [
            ("rx-0", 1_000_000_000),
            ("rx-1", 4_000_000),
            ("tx-0", 6_000_000),
            ("idle", 0),
        ]
        .into_iter()
        .map(|(n, ns)| (n.to_string(), ns))
        .collect();
        let t = by_thread(&used, Duration::from_secs(2));
        assert_eq!(t.len(), 2, "{t:?}");
        assert_eq!((t[0].name.as_str(), t[0].cores), ("rx-0", 0.5));
        assert_eq!(t[1].name, "other threads (2)");
        assert!((t[1].cores - 0.005).abs() < 1e-12, "{t:?}");
    }
}
