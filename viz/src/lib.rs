//! # rig-viz — the rig's live Rerun view
//!
//! [`Viz`] turns the rig's messages (as they travel on Zenoh or sit in an MCAP recording)
//! into a Rerun recording laid out by a blueprint ([`blueprint`]):
//!
//! - per joint, the **hysteresis loop** — deflection [deg] against torque [N·m], measured
//!   (the torque sensor, or the simulator's truth) and modelled (the estimator), as line
//!   strips over a trailing window (`joints/<j>/loop/*`);
//! - per joint, **pivot position and stiffness** over time, the estimate and the truth in
//!   simulation; for an AWAS joint the EKF's **inertia and damping** with ±2σ bands;
//! - the **planar robot** (links, joints, the end effector) with the estimated and true
//!   end-effector **force** as arrows (`robot/*`), and the force over time (`force/*`);
//! - **allocations**: wanted, achieved and estimated operational stiffness over time and as
//!   stiffness ellipses (`allocation/*`);
//! - joint and estimator **statuses** as a text log (`status`).
//!
//! High rates stay live by decimation on the messages' own clock: time series at 100 Hz,
//! loops of 2 s at 100 Hz redrawn at 5 Hz, the robot at 20 Hz; Rerun's batcher groups the
//! rest. 2D views in Rerun draw y downwards, so 2D entities log −y (torque and the robot's y
//! point up on screen); hovering shows the logged sign.
//!
//! No I/O beyond the Rerun sink; the Zenoh and MCAP edges live in the `rig` command.

pub mod paths;
mod scene;
mod trail;

use std::path::PathBuf;

pub use scene::{VizStats, blueprint};
pub use trail::{Gate, Trail};

use rig_config::RigConfig;
use rig_protocol::{Topic, decode_any};
use thiserror::Error;

pub use rerun;

/// Errors of the view.
#[derive(Debug, Error)]
pub enum VizError {
    #[error("rerun: {0}")]
    Rerun(#[from] rerun::RecordingStreamError),
    #[error("rerun: flushing the recording: {0}")]
    Flush(#[from] rerun::sink::SinkFlushError),
    #[error("rerun: the rig's name {name:?} makes no application id: {reason}")]
    ApplicationId { name: String, reason: String },
    #[error(
        "cannot spawn the Rerun viewer ({0}); install it with `pip install rerun-sdk==0.36.3`, or use --save FILE.rrd"
    )]
    Spawn(#[source] rerun::RecordingStreamError),
}

/// Where the view goes, as Rerun's own tools name it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Sink {
    /// Start a viewer (`rerun` on PATH) and stream to it.
    Spawn,
    /// Stream to a running viewer, e.g. `rerun+http://127.0.0.1:9876/proxy`.
    Connect(String),
    /// Write an .rrd file.
    Save(PathBuf),
}

impl Sink {
    /// The default: spawn the viewer when `rerun` is on PATH, else save to `fallback`.
    pub fn default_for(fallback: PathBuf) -> Self {
        if rerun_on_path() {
            Sink::Spawn
        } else {
            Sink::Save(fallback)
        }
    }

    /// A sentence for the user.
    pub fn describe(&self) -> String {
        match self {
            Sink::Spawn => "streaming to a spawned Rerun viewer".into(),
            Sink::Connect(url) => format!("streaming to the Rerun viewer at {url}"),
            Sink::Save(p) => format!(
                "saving the view to {} (open it with `rerun {}`)",
                p.display(),
                p.display()
            ),
        }
    }
}

/// Whether a `rerun` executable is on PATH.
pub fn rerun_on_path() -> bool {
    std::env::var_os("PATH").is_some_and(|paths| {
        std::env::split_paths(&paths).any(|d| {
            let p = d.join("rerun");
            p.is_file() || p.with_extension("exe").is_file()
        })
    })
}

/// Whether a `--connect` value is a Rerun viewer URL (rather than a Zenoh endpoint).
pub fn is_rerun_url(s: &str) -> bool {
    s.starts_with("rerun+http://")
        || s.starts_with("rerun+https://")
        || s.starts_with("rerun://")
        || s.starts_with("http://")
        || s.starts_with("https://")
}

/// The viewer's memory limit when we spawn it: past it, Rerun drops the oldest data, so a
/// rig left running for hours keeps a bounded viewer.
pub const VIEWER_MEMORY_LIMIT: &str = "1GB";

/// The live view of one rig.
pub struct Viz {
    rec: rerun::RecordingStream,
    scene: scene::Scene,
}

impl std::fmt::Debug for Viz {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viz")
            .field("stats", &self.scene.stats)
            .finish_non_exhaustive()
    }
}

impl Viz {
    /// Opens the sink and sends the blueprint for `cfg`'s rig.
    pub fn open(cfg: &RigConfig, sink: &Sink) -> Result<Self, VizError> {
        let app = rerun::ApplicationId::try_from(format!("rig-{}", cfg.name)).map_err(|e| {
            VizError::ApplicationId {
                name: cfg.name.clone(),
                reason: e.to_string(),
            }
        })?;
        // Chunks of 200 ms live: the viewer keeps a 100 Hz series in ~20-row chunks instead
        // of one row per chunk (the low-latency default when streaming), several times less
        // memory. A file takes 2 s chunks: an .rrd's footer indexes every chunk, and that
        // index is held in memory until the file is closed.
        let tick = match sink {
            Sink::Save(_) => std::time::Duration::from_secs(2),
            _ => std::time::Duration::from_millis(200),
        };
        let builder = rerun::RecordingStreamBuilder::new(app).batcher_config(
            rerun::log::ChunkBatcherConfig {
                flush_tick: tick,
                ..rerun::log::ChunkBatcherConfig::DEFAULT
            },
        );
        let rec = match sink {
            Sink::Spawn => builder
                .spawn_opts(&rerun::SpawnOptions {
                    memory_limit: VIEWER_MEMORY_LIMIT.into(),
                    // The viewer's gRPC server listens on loopback only, like the rig.
                    extra_args: vec!["--bind".into(), "127.0.0.1".into()],
                    ..Default::default()
                })
                .map_err(VizError::Spawn)?,
            Sink::Connect(url) => builder.connect_grpc_opts(url.clone())?,
            Sink::Save(path) => builder.save(path)?,
        };
        blueprint(cfg).send(&rec, rerun::blueprint::BlueprintActivation::default())?;
        let scene = scene::Scene::new(cfg);
        scene.log_static(&rec)?;
        Ok(Self { rec, scene })
    }

    /// One message as it came over Zenoh or out of a recording: its key and payload.
    /// Keys of other rigs, unknown keys and malformed payloads are counted and skipped.
    pub fn on_message(&mut self, key: &str, payload: &[u8]) {
        let Ok(topic) = Topic::parse(key) else {
            self.scene.stats.skipped += 1;
            return;
        };
        let Ok(msg) = decode_any(payload) else {
            self.scene.stats.skipped += 1;
            return;
        };
        if let Err(e) = self.scene.on(&self.rec, &topic, &msg) {
            self.scene.stats.errors += 1;
            if self.scene.stats.errors == 1 {
                eprintln!("rig viz: {e} (further errors counted, not printed)");
            }
        }
    }

    pub fn stats(&self) -> VizStats {
        self.scene.stats
    }

    /// Flushes what is buffered to the sink.
    pub fn finish(self) -> Result<VizStats, VizError> {
        self.rec.flush_blocking()?;
        Ok(self.scene.stats)
    }
}
