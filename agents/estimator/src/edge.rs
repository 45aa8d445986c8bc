//! The estimator host's Zenoh edge: samples in from `rig/<rig>/joint/*/sample`, estimates out
//! on `rig/<rig>/estimate/joint/<j>`, `rig/<rig>/estimate/ee` and `rig/<rig>/estimate/status`.

use std::time::Duration;

use rig_config::RigConfig;
use rig_protocol::{JointSample, Keys, decode, encode};
use rig_runtime::{NetOverrides, now_ns, open, zenoh_err as z};
use thiserror::Error;

use crate::core::{CoreStats, CoreTiming, EstimatorCore, Output};

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
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EstimatorReport {
    pub core: CoreStats,
    pub malformed: u64,
    /// Sample age on arrival (now − t_acq) [µs]: median, 99th percentile, largest.
    pub age_us: [u64; 3],
}

fn percentiles(mut v: Vec<u64>) -> [u64; 3] {
    if v.is_empty() {
        return [0; 3];
    }
    v.sort_unstable();
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    [at(0.5), at(0.99), v[v.len() - 1]]
}

/// Runs the host until `shutdown` resolves or the duration ends.
pub async fn run(
    opts: EstimatorOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<EstimatorReport, EstimatorError> {
    let cfg = &opts.cfg;
    let mut core = EstimatorCore::new(cfg, CoreTiming::for_rate(cfg.rate_hz))?;
    let keys = Keys::new(&cfg.name)?;
    let session = open(&cfg.zenoh, &opts.net).await?;
    let samples = session
        .declare_subscriber(format!("rig/{}/joint/*/sample", cfg.name))
        .await
        .map_err(z)?;
    let mut joint_pubs = Vec::new();
    for name in core.names() {
        joint_pubs.push(
            session
                .declare_publisher(keys.joint_estimate(name)?)
                .await
                .map_err(z)?,
        );
    }
    let ee_pub = session
        .declare_publisher(keys.ee_estimate())
        .await
        .map_err(z)?;
    let status_pub = session
        .declare_publisher(keys.estimator_status())
        .await
        .map_err(z)?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive("estimator", "0")?)
        .await
        .map_err(z)?;

    let mut report = EstimatorReport::default();
    let mut ages: Vec<u64> = Vec::new();
    let mut ticker = tokio::time::interval(Duration::from_millis(20));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    tokio::pin!(shutdown);
    loop {
        let outputs = tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => {
                if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
                    break;
                }
                core.on_tick(now_ns())
            }
            s = samples.recv_async() => match s {
                Ok(s) => match decode::<JointSample>(&s.payload().to_bytes()) {
                    Ok(sample) => {
                        let now = now_ns();
                        if ages.len() < 10_000_000 {
                            ages.push(now.saturating_sub(sample.t_acq_ns) / 1000);
                        }
                        core.on_sample(sample, now)
                    }
                    Err(e) => {
                        report.malformed += 1;
                        eprintln!("rig estimator: dropped a malformed sample on {}: {e}", s.key_expr());
                        Vec::new()
                    }
                },
                Err(_) => break,
            },
        };
        for o in outputs {
            match o {
                Output::Joint(e) => {
                    if let (Some(p), Ok(bytes)) = (joint_pubs.get(e.joint as usize), encode(&e)) {
                        p.put(bytes).await.map_err(z)?;
                    }
                }
                Output::Ee(e) => {
                    if let Ok(bytes) = encode(&e) {
                        ee_pub.put(bytes).await.map_err(z)?;
                    }
                }
                Output::Status(s) => {
                    eprintln!("rig estimator: {}", s.text);
                    if let Ok(bytes) = encode(&s) {
                        status_pub.put(bytes).await.map_err(z)?;
                    }
                }
            }
        }
    }
    report.core = core.stats;
    report.age_us = percentiles(ages);
    session.close().await.map_err(z)?;
    Ok(report)
}
