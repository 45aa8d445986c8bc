//! The Rerun view's edges: `rig viz` (a Zenoh observer of a running rig), the `--viz` of
//! `rig up` and `rig replay`, and the Rerun-style sink flags they share. The drawing itself is
//! `rig_viz`.

use std::path::PathBuf;
use std::sync::mpsc;

use rig_config::RigConfig;
use rig_runtime::{NetArgs, NetOverrides, RunFor, open, tokio_runtime, zenoh_err};
use rig_viz::{Sink, Viz, VizStats, is_rerun_url};

use crate::error::CliError;

/// Rerun's own flags: `--spawn`, `--viewer URL` (a running viewer), `--save FILE.rrd`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct VizArgs {
    /// Show the rig in Rerun: spawn the viewer when `rerun` is on PATH (pip install
    /// rerun-sdk==0.36.3), else save an .rrd and say where
    #[arg(long)]
    pub viz: bool,
    /// Spawn a Rerun viewer and stream to it (implies --viz)
    #[arg(long)]
    pub spawn: bool,
    /// Save the view to this .rrd file instead of showing it (implies --viz)
    #[arg(long, value_name = "FILE.rrd")]
    pub save: Option<PathBuf>,
    /// Stream to a running Rerun viewer at this URL, e.g. rerun+http://127.0.0.1:9876/proxy
    /// (implies --viz)
    #[arg(long, value_name = "URL")]
    pub viewer: Option<String>,
}

/// Refuses a Rerun viewer URL among the Zenoh endpoints of `--connect`, saying where it goes.
pub fn no_viewer_in_connect(net: &rig_runtime::NetArgs) -> Result<(), CliError> {
    match net.connect.iter().find(|c| is_rerun_url(c)) {
        Some(url) => Err(CliError::Invalid(format!(
            "--connect {url}: a Rerun viewer URL, not a Zenoh endpoint; give it with --viewer {url}"
        ))),
        None => Ok(()),
    }
}

impl VizArgs {
    /// The sink asked for, if any; `always` for `rig viz`.
    pub fn sink(&self, cfg: &RigConfig, always: bool) -> Result<Option<Sink>, CliError> {
        if let Some(p) = &self.save {
            return Ok(Some(Sink::Save(p.clone())));
        }
        if let Some(url) = &self.viewer {
            if !is_rerun_url(url) {
                return Err(CliError::Invalid(format!(
                    "--viewer {url}: not a Rerun viewer URL (rerun+http://HOST:PORT/proxy)"
                )));
            }
            return Ok(Some(Sink::Connect(url.clone())));
        }
        if self.spawn {
            return Ok(Some(Sink::Spawn));
        }
        Ok((self.viz || always).then(|| {
            let stamp = rig_runtime::now_ns() / 1_000_000_000;
            Sink::default_for(PathBuf::from(format!("rig-{}-{stamp}.rrd", cfg.name)))
        }))
    }
}

/// The view on its own thread, fed (key, payload) pairs through an unbounded channel so a
/// Zenoh callback never waits on Rerun.
pub struct VizThread {
    tx: mpsc::Sender<(String, Vec<u8>)>,
    thread: std::thread::JoinHandle<Result<VizStats, rig_viz::VizError>>,
}

impl VizThread {
    pub fn start(cfg: &RigConfig, sink: &Sink) -> Result<Self, CliError> {
        eprintln!("rig viz: {}", sink.describe());
        let mut viz = Viz::open(cfg, sink)?;
        let (tx, rx) = mpsc::channel::<(String, Vec<u8>)>();
        let thread = std::thread::Builder::new()
            .name("rig-viz".into())
            .spawn(move || {
                while let Ok((key, payload)) = rx.recv() {
                    viz.on_message(&key, &payload);
                }
                viz.finish()
            })?;
        Ok(Self { tx, thread })
    }

    pub fn sender(&self) -> mpsc::Sender<(String, Vec<u8>)> {
        self.tx.clone()
    }

    /// Waits for every message sent so far to be drawn and flushed.
    pub fn finish(self) -> Result<VizStats, CliError> {
        drop(self.tx);
        self.thread
            .join()
            .map_err(|_| CliError::Rig("the viz thread panicked".into()))?
            .map_err(CliError::from)
    }
}

/// Observes `rig/<rig>/**` over Zenoh into the view until `stop` resolves.
pub async fn observe(
    cfg: &RigConfig,
    net: &NetOverrides,
    viz: &VizThread,
    stop: impl std::future::Future<Output = ()>,
) -> Result<(), CliError> {
    observe_with(cfg, net, viz.sender(), stop).await
}

/// [`observe`] into a channel.
pub async fn observe_with(
    cfg: &RigConfig,
    net: &NetOverrides,
    tx: mpsc::Sender<(String, Vec<u8>)>,
    stop: impl std::future::Future<Output = ()>,
) -> Result<(), CliError> {
    let keys = rig_protocol::Keys::new(&cfg.name)?;
    let session = open(cfg, net, &rig_config::Identity::Viz).await?;
    let sub = session
        .declare_subscriber(keys.all())
        .callback(move |s| {
            let _ = tx.send((
                s.key_expr().to_string(),
                s.payload().to_bytes().into_owned(),
            ));
        })
        .await
        .map_err(zenoh_err)?;
    stop.await;
    let _ = sub.undeclare().await;
    let _ = session.close().await;
    Ok(())
}

/// `rig viz`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rig config (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Zenoh endpoints: `--connect` the running rig's (e.g. the `rig up --listen` one)
    #[command(flatten)]
    net: NetArgs,
    #[command(flatten)]
    run_for: RunFor,
    #[command(flatten)]
    sink: VizArgs,
}

pub fn run(a: &Args) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    no_viewer_in_connect(&a.net)?;
    let Some(sink) = a.sink.sink(&cfg, true)? else {
        return Err(CliError::Unsupported("no Rerun sink".into()));
    };
    let viz = VizThread::start(&cfg, &sink)?;
    let net = a.net.overrides();
    let rt = tokio_runtime(Some(2))?;
    let duration = a.run_for.duration;
    rt.block_on(observe(&cfg, &net, &viz, async move {
        match duration {
            Some(d) => tokio::time::sleep(d).await,
            None => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }))?;
    let stats = viz.finish()?;
    eprintln!(
        "rig viz: {} messages, {} drawn after decimation, {} skipped, {} errors",
        stats.messages, stats.logged, stats.skipped, stats.errors
    );
    Ok(())
}
