//! `rig identify`: close the loop with measured data — fit a declared model, trace its
//! residual to effects it lacks, add those that pay off on held-out data, and report the
//! error before and after (JSON, Markdown, PNG plots). The maths is
//! `rig_model::identify`; this edge reads files, draws and writes.

use std::path::{Path, PathBuf};

use clap::ValueEnum;
use rig_model::hysteresis::{Envelope, FitError};
use rig_model::identify::{
    Declared, Effect, Holdout, Identified, IdentifyError, Options, Place, Run, Tare, identify,
};
use serde_json::{Map, Value, json};

use crate::error::CliError;
use crate::identify_data::{ColumnMap, DataArgs, Layout, Sampling, read};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// Paper B's restoring-torque model (hysteresis from deflection alone): τ from φ and d
    Restoring,
    /// A linear spring with offset, τ = k·φ + c: the plainest start
    Linear,
    /// Paper A's link equation I·q̈ + N·q̇ = τ (columns t, q, tau: the net torque on the link)
    Link,
}

/// Find what a model lacks in measured data and report the error before and after.
///
/// Fits the declared model (--model) on --data, then tries a library of named effects —
/// hysteresis, coulomb_friction, viscous_friction, backlash, hard_stop, geometric_stiffness,
/// sensor_delay, offset, stiffness_drift, gravity, periodic_ripple — adding one at a time the
/// effect that lowers the error most on validation blocks of the fit data, while it lowers it
/// by at least --min-gain, and keeping it where the held-out data agrees (by more than noise
/// explains; beside another effect by --min-gain too). Every "before" and "after" figure is on
/// held-out data: the --holdout files, or else every fourth time block of each --data file (a
/// quarter).
///
/// Writes OUT.json, OUT.md (a summary) and OUT-fit.png, OUT-residual.png beside it.
///
/// Examples:
///   rig sim --scenario agents/sim/scenarios/lever-bench-friction.toml --out bench.csv
///   rig identify --data bench.csv --report bench-id.json
///   rig identify --model linear --columns t=time,phi=displacement:deg,tau=torque_out \
///       --data kt-9-1-70-5-….csv --holdout kt-9-2-71-5-….csv --report spring5.json
///   rig identify --model link --data awas.csv --report link.json
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    #[command(flatten)]
    data: DataArgs,
    /// The declared model to start from. Default, from what the data is: `restoring` for a
    /// VSA joint (the data has a pivot position — a `d` column, an MCAP recording — or
    /// --config/--apply names the joint: the model the estimator runs); `link` where the data
    /// has a link angle q and no deflection; otherwise `linear`, for a spring (t, φ, τ and no
    /// pivot), whose loop the `hysteresis` effect draws: on the measured torsion springs it
    /// does better than paper B's loop without a lever (docs/IDENTIFY.md)
    #[arg(long, value_enum)]
    model: Option<ModelArg>,
    /// Rig config: the joint's lever (--joint; else the first lever joint) makes
    /// geometric_stiffness a candidate, and the restoring model's loop is fitted with the
    /// envelope of the config's table (`envelope = "lever"`: the lever's curve), as the
    /// estimator will run it. --apply's config serves when this is not given
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Joint of an MCAP recording to identify (default: the first)
    #[arg(long, value_name = "NAME")]
    joint: Option<String>,
    /// Smallest relative drop of the validation RMSE that adds an effect, and of the held-out
    /// RMSE that keeps one beside another (an effect must also pass the information criterion
    /// on the residual's effective samples, and lower the held-out error by more than noise
    /// explains)
    #[arg(long, default_value_t = 0.05, value_name = "FRACTION")]
    min_gain: f64,
    /// Do not tare: by default each file's torque and deflection zeros are taken from the rest
    /// it starts with (at least 0.5 s still) and subtracted, in fit and held-out files alike
    #[arg(long)]
    no_tare: bool,
    /// Tare each file by its rest alone (its torque and deflection there are its zeros). By
    /// default, with the linear spring (`--model linear`), a rest is read as a state of the loop:
    /// the encoder's frame is kept from file to file (a file whose encoder was zeroed at its
    /// start is read from where the file before it ended unloaded: each --data file after the
    /// first from the one given before it, a held-out file from the last), the stop operators
    /// start where the rest puts them, and only what the loop cannot hold is a torque zero
    #[arg(long, conflicts_with = "no_tare")]
    rest_tare: bool,
    /// Keep the restoring model's envelope lines straight (paper B's) where no lever's geometry
    /// is given. By default lines that soften toward the ends, s(φ) = φ/√(1 + c·φ²), are tried
    /// as well — a lever swung far is up to a few tens of per cent softer at its ends than at
    /// rest — and kept where they lower the validation error by --min-gain and the held-out
    /// error by more than noise explains; the report says how much softer they are
    #[arg(long)]
    straight: bool,
    /// Half-window of the rates [ms]. Joint-torque models: the centred local quadratics'
    /// (default 20). Link equation: the half-support of the one smoother that the torque, q̇,
    /// q̈ and every effect's column all go through (the weak form: nothing is flattened, and
    /// the RMSEs reported are of the smoothed torque); default the narrowest of 10–320 at
    /// which the encoder's noise through I·q̈ is a tenth of the torque sensor's own
    #[arg(long, value_name = "MS")]
    rate_window_ms: Option<f64>,
    /// Where to write the JSON report (the .md and .png files go beside it)
    #[arg(long, value_name = "OUT.json")]
    report: PathBuf,
    /// Write what has a live form into CONFIG's `[joint.effects]` for --joint (in place,
    /// comments kept, validated first): the sensors' zeros (a zero that jumped: its level
    /// after the jump; the files' rest zeros when they were tared), backlash, a hard stop, a
    /// periodic ripple and a lag between the sensors (the estimator aligns the residual).
    /// Friction, drift, hysteresis, the lever's geometry and gravity are refused by name, with
    /// why. Needs --model restoring (the config's model) and --joint
    #[arg(long, value_name = "CONFIG", requires = "joint")]
    apply: Option<PathBuf>,
}

impl From<ModelArg> for Declared {
    fn from(m: ModelArg) -> Self {
        match m {
            ModelArg::Restoring => Declared::Restoring,
            ModelArg::Linear => Declared::Linear,
            ModelArg::Link => Declared::Link,
        }
    }
}

/// The declared model: `--model`, else what the data is (see [`Args::model`]), with why
/// when it was not given.
fn model_of(a: &Args, fit: &[Run]) -> (Declared, Option<&'static str>) {
    if let Some(m) = a.model {
        return (m.into(), None);
    }
    if a.config.is_some() || a.apply.is_some() {
        (
            Declared::Restoring,
            Some("the config names the joint: the model the estimator runs"),
        )
    } else if fit.iter().any(|r| r.d.is_some()) {
        (
            Declared::Restoring,
            Some("the data has a pivot position (d): a VSA joint, the model the estimator runs"),
        )
    } else if fit.iter().all(|r| r.phi.is_none() && r.q.is_some()) {
        (
            Declared::Link,
            Some("the data has a link angle (q) and no deflection"),
        )
    } else {
        (
            Declared::Linear,
            Some(
                "the data has no pivot position (d): a spring, whose loop the hysteresis effect \
                 draws; --model restoring fits paper B's loop instead",
            ),
        )
    }
}

pub fn run(a: &Args) -> Result<(), CliError> {
    if a.apply.is_some() && a.model.is_some_and(|m| m != ModelArg::Restoring) {
        return Err(CliError::Invalid(
            "--apply needs --model restoring: the live estimator runs the config's restoring-torque model".into(),
        ));
    }
    if !(a.min_gain.is_finite() && (0.0..1.0).contains(&a.min_gain)) {
        return Err(CliError::Invalid(format!(
            "--min-gain must be in [0, 1), got {}",
            a.min_gain
        )));
    }
    if let Some(w) = a.rate_window_ms
        && !(w.is_finite() && w > 0.0)
    {
        return Err(CliError::Invalid(format!(
            "--rate-window-ms must be > 0, got {w}"
        )));
    }
    // Checked before the fit: the report goes into a directory that exists (none is made).
    if let Some(dir) = a.report.parent().filter(|p| !p.as_os_str().is_empty())
        && !dir.is_dir()
    {
        return Err(CliError::Invalid(format!(
            "--report {}: the directory {} does not exist (create it first)",
            a.report.display(),
            dir.display()
        )));
    }
    let map = ColumnMap::parse(a.data.columns.as_deref())?;
    // The lever and the loop's envelope of the joint identified (--joint; else the config's
    // first lever joint), from --config or the config --apply writes to.
    let (lever, envelope) = match a.config.as_ref().or(a.apply.as_ref()) {
        Some(path) => {
            let cfg = rig_config::load(path)?;
            if let Some(name) = &a.joint
                && !cfg.joints.iter().any(|j| &j.name == name)
            {
                let names: Vec<&str> = cfg.joints.iter().map(|j| j.name.as_str()).collect();
                return Err(CliError::Invalid(format!(
                    "--joint {name}: {} has no joint of that name (its joints: {})",
                    path.display(),
                    names.join(", ")
                )));
            }
            cfg.joints
                .iter()
                .filter(|j| a.joint.as_ref().is_none_or(|name| &j.name == name))
                .find_map(|j| match &j.kind {
                    rig_config::JointKind::Lever { vsa, restoring, .. } => {
                        Some((Some(*vsa), restoring.envelope()))
                    }
                    _ => None,
                })
                .unwrap_or((None, Envelope::Linear))
        }
        None => (None, Envelope::Linear),
    };
    let load = |files: &[PathBuf]| -> Result<(Vec<Run>, Vec<Sampling>), CliError> {
        let mut runs = Vec::new();
        let mut smp = Vec::new();
        for f in files {
            let (r, s) = read(f, &map, a.joint.as_deref())?;
            runs.push(r);
            smp.push(s);
        }
        Ok((runs, smp))
    };
    let (fit_runs, mut sampling) = load(&a.data.data)?;
    let (held_runs, held_sampling) = load(&a.data.holdout)?;
    sampling.extend(held_sampling);
    let (declared, chosen) = model_of(a, &fit_runs);
    if let Some(why) = chosen {
        eprintln!("rig identify: model {}: {why}", declared.name());
    }
    for s in &sampling {
        if let Some(note) = s.layout.as_ref().and_then(Layout::note) {
            eprintln!("rig identify: {}: read as {note}", s.file);
        }
        let dropped: usize = s.missing.values().sum::<usize>() + s.time_not_increasing;
        if dropped > 0 || s.irregular || s.gaps > 0 {
            eprintln!(
                "rig identify: {}: {} of {} rows used ({} missing values, {} out of order); sampling {:.1} Hz median, step p99 {:.1} ms, {} gaps{}",
                s.file,
                s.used,
                s.rows,
                s.missing.values().sum::<usize>(),
                s.time_not_increasing,
                1.0 / s.dt_median_s,
                s.dt_p99_s * 1e3,
                s.gaps,
                if s.irregular { " (irregular)" } else { "" }
            );
        }
    }
    let opts = Options {
        model: declared,
        lever,
        envelope,
        min_gain: a.min_gain,
        rate_window: a.rate_window_ms.map(|w| w * 1e-3),
        tare: !a.no_tare,
        loop_states: !a.rest_tare,
        soften: !a.straight,
        ..Options::default()
    };
    let holdout = if held_runs.is_empty() {
        Holdout::Blocks
    } else {
        Holdout::Runs(&held_runs)
    };
    let pb = crate::progress::bar(1, "identify: candidate fits");
    let res = identify(&fit_runs, holdout, &opts, &mut |done, total| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    })
    .map_err(|e| match e {
        // The library says why the loop found no spring; what fits such a spring is this
        // command's to say.
        IdentifyError::Restoring(FitError::NotASpring { .. }) => CliError::Invalid(format!(
            "{e}. A spring without a lever is fitted with `--model linear` (a spring with offset)"
        )),
        e => e.into(),
    })?;
    pb.finish_and_clear();

    let mut notes = notes(&res, &fit_runs, &held_runs);
    if let Some(why) = chosen {
        notes.push(format!("model {} (no --model): {why}", declared.name()));
    }
    let curved = matches!(envelope, Envelope::Lever(_)) && declared == Declared::Restoring;
    if curved {
        notes.push("the restoring loop's envelope follows the lever's curve, as the config's table does (envelope = \"lever\"): its k is the stiffness at rest".into());
    }
    let mut report = report_json(a, &res, &sampling, &notes, held_runs.is_empty());
    if declared == Declared::Restoring {
        report["loop_dead_band_rad"] = num(res.loop_dead_band);
        report["envelope"] = json!(if curved {
            "lever"
        } else if res.softening.is_some() {
            "softening"
        } else {
            "linear"
        });
    }
    std::fs::write(
        &a.report,
        serde_json::to_string_pretty(&report).unwrap_or_default(),
    )?;
    let (md, fit_png, res_png) = (
        a.report.with_extension("md"),
        sibling(&a.report, "-fit.png"),
        sibling(&a.report, "-residual.png"),
    );
    crate::identify_plots::fit(&fit_png, &res).map_err(CliError::Invalid)?;
    crate::identify_plots::residual(&res_png, &res).map_err(CliError::Invalid)?;
    std::fs::write(&md, markdown(a, &res, &notes, &fit_png, &res_png))?;
    print_summary(&res, &notes);
    eprintln!(
        "rig identify: wrote {}, {}, {}, {}",
        a.report.display(),
        md.display(),
        fit_png.display(),
        res_png.display()
    );
    if let (Some(config), Some(joint)) = (&a.apply, &a.joint) {
        apply(&res, config, joint)?;
    }
    Ok(())
}

/// `[joint.effects]` keys and values in lab units, in the order written.
fn live_fields(a: &rig_model::live::Applied) -> Vec<(&'static str, f64)> {
    let e = &a.effects;
    let mut f = vec![
        ("torque_offset_nm", a.torque_offset_nm),
        ("encoder_offset_deg", a.encoder_offset_rad.to_degrees()),
    ];
    if e.backlash_half_width_rad > 0.0 {
        f.push((
            "backlash_half_width_deg",
            e.backlash_half_width_rad.to_degrees(),
        ));
    }
    if let Some(s) = &e.stop {
        if s.rate_nm_per_rad > 0.0 {
            f.push(("stop_onset_deg", s.onset_rad.to_degrees()));
            f.push(("stop_rate_nm_per_rad", s.rate_nm_per_rad));
        }
        if s.rate_negative_nm_per_rad > 0.0 {
            f.push(("stop_onset_negative_deg", s.onset_negative_rad.to_degrees()));
            f.push(("stop_rate_negative_nm_per_rad", s.rate_negative_nm_per_rad));
        }
    }
    if let Some(r) = &e.ripple {
        f.push(("ripple_amplitude_nm", r.amplitude_nm));
        f.push(("ripple_period_deg", r.period_rad.to_degrees()));
        f.push(("ripple_phase_deg", r.phase_rad.to_degrees()));
    }
    if e.torque_lag_s != 0.0 {
        f.push(("torque_lag_ms", e.torque_lag_s * 1e3));
    }
    f
}

/// `--apply`: writes the live effects into `config`'s `[joint.effects]` of `joint`.
fn apply(res: &Identified, config: &Path, joint: &str) -> Result<(), CliError> {
    let live = rig_model::live::from_found(&res.effects, &res.tare);
    for (place, at) in &live.jumps {
        eprintln!(
            "rig identify --apply: the {} zero jumped {at:.1} s into the run; its level after the jump is applied",
            match place {
                Place::Deflection => "encoder's",
                Place::Torque => "torque sensor's",
            }
        );
    }
    for (e, why) in &live.refused {
        eprintln!("rig identify --apply: refused {}: {why}", e.name());
    }
    // Six significant digits: the config keeps what the fit resolved, not its noise.
    let round = |v: f64| -> f64 {
        if v == 0.0 || !v.is_finite() {
            return 0.0;
        }
        let digits = 5 - v.abs().log10().floor() as i32;
        (v * 10f64.powi(digits)).round() / 10f64.powi(digits)
    };
    let fields: Vec<(&str, f64)> = live_fields(&live)
        .into_iter()
        .map(|(k, v)| (k, round(v)))
        .collect();
    let mut doc = crate::config_edit::open(config)?;
    let t = crate::config_edit::joint(&mut doc, joint)?;
    let effects = t
        .entry("effects")
        .or_insert_with(|| toml_edit::Item::Table(toml_edit::Table::new()))
        .as_table_mut()
        .ok_or_else(|| {
            CliError::Invalid(format!(
                "{}: joint {joint:?}'s `effects` is not a table",
                config.display()
            ))
        })?;
    // A new identification replaces the section: every key it may hold is --apply's (the
    // config refuses any other).
    effects.clear();
    for (key, v) in &fields {
        effects[*key] = toml_edit::value(*v);
    }
    effects.decor_mut().set_prefix(format!(
        "# Identified by `rig identify --apply` (held-out RMSE {:.4} → {:.4} N·m): the estimator\n# takes the sensor zeros off each sample and runs the rest with the joint's model.\n",
        res.before.rmse, res.after.rmse
    ));
    crate::config_edit::write_validated(config, &doc.to_string())?;
    let written: Vec<String> = fields.iter().map(|(k, v)| format!("{k} = {v}")).collect();
    println!(
        "applied to joint {joint} in {}: {}{}",
        config.display(),
        written.join(", "),
        if live.refused.is_empty() {
            String::new()
        } else {
            format!("; refused: {}", live.refused.len())
        }
    );
    Ok(())
}

/// `dir/stem` + `suffix`.
fn sibling(p: &Path, suffix: &str) -> PathBuf {
    let stem = p
        .file_stem()
        .map_or_else(|| "report".into(), |s| s.to_string_lossy().into_owned());
    p.with_file_name(format!("{stem}{suffix}"))
}

/// Honest remarks on the data: offsets that differ between runs, lags, stick-slip steps.
fn notes(res: &Identified, fit: &[Run], held: &[Run]) -> Vec<String> {
    let mut n = Vec::new();
    if res.model == Declared::Restoring
        && let Some(c) = named(&res.base_before, "offset_nm")
    {
        n.push(format!(
            "before: the loop's lines pass through zero and could not reach the data as given (a deflection read far from its zero: an encoder never re-zeroed), so the loop is fitted beside a torque constant, {c:+.3} N·m, as the linear spring's offset"
        ));
    }
    let peak = res
        .heldout
        .measured
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    for (run, b) in &res.bias {
        if b.abs() > 0.3 * res.after.rmse && b.abs() > 0.01 * peak {
            n.push(format!(
                "offset: on {run} the model is off by {b:+.3} N·m on average ({:.0} % of the held-out RMSE) — the torque or deflection zero differs from the fit data's",
                100.0 * b.abs() / res.after.rmse
            ));
        }
    }
    if let Some(d) = res.effects.iter().find(|e| e.effect == Effect::SensorDelay) {
        let delay = d.params.first().map_or(0.0, |p| p.1);
        let x = if res.model == Declared::Link {
            "angle"
        } else {
            "deflection"
        };
        let mut note = if delay >= 0.0 {
            format!("lag: the torque lags the {x} by {:.1} ms", delay * 1e3)
        } else {
            format!("lag: the {x} lags the torque by {:.1} ms", -delay * 1e3)
        };
        if d.at_search_bound() {
            note.push_str(
                " — the bound of the lags searched: the error still falls there, so the lag is not located (the real one may be shorter; on the link equation an encoder's noise pulls it out); `--apply` leaves the rig's timing as it is",
            );
        }
        if let Some(lr) = d.param(rig_model::identify::NAMED_ON_HELD_OUT) {
            note.push_str(&format!(
                " — named on the held-out data's evidence: on the fit data it lowered the validation error by {:.1} % only, under --min-gain, for a lag of the link equation is to first order a change of inertia and shows only where the acceleration changes (the few corners of moves between holds); the held-out data confirmed it (likelihood ratio {lr:.1}, over χ²₁'s 1 % point) and lost more than --min-gain of its error with it, so the error after is not independent of this choice; fit on a motion whose acceleration changes all the time (a chirp, a multi-sine) to name it from the fit data alone",
                100.0 * d.validation_gain,
            ));
        }
        n.push(note);
    }
    if let Some((d, lr)) = (res.effects.iter())
        .filter(|e| e.effect == Effect::Offset)
        .find_map(|e| Some((e, e.param(rig_model::identify::NAMED_ON_HELD_OUT)?)))
    {
        n.push(format!(
            "slip: the encoder's jump at {:.3} s was named on the held-out data's evidence: on the fit data the loop kept (the better of two starts) held the jump as well as the other start's loop with it (validation {:+.1} %), for a loop with memory can carry a jump through one run's motion; with it the fit rows fit better by the criterion, and the held-out data confirmed it (likelihood ratio {lr:.1}, over χ²₁'s 1 % point) and lost more than --min-gain of its error, so the error after is not independent of this choice; a second held-out test, or a fit run of another motion, would tell from the fit data alone",
            d.param("jump_at_s").unwrap_or(f64::NAN),
            100.0 * d.validation_gain,
        ));
    }
    for e in &res.effects {
        let Some((from, to)) = e.held_out_block() else {
            continue;
        };
        n.push(format!(
            "jump: the {}'s jump lies in the held-out block {from:.2}–{to:.2} s, where the fit rows cannot place it; it is put at the block's middle, {:.2} s, and the held-out error counts that block with the instant unknown (hold out a second test, --holdout, to place it)",
            e.effect.name(),
            0.5 * (from + to)
        ));
    }
    if let Some(note) = mild_stop(res) {
        n.push(note);
    }
    for r in fit.iter().chain(held) {
        let steps = rig_model::identify::signals::steps(&r.tau);
        if steps > 0 {
            n.push(format!(
                "steps: {steps} sudden jumps of the torque in {} (over 10× the 90th percentile of its sample-to-sample change: stick-slip, or sensor glitches)",
                r.name
            ));
        }
    }
    // A fit at one speed cannot tell a torque in proportion to the rate from dry friction.
    let joint = res.model.is_joint();
    let fit_motion = fit.iter().filter_map(|r| {
        let x = if joint {
            r.phi.as_deref()
        } else {
            r.q.as_deref()
        };
        x.map(|x| (&r.t[..], x))
    });
    if let Some((lo, hi)) = rig_model::identify::signals::speeds(fit_motion, SPEED_SPAN_S)
        .filter(|(lo, hi)| *hi < 1.25 * *lo)
    {
        let rate_named = res.effects.iter().any(|e| {
            matches!(
                e.effect,
                Effect::ViscousFriction | Effect::SensorDelay | Effect::CoulombFriction
            )
        });
        n.push(format!(
            "speed: the fit data move at one speed ({} to {} rad/s over most of their motion, a triangle wave's): a torque in proportion to the rate (viscous friction, a lag) is a constant height on each stroke there, the shape of dry friction and of the loop, so the fit cannot tell them apart{}; fit on a test at several speeds (a chirp, a multi-sine, ramps of different lengths)",
            sig(lo),
            sig(hi),
            if rate_named {
                " (what was named of them may be another of them)"
            } else {
                ""
            }
        ));
    }
    for s in &res.residual.structure {
        n.push(format!("residual: {s}"));
    }
    n
}

/// A stop's added stiffness under this share of the spring's own is said to be mild: a
/// contact (an end stop, parts meeting) is a stiff part in parallel and adds about the
/// spring's stiffness or more (the generators' stops 4–6.8×), while a progressive or
/// asymmetric spring, or a sensor's nonlinearity, changes the slope by a few to a few tens of
/// per cent (the measured torsion springs' "stops": 3.7–31 %).
const MILD_STOP_SHARE: f64 = 0.5;

/// The spring's own stiffness as the report's base gives it [N·m/rad]: the linear spring's,
/// or the restoring loop's at rest times its scale; `None` for the link equation or a loop
/// without a curve.
fn spring_stiffness(res: &Identified) -> Option<f64> {
    let get = |name| named(&res.base_after, name);
    let k = get("stiffness_nm_per_rad")? * get("scale").unwrap_or(1.0);
    (k.is_finite() && k > 0.0).then_some(k)
}

/// The parameter called `name` among a declared model's `params` (the report's `base`).
fn named(params: &[(&'static str, f64)], name: &str) -> Option<f64> {
    params.iter().find(|(k, _)| *k == name).map(|&(_, v)| v)
}

/// A note where a named `hard_stop` stiffens the joint by less than [`MILD_STOP_SHARE`] of
/// the spring's own stiffness on a side: a torque–deflection test shows a slope that changes
/// past a deflection, and a change that small is as likely the spring's own as a contact.
fn mild_stop(res: &Identified) -> Option<String> {
    let stop = res.effects.iter().find(|e| e.effect == Effect::HardStop)?;
    let k = spring_stiffness(res)?;
    let sides: Vec<String> = [
        ("onset_rad", "stop_rate_nm_per_rad"),
        ("onset_negative_rad", "stop_rate_negative_nm_per_rad"),
    ]
    .iter()
    .filter_map(|(at, rate)| Some((stop.param(at)?, stop.param(rate)?)))
    .filter(|&(_, rate)| rate > 0.0 && rate < MILD_STOP_SHARE * k)
    .map(|(at, rate)| {
        format!(
            "beyond {:+.2} mrad by {} N·m/rad ({:.1} %)",
            at * 1e3,
            sig(rate),
            100.0 * rate / k,
        )
    })
    .collect();
    (!sides.is_empty()).then(|| {
        format!(
            "stop: the hard_stop stiffens the joint {} of the spring's {} N·m/rad — a contact (an end stop, parts meeting) adds about the spring's stiffness or more; a change this mild may as well be the spring's own slope changing with its deflection (a progressive or asymmetric spring, or the sensor's nonlinearity): look for a contact at that deflection before acting on the name",
            sides.join(" and "),
            sig(k)
        )
    })
}

/// The span the rate is read over for `signals::speeds`: a count of a 14-bit encoder is
/// 0.008 rad/s over it, and a triangle wave's turn at 0.5 Hz blurs 5 % of its samples.
const SPEED_SPAN_S: f64 = 0.05;

/// An effect's parameters; an offset's sensor as `on`.
fn effect_params_json(e: &rig_model::identify::Found) -> Value {
    let mut v = params_json(&e.params);
    if let (Some(on), Value::Object(m)) = (e.on, &mut v) {
        m.insert("on".into(), Value::String(on.name().into()));
    }
    v
}

/// The deflection's measured noise and what the joint models do with it.
fn noise_line(res: &Identified) -> String {
    let noise = sig(res.angle_noise * 1e6);
    if res.smoothing.is_empty() {
        return format!(
            "encoder noise: {noise} µrad rms as measured, within a third of the dead band \
             ({} µrad): the deflection is used as measured",
            sig(res.dead_band * 1e6)
        );
    }
    let windows: Vec<String> = res
        .smoothing
        .iter()
        .map(|(run, h)| match *h > 0.0 {
            true => format!("{run} ±{:.1} ms", h * 1e3),
            false => format!(
                "{run} as measured (even five samples would smooth away motion or jumps, not only noise)"
            ),
        })
        .collect();
    format!(
        "encoder noise: {noise} µrad rms as measured, averaged out by a local quadratic, each \
         sample's as wide as the motion around it allows (half-window, median: {}); \
         the joint model and its effects see that deflection, the \"before\" the raw one",
        windows.join(", ")
    )
}

/// How a file's rest compares with the first file's, and what the rest was read as (a state
/// of the loop where the model has one: `Tare::loop_state`).
fn zeros_why(t: &Tare) -> String {
    let mut against = against_first(t);
    if let Some(file) = &t.read_after {
        against.push_str(&format!(
            "; its encoder zeroed at its start, read from where {file} ended unloaded"
        ));
    }
    if t.frame_at_rest {
        against.push_str(
            "; its deflection read from its own rest, put where the first file's rest is: its zero moved between the tests (this predicts it better than the frame it was given)",
        );
    }
    if let Some(z) = t.zero_not_taken {
        against.push_str(&format!(
            "; the {} N·m its rest read not taken for a zero: the file as measured fits better (its rest was loaded, or its zero moved again within the test)",
            sig(z)
        ));
    }
    match t.loop_state {
        Some(lam) => format!(
            "{against}; read as a state of the loop: its stops start at {lam:+.2} of their half-widths"
        ),
        None => against,
    }
}

fn against_first(t: &Tare) -> String {
    if t.rest_shift_nm == 0.0 {
        "the reference".into()
    } else if t.within_loop {
        format!(
            "rest {} N·m off the first file's, within the loop it traced there: friction may hold the spring there, part of this may be load",
            sig(t.rest_shift_nm)
        )
    } else if t.loop_state.is_some_and(|lam| lam.abs() < 1.0) {
        // The first file never passed there unloaded, but the fitted loop (its widest stops)
        // reaches that rest: a state it holds, not a zero.
        format!(
            "rest {} N·m off the first file's as a linear spring reads it, outside the loop the first file traced there, but within the fitted loop's reach",
            sig(t.rest_shift_nm)
        )
    } else {
        format!(
            "rest {} N·m off the first file's, outside its loop there: a zero moved",
            sig(t.rest_shift_nm)
        )
    }
}

/// The tare per file: the rest it found and the zeros subtracted.
fn tare_json(res: &Identified, off: bool) -> Value {
    if off {
        return json!("off (--no-tare)");
    }
    if res.model == Declared::Link {
        return json!("not applied: the link equation's torque at rest is gravity's");
    }
    if let Some(note) = &res.tare_note {
        return json!(note);
    }
    Value::Array(
        res.tare
            .iter()
            .map(|t| {
                json!({
                    "file": t.run,
                    "from_s": num(t.from_s),
                    "window_s": num(t.window_s),
                    "torque_zero": num(t.torque_zero),
                    "deflection_zero": num(t.deflection_zero),
                    "torque_noise": num(t.torque_noise),
                    "rest_shift_nm": num(t.rest_shift_nm),
                    "within_loop": t.within_loop,
                    "loop_state": t.loop_state.map_or(Value::Null, num),
                    "read_after": t.read_after,
                    "frame_at_rest": t.frame_at_rest,
                    "zero_not_taken_nm": t.zero_not_taken.map_or(Value::Null, num),
                })
            })
            .collect(),
    )
}

fn params_json(p: &[(&str, f64)]) -> Value {
    Value::Object(
        p.iter()
            .map(|(k, v)| (k.to_string(), num(*v)))
            .collect::<Map<String, Value>>(),
    )
}

/// A JSON number, or null when not finite.
fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

fn report_json(
    a: &Args,
    res: &Identified,
    sampling: &[Sampling],
    notes: &[String],
    blocks: bool,
) -> Value {
    let errors = |e: &rig_model::identify::Errors| json!({"rmse": num(e.rmse), "mae": num(e.mae)});
    let holdout = if blocks {
        json!({"fraction": num(res.holdout_samples as f64 / (res.holdout_samples + res.fit_samples) as f64), "scheme": "every fourth of 12 time blocks per file"})
    } else {
        json!({"files": a.data.holdout.iter().map(|p| p.display().to_string()).collect::<Vec<_>>()})
    };
    let mut v = json!({
        "model": res.model.name(),
        "declared_effects": res.model.declares().iter().map(|e| e.name()).collect::<Vec<_>>(),
        "samples": res.fit_samples + res.holdout_samples,
        "fit_samples": res.fit_samples,
        "holdout_samples": res.holdout_samples,
        "data": a.data.data.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "holdout": holdout,
        "before": errors(&res.before),
        "after": errors(&res.after),
        "base": {"before": params_json(&res.base_before), "after": params_json(&res.base_after)},
        "tared": errors(&res.tared),
        "tare": tare_json(res, a.no_tare),
        "softening": res.softening.map(|b| json!({
            "c_per_rad2": num(b.c),
            "x_max_rad": num(b.x_max),
            "softer_at_x_max": num(b.softer),
            "validation_gain": num(b.validation_gain),
            "held_out_rmse_straight": num(b.held_out.0),
            "held_out_rmse_softened": num(b.held_out.1),
        })),
        "effects": res.effects.iter().map(|e| json!({
            "name": e.effect.name(),
            "params": effect_params_json(e),
            "gain_rmse": num(e.gain_rmse),
            "validation_gain": num(e.validation_gain),
            "meaning": e.effect.meaning(),
            "held_out_at_s": e.held_out_at_s.iter().map(|(file, at)| json!({"file": file, "at_s": at.map(num)})).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "refused": res.refused.iter().map(|r| json!({"name": r.effect.name(), "best_validation_gain": num(r.best_gain), "why": r.why})).collect::<Vec<_>>(),
        "not_applicable": res.not_applicable.iter().map(|(e, why)| json!({"name": e.name(), "why": why})).collect::<Vec<_>>(),
        "residual": {
            "white": res.residual.white,
            "max_autocorr": num(res.residual.max_autocorr),
            "max_autocorr_lag_s": num(res.residual.max_autocorr_lag_s),
            "band": num(res.residual.band),
            "lags": res.residual.lags,
            "cross": res.residual.cross.iter().map(|c| json!({"input": c.input, "max_abs": num(c.max_abs), "lag_s": num(c.lag_s)})).collect::<Vec<_>>(),
            "loop_before": num(res.residual.loop_before),
            "loop_after": num(res.residual.loop_after),
            "bend": res.residual.bend.map(|b| json!({"share": num(b.share), "x_max_rad": num(b.x_max), "stiffness_change": num(b.change)})),
            "structure": res.residual.structure,
        },
        "bias": res.bias.iter().map(|(r, b)| json!({"run": r, "mean_residual_nm": num(*b)})).collect::<Vec<_>>(),
        "sampling": sampling,
        "dead_band_rad": num(res.dead_band),
        "angle_noise_rad": num(res.angle_noise),
        "smoothing": res.smoothing.iter().map(|(run, h)| json!({"run": run, "half_window_s": num(*h)})).collect::<Vec<_>>(),
        "rate_window_s": num(res.rate_window),
        "min_gain": num(a.min_gain),
        "notes": notes,
    });
    if res.model == Declared::Link {
        let get = |k| named(&res.base_after, k).unwrap_or(f64::NAN);
        v["inertia"] = num(get("inertia_kgm2"));
        v["weak_form"] = json!({
            "half_support_s": num(res.rate_window),
            "rmse_of": "the torque through the smoother",
            "angle_read_as_taut_string": res.strung,
            // Widened from the noise rule's for q̈ alone, where a filter on the angle was then
            // named (its undoing carries the counts' noise through T·q⃛).
            "widened_from_s": res.widened_from.map(|w| num(w.0)),
            "widened_for_angle_lag_s": res.widened_from.map(|w| num(w.1)),
        });
        v["damping"] = num(get("damping_nms_per_rad"));
    }
    v
}

fn effect_line(e: &rig_model::identify::Found) -> String {
    let p: Vec<String> = e
        .params
        .iter()
        .map(|(k, v)| format!("{k} = {}", sig(*v)))
        .collect();
    let on =
        e.on.map_or(String::new(), |o| format!(" on the {}", o.name()));
    // A jump's instant in each held-out file, read from that file.
    let held: String = e
        .held_out_at_s
        .iter()
        .map(|(file, at)| match at {
            Some(t) => format!("; in the held-out {file} at {} s", sig(*t)),
            None => format!("; none in the held-out {file}"),
        })
        .collect();
    format!(
        "{}{on} ({}){held}: held-out RMSE lower by {} N·m",
        e.effect.name(),
        p.join(", "),
        sig(e.gain_rmse)
    )
}

/// Four significant digits.
fn sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    if !(-3..5).contains(&mag) {
        format!("{v:.3e}")
    } else {
        format!("{:.*}", (3 - mag).max(0) as usize, v)
    }
}

/// What the link equation's RMSEs are of (the weak form).
fn weak_form_line(res: &Identified) -> String {
    let strung = if res.strung.is_empty() {
        String::new()
    } else {
        format!(
            "; the quantised angle of {} read as the taut string through its counts",
            res.strung.join(", ")
        )
    };
    let widened = res.widened_from.map_or(String::new(), |(from, tc)| {
        format!(
            " (widened from {} ms: a first selection found the angle lagging by {} ms, and a first-order filter undone carries the counts' noise through T·q⃛)",
            sig(from * 1e3),
            sig(tc * 1e3)
        )
    });
    format!(
        "link equation in weak form: the torque, q̇, q̈ and every effect through one smoother of half-support {} ms{widened}; the RMSEs are of the smoothed torque{strung}",
        sig(res.rate_window * 1e3)
    )
}

/// The declared loop's lines bent toward the ends (no lever's geometry given), if they were.
fn softening_line(res: &Identified) -> Option<String> {
    res.softening.map(|b| {
        format!(
            "declared loop's lines bent: {:.0} % softer at ±{:.3} rad than at rest, s(φ) = φ/√(1 + {}·φ²) (held-out RMSE {} → {} N·m; validation {:.0} % better than straight lines) — a lever's geometry given by --config follows the lever itself; --straight keeps paper B's lines",
            100.0 * b.softer,
            b.x_max,
            sig(b.c),
            sig(b.held_out.0),
            sig(b.held_out.1),
            100.0 * b.validation_gain
        )
    })
}

fn print_summary(res: &Identified, notes: &[String]) {
    println!(
        "model {}: held-out RMSE {} → {} N·m, MAE {} → {} N·m ({} fit, {} held-out samples)",
        res.model.name(),
        sig(res.before.rmse),
        sig(res.after.rmse),
        sig(res.before.mae),
        sig(res.after.mae),
        res.fit_samples,
        res.holdout_samples
    );
    if res.model == Declared::Link {
        println!("  {}", weak_form_line(res));
    }
    for t in &res.tare {
        println!(
            "  tare: {} at rest for {:.1} s from {:.2} s: torque zero {} N·m, deflection zero {} rad ({})",
            t.run,
            t.window_s,
            t.from_s,
            sig(t.torque_zero),
            sig(t.deflection_zero),
            zeros_why(t)
        );
    }
    if let Some(note) = &res.tare_note {
        println!("  tare: {note}");
    }
    if let Some(line) = softening_line(res) {
        println!("  {line}");
    }
    if res.model.is_joint() {
        println!("  {}", noise_line(res));
    }
    if !res.tare.is_empty() {
        println!("  tared: held-out RMSE {} N·m", sig(res.tared.rmse));
    }
    if res.effects.is_empty() {
        println!("no effect added: none paid off beyond what noise explains");
    }
    for e in &res.effects {
        println!("  + {}", effect_line(e));
    }
    for n in notes {
        println!("  note: {n}");
    }
}

fn markdown(
    a: &Args,
    res: &Identified,
    notes: &[String],
    fit_png: &Path,
    res_png: &Path,
) -> String {
    let name = |p: &Path| {
        p.file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    };
    let mut s = String::new();
    s.push_str(&format!(
        "# rig identify — declared model `{}`\n\n",
        res.model.name()
    ));
    s.push_str(&format!(
        "Fit on {}; held out: {}.\n\n",
        a.data
            .data
            .iter()
            .map(|p| format!("`{}`", name(p)))
            .collect::<Vec<_>>()
            .join(", "),
        if a.data.holdout.is_empty() {
            format!(
                "every fourth time block ({:.0} % of the samples)",
                100.0 * res.holdout_samples as f64 / (res.holdout_samples + res.fit_samples) as f64
            )
        } else {
            a.data
                .holdout
                .iter()
                .map(|p| format!("`{}`", name(p)))
                .collect::<Vec<_>>()
                .join(", ")
        }
    ));
    if res.model == Declared::Link {
        s.push_str(&format!("{}.\n\n", weak_form_line(res)));
    }
    s.push_str("| held-out | RMSE [N·m] | MAE [N·m] |\n|---|---|---|\n");
    s.push_str(&format!(
        "| before | {} | {} |\n| after | {} | {} |\n\n",
        sig(res.before.rmse),
        sig(res.before.mae),
        sig(res.after.rmse),
        sig(res.after.mae)
    ));
    if !res.tare.is_empty() {
        s.push_str("## Tare (zeros from each file's rest, subtracted)\n\n| file | rest from [s] | rest for [s] | torque zero [N·m] | deflection zero [rad] | rest against the first file |\n|---|---|---|---|---|---|\n");
        for t in &res.tare {
            s.push_str(&format!(
                "| `{}` | {:.2} | {:.1} | {} | {} | {} |\n",
                t.run,
                t.from_s,
                t.window_s,
                sig(t.torque_zero),
                sig(t.deflection_zero),
                zeros_why(t)
            ));
        }
        s.push_str(&format!(
            "\nHeld-out RMSE after the tare: {} N·m.\n\n",
            sig(res.tared.rmse)
        ));
    }
    if let Some(note) = res.tare_note.as_ref().filter(|_| res.tare.is_empty()) {
        s.push_str(&format!("## Tare\n\n{note}.\n\n"));
    }
    if let Some(line) = softening_line(res) {
        s.push_str(&format!("{line}.\n\n"));
    }
    if res.model.is_joint() {
        s.push_str(&format!(
            "{}; held-out RMSE then {} N·m.\n\n",
            noise_line(res),
            sig(res.tared.rmse)
        ));
    }
    s.push_str("## Effects added\n\n");
    if res.effects.is_empty() {
        s.push_str("None: no candidate lowered the validation error by the required fraction.\n");
    }
    for e in &res.effects {
        s.push_str(&format!("- {} — {}\n", effect_line(e), e.effect.meaning()));
    }
    s.push_str("\n## Refused (best relative validation gain)\n\n");
    for r in &res.refused {
        s.push_str(&format!(
            "- {}: {:+.1} % — {}\n",
            r.effect.name(),
            100.0 * r.best_gain,
            r.why
        ));
    }
    for (e, why) in &res.not_applicable {
        s.push_str(&format!("- {}: not tried — {why}\n", e.name()));
    }
    s.push_str(&format!(
        "\n## Residual (held out, after)\n\nWhite: {} (largest autocorrelation {:.3} at {:.3} s; band ±{:.3} over {} lags).\n\n",
        if res.residual.white { "yes" } else { "no" },
        res.residual.max_autocorr,
        res.residual.max_autocorr_lag_s,
        res.residual.band,
        res.residual.lags
    ));
    for c in &res.residual.cross {
        s.push_str(&format!(
            "- cross-correlation with the {}: {:.3} at {:+.3} s\n",
            c.input, c.max_abs, c.lag_s
        ));
    }
    if !notes.is_empty() {
        s.push_str("\n## Notes\n\n");
        for n in notes {
            s.push_str(&format!("- {n}\n"));
        }
    }
    s.push_str(&format!(
        "\n![measured vs model]({})\n\n![residual]({})\n",
        name(fit_png),
        name(res_png)
    ));
    s
}
