//! The estimator host's Zenoh edge: samples in from `rig/<rig>/joint/*/sample` (a board of one
//! joint) and `rig/<rig>/board/*/sample` (a board's tick of several joints, kind 9), estimates
//! out on `rig/<rig>/estimate/joint/<j>`, `rig/<rig>/estimate/ee` and `rig/<rig>/estimate/status`.
//!
//! Samples are handled in the subscriber's callback, on Zenoh's receive thread: decode, feed
//! the core, publish what it returns. No hop through a channel and an async task, which on
//! this 2-core machine cost more than the estimation itself (`rig bench latency` measures
//! it). A 20 ms timer drives the core's staleness checks from an async task; both paths share
//! the core behind a mutex that is held only while the core computes.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use rig_config::RigConfig;
use rig_protocol::{BoardSample, JointSample, Keys, decode, encode};
use rig_runtime::zenoh::{self, Wait};
use rig_runtime::{NetOverrides, now_ns, open, publisher, zenoh_err as z};
use thiserror::Error;

use crate::core::{CoreStats, CoreTiming, EstimatorCore, Output};
use crate::histogram::{Histogram, LatencySummary};

#[derive(Debug, Error)]
pub enum EstimatorError {
    #[error(transparent)]
    Core(#[from] crate::core::CoreError),
    #[error(transparent)]
    Runtime(#[from] rig_runtime::RuntimeError),
}

impl From<rig_protocol::KeyError> for EstimatorError {
    fn from(e: rig_protocol::KeyError) -> Self {
        Self::Runtime(e.into())
    }
}

/// How to run the estimator host.
#[derive(Debug, Clone)]
pub struct EstimatorOptions {
    pub cfg: RigConfig,
    pub net: NetOverrides,
    pub duration: Option<Duration>,
}

/// What the host did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EstimatorReport {
    pub core: CoreStats,
    pub malformed: u64,
    /// Sample age on arrival (now − t_acq) [µs]: median, 99th percentile, largest.
    pub age_us: LatencySummary,
    /// Latency of the host [µs]: median, 99th percentile, largest — from the Zenoh timestamp
    /// of the sample that completed a tick (when its agent published it) to the moment the
    /// tick's first estimate was published (the end-effector force of a robot; it goes out
    /// first): one Zenoh hop plus the estimation.
    pub latency_us: LatencySummary,
    /// The same, to the moment every estimate of the tick (each joint's too) was published.
    pub all_published_us: LatencySummary,
    /// The same, to the moment the tick's first estimate was handed to Zenoh (encoded, its put
    /// called): the hop and the host's own work, without the put. The put's time is mostly
    /// Zenoh waking its transmit thread, which the next hop's one way counts again: a raw
    /// one way starts at the ping's timestamp, taken as its put is called.
    pub handed_us: LatencySummary,
    /// The transport part of that latency [µs]: from the same Zenoh timestamp to the sample's
    /// arrival in the host, before any estimation.
    pub transport_us: LatencySummary,
    /// Time from the first to the last sample received [ns].
    pub window_ns: u64,
    /// Estimates or statuses Zenoh refused to publish.
    pub publish_errors: u64,
    /// Each joint's board clock against this host's at the end [ns] (positive: ahead; one
    /// way, low by the smallest transit), in the config's joint order.
    pub clock_offsets_ns: Vec<Option<i64>>,
}

/// The host's publishers.
struct Publishers {
    joints: Vec<zenoh::pubsub::Publisher<'static>>,
    ee: zenoh::pubsub::Publisher<'static>,
    status: zenoh::pubsub::Publisher<'static>,
}

impl Publishers {
    /// Publishes the core's outputs in order (the end-effector estimate first); returns how
    /// many Zenoh refused, and when the first estimate was handed to Zenoh and when it was
    /// out [ns].
    fn publish(&self, outputs: Vec<Output>) -> (u64, Option<(u64, u64)>) {
        let mut failed = 0;
        let mut first_handed = None;
        let mut first_out = None;
        let mut put = |p: &zenoh::pubsub::Publisher<'static>, bytes: Vec<u8>| {
            failed += u64::from(p.put(bytes).wait().is_err());
        };
        for o in outputs {
            match o {
                Output::Joint(e) => {
                    if let (Some(p), Ok(bytes)) = (self.joints.get(e.joint as usize), encode(&e)) {
                        first_handed.get_or_insert_with(now_ns);
                        put(p, bytes);
                        first_out.get_or_insert_with(now_ns);
                    }
                }
                Output::Ee(e) => {
                    if let Ok(bytes) = encode(&e) {
                        first_handed.get_or_insert_with(now_ns);
                        put(&self.ee, bytes);
                        first_out.get_or_insert_with(now_ns);
                    }
                }
                Output::Status(s) => {
                    eprintln!("rig estimator: {}", s.text);
                    if let Ok(bytes) = encode(&s) {
                        put(&self.status, bytes);
                    }
                }
            }
        }
        (failed, first_handed.zip(first_out))
    }
}

/// The core and the host's bookkeeping, shared by the sample callback and the timer.
struct State {
    core: EstimatorCore,
    report: EstimatorReport,
    ages: Histogram,
    latencies: Histogram,
    transport: Histogram,
    all_out: Histogram,
    handed: Histogram,
    first_arrival: Option<u64>,
}

fn lock(state: &Mutex<State>) -> MutexGuard<'_, State> {
    // A panic elsewhere cannot leave the core half-updated in a way that matters more than
    // stopping: keep serving with what is there.
    state
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// One message from Zenoh — a joint's sample, or a board's tick (`board`) — decoded, fed to
/// the core, its estimates published.
fn on_sample(state: &Mutex<State>, pubs: &Publishers, s: &zenoh::sample::Sample, board: bool) {
    let bytes = s.payload().to_bytes();
    let decoded = if board {
        decode::<BoardSample>(&bytes).map(|b| b.samples)
    } else {
        decode::<JointSample>(&bytes).map(|s| vec![s])
    };
    let samples = match decoded {
        Ok(samples) => samples,
        Err(e) => {
            let n = {
                let mut st = lock(state);
                st.report.malformed += 1;
                st.report.malformed
            };
            // Counted, and said at the 1st, 10th, 100th…: a flood cannot fill the log.
            if rig_runtime::worth_a_line(n) {
                eprintln!(
                    "rig estimator: dropped a malformed sample on {}: {e} ({n} malformed so far)",
                    s.key_expr()
                );
            }
            return;
        }
    };
    // `rig/<rig>/joint/<j>/sample` or `rig/<rig>/board/<b>/sample`: the payload must be
    // joint <j>'s, or of joints board <b> runs.
    let key_name = s.key_expr().as_str().rsplit('/').nth(1).unwrap_or("");
    let published_ns = rig_runtime::published_ns(s);
    let now = now_ns();
    let outputs = {
        let mut st = lock(state);
        let first = *st.first_arrival.get_or_insert(now);
        st.report.window_ns = now.saturating_sub(first);
        for sample in &samples {
            st.ages.record(now.saturating_sub(sample.t_acq_ns) / 1000);
        }
        match (board, samples.as_slice()) {
            (false, [sample]) => st.core.on_sample_from(key_name, *sample, now),
            _ => st
                .core
                .on_board_sample_from(key_name, BoardSample { samples }, now),
        }
    };
    let (failed, first_out) = pubs.publish(outputs);
    let done = now_ns();
    let mut st = lock(state);
    st.report.publish_errors += failed;
    if let (Some(t), Some((handed, first))) = (published_ns, first_out) {
        st.transport.record(now.saturating_sub(t) / 1000);
        st.handed.record(handed.saturating_sub(t) / 1000);
        st.latencies.record(first.saturating_sub(t) / 1000);
        st.all_out.record(done.saturating_sub(t) / 1000);
    }
}

/// Runs the host until `shutdown` resolves or the duration ends.
pub async fn run(
    opts: EstimatorOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<EstimatorReport, EstimatorError> {
    let cfg = &opts.cfg;
    let core = EstimatorCore::new(cfg, CoreTiming::for_config(cfg))?;
    let keys = Keys::new(&cfg.name)?;
    let session = open(cfg, &opts.net, &rig_config::Identity::Estimator).await?;
    let mut joints = Vec::new();
    for name in core.names() {
        joints.push(publisher(&session, keys.joint_estimate(name)?).await?);
    }
    let pubs = Arc::new(Publishers {
        joints,
        ee: publisher(&session, keys.ee_estimate()).await?,
        status: publisher(&session, keys.estimator_status()).await?,
    });
    let state = Arc::new(Mutex::new(State {
        core,
        report: EstimatorReport::default(),
        ages: Histogram::new(),
        latencies: Histogram::new(),
        transport: Histogram::new(),
        all_out: Histogram::new(),
        handed: Histogram::new(),
        first_arrival: None,
    }));
    // One subscriber per joint on its concrete key, not one on `joint/*/sample`: Zenoh caches
    // the route of a key it has a resource for, and matches every other key against all
    // resources it knows, per message (a third of the CPU at 64 joints).
    let mut samples = Vec::new();
    for name in cfg.joints.iter().map(|j| j.name.as_str()) {
        let (state, pubs) = (state.clone(), pubs.clone());
        samples.push(
            session
                .declare_subscriber(keys.joint_sample(name)?)
                .callback(move |s| on_sample(&state, &pubs, &s, false))
                .await
                .map_err(z)?,
        );
    }
    // Boards of several joints: one message per tick each, few enough that one wildcard
    // subscription costs nothing measurable (their names come from the agents' plan).
    {
        let (state, pubs) = (state.clone(), pubs.clone());
        samples.push(
            session
                .declare_subscriber(keys.all_board_samples())
                .callback(move |s| on_sample(&state, &pubs, &s, true))
                .await
                .map_err(z)?,
        );
    }
    let _token = session
        .liveliness()
        .declare_token(keys.alive("estimator", "0")?)
        .await
        .map_err(z)?;

    let mut ticks = rig_runtime::Ticks::new(Duration::from_millis(20), opts.duration, shutdown);
    while ticks.next().await {
        let outputs = lock(&state).core.on_tick(now_ns());
        let (failed, _) = pubs.publish(outputs);
        lock(&state).report.publish_errors += failed;
    }
    // No callback runs after the subscribers are undeclared.
    for s in samples {
        s.undeclare().await.map_err(z)?;
    }
    let report = {
        let mut st = lock(&state);
        st.report.core = st.core.stats;
        let mut r = st.report.clone();
        r.clock_offsets_ns = st.core.clock_offsets_ns().to_vec();
        r.age_us = st.ages.summary();
        r.latency_us = st.latencies.summary();
        r.transport_us = st.transport.summary();
        r.all_published_us = st.all_out.summary();
        r.handed_us = st.handed.summary();
        r
    };
    session.close().await.map_err(z)?;
    Ok(report)
}
