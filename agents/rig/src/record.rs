//! `rig record` and `rig replay`: every message under `rig/<rig>/**` to an MCAP file and back.
//!
//! Each key is an MCAP channel (topic = the key, message encoding `rig-wire/1`: the payload
//! exactly as on the wire, `protocol/WIRE.md`); each message kind has a schema (encoding
//! `rig-wire/1`, data: its Python struct layout). Records are written unchunked and flushed
//! every 100 ms, so a killed recorder leaves a file whose complete records all read back.
//! `rig replay --estimate` runs the estimator's core offline over the recorded samples and
//! compares with the live estimates in the same file.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Duration;

use rig_estimator::core::{CoreTiming, EstimatorCore, Output};
use rig_protocol::{EeEstimate, JointEstimate, JointSample, Keys, Kind, decode};
use rig_runtime::{NetArgs, RunFor, now_ns, open, tokio_runtime, zenoh_err};

use crate::error::CliError;

/// Message encoding of every channel.
pub const ENCODING: &str = "rig-wire/1";

/// A kind's MCAP schema: its name and its layout (the envelope's and the body's Python
/// `struct` formats, from the wire table).
fn schema_of(kind: u8) -> (String, String) {
    match Kind::try_from(kind) {
        Ok(k) => (
            format!("rig.{}", k.name()),
            format!("<2sBBI {}", k.body_format()),
        ),
        Err(_) => ("rig.Unknown".into(), "not a rig message".into()),
    }
}

#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// Output file (.mcap)
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Rig config, for the rig's name and Zenoh endpoints (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Zenoh endpoints: `--connect` the running rig's, e.g. the tcp/127.0.0.1:PORT that
    /// `rig up --listen` opened
    #[command(flatten)]
    net: NetArgs,
    #[command(flatten)]
    run_for: RunFor,
}

pub fn record(a: &RecordArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let rt = tokio_runtime(Some(2))?;
    rt.block_on(async {
        let keys = Keys::new(&cfg.name)?;
        let session = open(&cfg.zenoh, &a.net.overrides())
            .await?;
        // A callback into an unbounded channel: the session's receive path never waits on the
        // disk, so nothing is dropped upstream while a write is slow.
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
        let _sub = session
            .declare_subscriber(keys.all())
            .callback(move |s| {
                let _ = tx.send(s);
            })
            .await
            .map_err(zenoh_err)?;
        // Up once subscribed, as every role: `rig/<rig>/alive/recorder/<pid>`.
        let _token = session
            .liveliness()
            .declare_token(
                keys.alive("recorder", &std::process::id().to_string())?,
            )
            .await
            .map_err(zenoh_err)?;
        let file = std::fs::File::create(&a.out)?;
        let mut w = mcap::WriteOptions::new()
            .use_chunks(false)
            .profile("rig")
            .create(BufWriter::new(file))
            ?;
        let mut schemas: BTreeMap<u8, u16> = BTreeMap::new();
        let mut channels: BTreeMap<String, u16> = BTreeMap::new();
        let mut seq = 0u32;
        let deadline = a.run_for.duration.map(|d| tokio::time::Instant::now() + d);
        let mut flush = tokio::time::interval(Duration::from_millis(100));
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        eprintln!("rig record: recording {} into {}", keys.all(), a.out.display());
        loop {
            let far = tokio::time::Instant::now() + Duration::from_secs(3600);
            tokio::select! {
                _ = &mut ctrl_c => break,
                _ = tokio::time::sleep_until(deadline.unwrap_or(far)) => break,
                _ = flush.tick() => w.flush()?,
                s = rx.recv() => {
                    let Some(s) = s else { break };
                    let bytes = s.payload().to_bytes();
                    let kind = bytes.get(3).copied().unwrap_or(0);
                    let key = s.key_expr().as_str().to_string();
                    let schema = match schemas.get(&kind) {
                        Some(&id) => id,
                        None => {
                            let (name, data) = schema_of(kind);
                            let id = w.add_schema(&name, ENCODING, data.as_bytes())?;
                            schemas.insert(kind, id);
                            id
                        }
                    };
                    let channel = match channels.get(&key) {
                        Some(&id) => id,
                        None => {
                            let id = w.add_channel(schema, &key, ENCODING, &BTreeMap::new())?;
                            channels.insert(key, id);
                            id
                        }
                    };
                    let log_time = now_ns();
                    let publish_time = s.timestamp().map_or(log_time, |t| t.get_time().to_system_time().duration_since(std::time::UNIX_EPOCH).map_or(log_time, |d| d.as_nanos() as u64));
                    seq = seq.wrapping_add(1);
                    w.write_to_known_channel(&mcap::records::MessageHeader { channel_id: channel, sequence: seq, log_time, publish_time }, &bytes)
                        ?;
                }
            }
        }
        w.finish()?;
        let _ = session.close().await;
        eprintln!("rig record: {seq} messages on {} keys written to {}", channels.len(), a.out.display());
        Ok(())
    })
}

/// One recorded message.
pub struct Recorded {
    pub topic: String,
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// Reads every complete message; a file cut short (killed recorder) ends at its last whole
/// record, which is reported, not an error.
pub fn read_all(path: &PathBuf) -> Result<(Vec<Recorded>, bool), CliError> {
    let buf = std::fs::read(path)?;
    let stream = mcap::MessageStream::new_with_options(
        &buf,
        enumset::EnumSet::only(mcap::read::Options::IgnoreEndMagic),
    )
    .map_err(|e| CliError::Invalid(format!("{}: not an MCAP recording: {e}", path.display())))?;
    let mut out = Vec::new();
    let mut truncated = false;
    for m in stream {
        match m {
            Ok(m) => out.push(Recorded {
                topic: m.channel.topic.clone(),
                log_time: m.log_time,
                data: m.data.into_owned(),
            }),
            Err(e) if out.is_empty() => {
                // Not one complete record: not a recording of ours (random bytes, another
                // format, or cut before its first message).
                return Err(CliError::Invalid(format!(
                    "{}: not an MCAP recording with any complete message: {e}",
                    path.display()
                )));
            }
            Err(_) => {
                // A killed recorder leaves a partial last record: what precedes it is kept.
                truncated = true;
                break;
            }
        }
    }
    Ok((out, truncated))
}

#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The recording (.mcap)
    file: PathBuf,
    /// Rig config (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Republish as fast as possible instead of in real time
    #[arg(long)]
    as_fast_as_possible: bool,
    /// Do not publish: run the estimator offline over the recorded samples and compare with the
    /// live estimates recorded beside them
    #[arg(long)]
    estimate: bool,
    /// With --estimate: one JSON object
    #[arg(long)]
    json: bool,
    /// With --estimate: compare only after this many seconds. Exact agreement needs the
    /// recording to start before the rig (the models' hysteresis remembers what it saw)
    #[arg(long, default_value_t = 0.0, value_name = "SECONDS")]
    settle: f64,
    /// Zenoh endpoints to republish on
    #[command(flatten)]
    net: NetArgs,
    /// Draw the recording in Rerun instead of republishing it
    #[command(flatten)]
    viz: crate::viz::VizArgs,
}

pub fn replay(a: &ReplayArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let (msgs, truncated) = read_all(&a.file)?;
    if truncated {
        eprintln!(
            "rig replay: {} ends in a partial record (recorder killed?); replaying its {} complete messages",
            a.file.display(),
            msgs.len()
        );
    }
    if a.estimate {
        return estimate_offline(&cfg, &msgs, a);
    }
    crate::viz::no_viewer_in_connect(&a.net)?;
    if let Some(sink) = a.viz.sink(&cfg, false)? {
        let viz = crate::viz::VizThread::start(&cfg, &sink)?;
        let tx = viz.sender();
        for m in &msgs {
            let _ = tx.send((m.topic.clone(), m.data.clone()));
        }
        drop(tx);
        let s = viz.finish()?;
        eprintln!(
            "rig replay: {} messages drawn ({} log calls after decimation, {} skipped)",
            s.messages, s.logged, s.skipped
        );
        return Ok(());
    }
    let rt = tokio_runtime(Some(2))?;
    rt.block_on(async {
        let session = open(&cfg.zenoh, &a.net.overrides()).await?;
        tokio::time::sleep(Duration::from_millis(500)).await;
        let t0 = msgs.first().map_or(0, |m| m.log_time);
        let start = tokio::time::Instant::now();
        for m in &msgs {
            if !a.as_fast_as_possible {
                tokio::time::sleep_until(
                    start + Duration::from_nanos(m.log_time.saturating_sub(t0)),
                )
                .await;
            }
            session
                .put(m.topic.as_str(), m.data.clone())
                .await
                .map_err(zenoh_err)?;
        }
        let _ = session.close().await;
        eprintln!("rig replay: {} messages republished", msgs.len());
        Ok(())
    })
}

fn estimate_offline(
    cfg: &rig_config::RigConfig,
    msgs: &[Recorded],
    a: &ReplayArgs,
) -> Result<(), CliError> {
    let mut core = EstimatorCore::new(cfg, CoreTiming::for_config(cfg))?;
    let ee_key = Keys::new(&cfg.name)?.ee_estimate();
    let mut live: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    let mut offline: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    let collect = |outs: Vec<Output>, offline: &mut BTreeMap<u64, (f64, f64)>| {
        for o in outs {
            if let Output::Ee(e) = o
                && let Some(f) = e.force_n
            {
                offline.insert(e.t_ns, f);
            }
        }
    };
    // Samples in acquisition order (the order the live core processes ticks in), each fed
    // at its acquisition time; the core's clock-driven checks run between them.
    let mut samples: Vec<JointSample> = Vec::new();
    let mut used: std::collections::BTreeSet<(u16, u64)> = std::collections::BTreeSet::new();
    for m in msgs {
        if m.topic.contains("/estimate/joint/") {
            if let Ok(e) = decode::<JointEstimate>(&m.data) {
                used.insert((e.joint, e.seq));
            }
        } else if m.topic == ee_key {
            if let Ok(e) = decode::<EeEstimate>(&m.data)
                && let Some(f) = e.force_n
            {
                live.insert(e.t_ns, f);
            }
        } else if m.topic.ends_with("/sample")
            && let Ok(s) = decode::<JointSample>(&m.data)
        {
            samples.push(s);
        }
    }
    samples.sort_by_key(|s| (s.t_acq_ns, s.joint));
    // Feed exactly what the live estimator used: the samples it made a joint estimate from
    // (it drops samples before its first complete tick and any that arrive too late). With
    // the same input in the same tick order, the same code gives the same estimates.
    if !used.is_empty() {
        samples.retain(|s| used.contains(&(s.joint, s.seq)));
    }
    let missing = used.len().saturating_sub(samples.len());
    if missing > 0 {
        let have: std::collections::BTreeSet<(u16, u64)> =
            samples.iter().map(|s| (s.joint, s.seq)).collect();
        let which: Vec<String> = used
            .difference(&have)
            .take(8)
            .map(|(j, q)| format!("joint {j} seq {q}"))
            .collect();
        eprintln!(
            "rig replay: {missing} samples the live estimator used are not in the recording (the recorder lost them): {}{}",
            which.join(", "),
            if missing > which.len() { ", …" } else { "" }
        );
    }
    let t0 = samples.first().map_or(0, |s| s.t_acq_ns);
    let mut next_tick = t0;
    for s in &samples {
        while s.t_acq_ns >= next_tick {
            collect(core.on_tick(next_tick), &mut offline);
            next_tick += 20_000_000;
        }
        collect(core.on_sample(*s, s.t_acq_ns), &mut offline);
    }
    let samples = samples.len();
    let settle_ns = t0 + (a.settle.max(0.0) * 1e9) as u64;
    let (mut matched, mut max_diff) = (0u64, 0.0_f64);
    for (t, f) in live.range(settle_ns..) {
        if let Some(g) = offline.get(t) {
            matched += 1;
            max_diff = max_diff.max((f.0 - g.0).hypot(f.1 - g.1));
        }
    }
    if a.json {
        println!(
            "{{\"samples\": {samples}, \"offline_ee_estimates\": {}, \"live_ee_estimates\": {}, \"matched\": {matched}, \"max_force_diff_n\": {max_diff:e}}}",
            offline.len(),
            live.len()
        );
    } else {
        println!(
            "offline estimator: {samples} samples → {} end-effector estimates",
            offline.len()
        );
        println!(
            "live estimates in the recording: {}; compared after {:.1} s: {matched}, largest force difference {max_diff:.3e} N",
            live.len(),
            a.settle
        );
    }
    Ok(())
}
