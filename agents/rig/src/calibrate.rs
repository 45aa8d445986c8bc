//! `rig calibrate`: fit a joint's restoring-torque table (paper B eq. 7 at each pivot position
//! the data holds, smooth in d) from bench data with a torque reference, compare it with the
//! config's table on held-out data, and write it into the config keeping its comments.
//!
//! The fit is `rig_model::hysteresis::fit_restoring`; the table a config holds is
//! `[[joint.restoring.point]]` (`d_mm`, `k_nm_per_rad`, `h_nm`, `a_s`, `n`). Pivot positions the
//! data does not cover keep the config's points, and the report names them: nothing is
//! extrapolated silently. The joint's `[joint.effects]` stay outside the table: the sensor
//! zeros are taken off, the deflection delayed by a torque lag and passed through a gap, a
//! stop's and a ripple's torque taken off, and both tables are scored as the estimator runs
//! them (`rig_model::live`).

use std::path::{Path, PathBuf};

use rig_config::{JointKind, RigConfig};
use rig_model::hysteresis::{
    Envelope, FitOptions, FitSample, RestoringCurve, RestoringParams, RestoringTorqueModel,
    fit_restoring,
};
use rig_model::identify::Run;
use rig_model::live::LiveJoint;
use serde_json::json;

use crate::error::CliError;
use crate::identify_data::{ColumnMap, DataArgs, read};

/// A fitted point replaces the config's points closer than this [m] (half the examples'
/// 2.25 mm spacing would merge neighbours; a pivot read back within a count is far closer).
const SAME_PIVOT_M: f64 = 0.5e-3;

/// Fit a joint's restoring-torque table from bench data with a torque reference.
///
/// Reads --data (CSV with a header row and --columns, or a `rig record` MCAP of the joint),
/// fits paper B's eq. 7 at each pivot position in it (samples within 0.1 mm are one
/// position; each needs the deflection to move both ways), and merges the fitted points into
/// the joint's table: a fitted point replaces the config's points within 0.5 mm, the others are
/// kept and listed. Prints the torque RMSE of the config's table and of the new one on the
/// --holdout files (each replayed from a virgin state), or on the fit data when none is given.
///
/// Without --write or --out nothing is written. --write updates the config in place (its
/// comments and layout kept; the new file is validated before it replaces the old); --out
/// writes the updated copy elsewhere.
///
/// Examples:
///   rig sim --scenario agents/sim/scenarios/lever-bench.toml --out fit.csv
///   rig calibrate --config rig-config/examples/bench.toml --joint j1 --data fit.csv \
///       --holdout held.csv --out bench-calibrated.toml
///   rig record --config bench.toml --connect tcp/127.0.0.1:7447 --out bench.mcap --duration 60
///   rig calibrate --config bench.toml --joint j1 --data bench.mcap --write
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The rig config holding the joint
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The joint to calibrate (a lever joint of the config)
    #[arg(long, value_name = "NAME")]
    joint: String,
    #[command(flatten)]
    data: DataArgs,
    /// The pivot position of data without a d column [mm]
    #[arg(long, value_name = "MM")]
    pivot_mm: Option<f64>,
    /// Update the config file in place
    #[arg(long, conflicts_with = "out")]
    write: bool,
    /// Write the updated config here instead
    #[arg(long, value_name = "NEW.toml")]
    out: Option<PathBuf>,
    /// Print one JSON object instead of the report
    #[arg(long)]
    json: bool,
}

/// One file's samples in order, with their times [s] and the config's sensor zeros taken off
/// (`[joint.effects]`: what the estimator does to each sample before its model sees it).
fn samples(
    run: &Run,
    pivot_m: Option<f64>,
    file: &Path,
    zeros: &rig_config::JointEffects,
) -> Result<Timed, CliError> {
    let phi = run.phi.as_ref().ok_or_else(|| {
        CliError::Invalid(format!(
            "{}: no deflection (phi) column; name it with --columns phi=COLUMN[:deg]",
            file.display()
        ))
    })?;
    let d: Vec<f64> = match (&run.d, pivot_m) {
        (Some(d), _) => d.clone(),
        (None, Some(p)) => vec![p; phi.len()],
        (None, None) => {
            return Err(CliError::Invalid(format!(
                "{}: no pivot position (d) column; name it with --columns d=COLUMN:mm, or give --pivot-mm",
                file.display()
            )));
        }
    };
    let samples = (0..phi.len())
        .map(|i| FitSample {
            phi: phi[i] - zeros.encoder_offset_rad,
            tau: run.tau[i] - zeros.torque_offset_nm,
            d: d[i],
        })
        .collect();
    Ok((run.t.clone(), samples))
}

/// A run's times [s] and samples.
type Timed = (Vec<f64>, Vec<FitSample>);

/// What the table must hold of a run, given the live effects the config applies with it: the
/// deflection delayed by a torque lag, then what the spring sees and carries
/// ([`rig_model::live::LiveEffects::spring_side`]).
fn spring_side(run: &Timed, e: &rig_model::live::LiveEffects) -> Vec<FitSample> {
    let (t, s) = run;
    let phi: Vec<f64> = s.iter().map(|x| x.phi).collect();
    let phi = rig_model::identify::signals::shifted(t, &phi, e.torque_lag_s);
    s.iter()
        .zip(phi)
        .map(|(x, phi)| {
            let (phi, tau) = e.spring_side(phi, x.tau);
            FitSample { phi, tau, d: x.d }
        })
        .collect()
}

/// Torque RMSE [N·m] of `curve` run live over each run from a virgin state, with the config's
/// live effects: the residual the estimator would show.
fn rmse(
    curve: &RestoringCurve,
    dead_band: f64,
    effects: &rig_model::live::LiveEffects,
    runs: &[Timed],
) -> f64 {
    let (mut sq, mut n) = (0.0, 0usize);
    for (t, s) in runs {
        let mut m = LiveJoint::new(
            RestoringTorqueModel::new(curve.clone(), dead_band),
            *effects,
        );
        for (t, x) in t.iter().zip(s) {
            if let Some(r) = m.update(*t, x.phi, x.d, Some(x.tau)).residual_nm {
                sq += r * r;
                n += 1;
            }
        }
    }
    (sq / n.max(1) as f64).sqrt()
}

/// The merged table: the fitted points, and the config's points no fitted point is within
/// [`SAME_PIVOT_M`] of (returned apart, to be named).
fn merge(
    fitted: &[(f64, RestoringParams)],
    config: &[(f64, RestoringParams)],
) -> (Vec<(f64, RestoringParams)>, Vec<f64>) {
    let mut kept = Vec::new();
    let mut table: Vec<(f64, RestoringParams)> = fitted.to_vec();
    for &(d, p) in config {
        if fitted.iter().all(|(fd, _)| (fd - d).abs() > SAME_PIVOT_M) {
            table.push((d, p));
            kept.push(d);
        }
    }
    table.sort_by(|a, b| a.0.total_cmp(&b.0));
    (table, kept)
}

/// The config's text with joint `name`'s `[[joint.restoring.point]]` replaced by `table`
/// (comments and layout elsewhere kept; the first point carries `note` as its comment).
fn rewrite(
    text: &str,
    name: &str,
    table: &[(f64, RestoringParams)],
    note: &str,
) -> Result<String, CliError> {
    let mut doc: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e| CliError::Invalid(format!("the config does not parse as TOML: {e}")))?;
    let restoring = crate::config_edit::joint(&mut doc, name)?
        .get_mut("restoring")
        .and_then(toml_edit::Item::as_table_mut)
        .ok_or_else(|| {
            CliError::Invalid(format!("joint {name:?} has no [joint.restoring] table"))
        })?;
    let mut points = toml_edit::ArrayOfTables::new();
    for (i, (d, p)) in table.iter().enumerate() {
        let mut t = toml_edit::Table::new();
        // Six significant digits, as the examples' tables: far below the fit's own error.
        let six = |v: f64| format!("{v:.6e}").parse::<f64>().unwrap_or(v);
        t["d_mm"] = toml_edit::value((d * 1e5).round() / 1e2);
        t["k_nm_per_rad"] = toml_edit::value(six(p.k));
        t["h_nm"] = toml_edit::value(six(p.h));
        t["a_s"] = toml_edit::value(six(p.a_s));
        t["n"] = toml_edit::value(six(p.n));
        if i == 0 {
            t.decor_mut().set_prefix(note);
        }
        points.push(t);
    }
    // The fit's envelope (a value already there keeps its comment).
    if restoring.get("envelope").and_then(toml_edit::Item::as_str) != Some("lever") {
        restoring.insert("envelope", toml_edit::value("lever"));
    }
    restoring.insert("point", toml_edit::Item::ArrayOfTables(points));
    Ok(doc.to_string())
}

pub fn run(a: &Args) -> Result<(), CliError> {
    let cfg: RigConfig = rig_config::load(&a.config)?;
    let j = rig_joint::board::joint_index(&cfg, &a.joint)?;
    let JointKind::Lever {
        vsa,
        restoring,
        dead_band_rad,
    } = &cfg.joints[j].kind
    else {
        return Err(CliError::Unsupported(format!(
            "joint {:?} is not a lever joint: only paper B's lever VSA has a restoring-torque table",
            a.joint
        )));
    };
    let pivot_m = match a.pivot_mm {
        Some(p) if p.is_finite() => Some(p * 1e-3),
        Some(p) => {
            return Err(CliError::Invalid(format!(
                "--pivot-mm must be a number, got {p}"
            )));
        }
        None => None,
    };
    let map = ColumnMap::parse(a.data.columns.as_deref())?;
    let effects = cfg.joints[j].effects;
    let load = |files: &[PathBuf]| -> Result<Vec<Timed>, CliError> {
        files
            .iter()
            .map(|f| {
                let (run, _) = read(f, &map, Some(&a.joint))?;
                samples(&run, pivot_m, f, &effects)
            })
            .collect()
    };
    let fit_runs = load(&a.data.data)?;
    let held_runs = load(&a.data.holdout)?;
    // The table holds what the spring does; the config's live effects stay outside it.
    let all: Vec<FitSample> = fit_runs
        .iter()
        .flat_map(|r| spring_side(r, &effects.live))
        .collect();
    // The envelope lines follow the joint's lever (restoring.rs): k is the stiffness at rest
    // and the rig's reported stiffness the centre line's slope at the current deflection.
    let envelope = Envelope::Lever(*vsa);
    let opts = FitOptions {
        dead_band: *dead_band_rad,
        envelope,
        ..FitOptions::default()
    };
    let pb = crate::progress::bar(1, "calibrate: fitting eq. 7 at each pivot position");
    let fit = fit_restoring(&all, &opts).map_err(|e| CliError::Invalid(format!("the fit: {e}")))?;
    pb.finish_and_clear();
    let fitted: Vec<(f64, RestoringParams)> = fit.groups.iter().map(|g| (g.d, g.params)).collect();
    let (table, kept) = merge(&fitted, &restoring.table());
    if !kept.is_empty() && restoring.envelope() != envelope {
        eprintln!(
            "rig calibrate: warning: the table keeps the config's points at {} mm, fitted with paper B's straight envelope lines; their k is a secant of the stroke they were fitted on, not the stiffness at rest: record the joint there too and calibrate again",
            kept.iter()
                .map(|d| format!("{:.2}", d * 1e3))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let curve = RestoringCurve::new(&table)
        .map_err(|e| CliError::Invalid(format!("the merged table: {e}")))?
        .with_envelope(envelope);
    let (scored_on, score_runs) = if held_runs.is_empty() {
        ("the fit data (no --holdout given)", &fit_runs)
    } else {
        ("the held-out data", &held_runs)
    };
    let before = rmse(restoring, *dead_band_rad, &effects.live, score_runs);
    let after = rmse(&curve, *dead_band_rad, &effects.live, score_runs);
    let scored_samples: usize = score_runs.iter().map(|r| r.1.len()).sum();

    let files = a
        .data
        .data
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let note = format!(
        "# Fitted by `rig calibrate` on {files} at {} mm; torque RMSE on {scored_on}: \
         {before:.4} N·m with the previous table, {after:.4} N·m with this one.\n",
        fitted
            .iter()
            .map(|(d, _)| format!("{:.2}", d * 1e3))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let target = if a.write {
        Some(a.config.clone())
    } else {
        a.out.clone()
    };
    if let Some(path) = &target {
        let text = std::fs::read_to_string(&a.config)?;
        let new = rewrite(&text, &a.joint, &table, &note)?;
        // Validated before it lands: a table the config checker refuses is never written.
        crate::config_edit::write_validated(path, &new)?;
    }

    if a.json {
        let points: Vec<_> = table
            .iter()
            .map(|(d, p)| {
                json!({"d_mm": d * 1e3, "k_nm_per_rad": p.k, "h_nm": p.h, "a_s": p.a_s, "n": p.n,
                       "fitted": fitted.iter().any(|(fd, _)| fd == d)})
            })
            .collect();
        let groups: Vec<_> = fit
            .groups
            .iter()
            .map(|g| json!({"d_mm": g.d * 1e3, "samples": g.samples, "rmse_nm": g.rmse, "peak_nm": g.peak}))
            .collect();
        println!(
            "{}",
            json!({
                "joint": a.joint,
                "fitted": groups,
                "kept_from_config_mm": kept.iter().map(|d| d * 1e3).collect::<Vec<_>>(),
                "table": points,
                "scored_on": if held_runs.is_empty() { "fit" } else { "holdout" },
                "scored_samples": scored_samples,
                "rmse_before_nm": before,
                "rmse_after_nm": after,
                "written": target.as_ref().map(|p| p.display().to_string()),
            })
        );
        return Ok(());
    }
    println!(
        "joint {}: {} pivot position(s) in the data",
        a.joint,
        fit.groups.len()
    );
    println!(
        "  {:>7} {:>9} {:>13} {:>11} {:>9} {:>7} {:>13}",
        "d [mm]", "samples", "k [N·m/rad]", "h [N·m]", "A_s", "n", "fit RMSE [N·m]"
    );
    for g in &fit.groups {
        println!(
            "  {:>7.2} {:>9} {:>13.5} {:>11.3e} {:>9.4} {:>7.4} {:>13.4}",
            g.d * 1e3,
            g.samples,
            g.params.k,
            g.params.h,
            g.params.a_s,
            g.params.n,
            g.rmse
        );
    }
    if !kept.is_empty() {
        println!(
            "kept from the config (the data does not reach them): {} mm",
            kept.iter()
                .map(|d| format!("{:.2}", d * 1e3))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    println!(
        "torque RMSE on {scored_on} ({scored_samples} samples): {before:.4} N·m with the config's table, {after:.4} N·m with the new one ({:.2}×)",
        before / after.max(f64::MIN_POSITIVE)
    );
    match &target {
        Some(p) => println!("wrote {}", p.display()),
        None => println!("nothing written: add --write (in place) or --out NEW.toml"),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    fn p(k: f64) -> RestoringParams {
        RestoringParams {
            k,
            h: 0.001,
            a_s: k,
            n: 1.0,
        }
    }

    #[test]
    fn the_table_is_fitted_to_what_the_spring_does_beside_the_configs_live_effects() {
        // A joint whose table is k = 2.5 N·m/rad with a 5 mrad gap and a 15 ms torque lag
        // applied live: data generated by the live model itself (noise-free), fitted with the
        // effects taken out, gives back the table's slope, and scored live reproduces the data;
        // fitted ignoring them, the table bends to hold them.
        let table = p(2.5);
        let effects = rig_model::live::LiveEffects {
            backlash_half_width_rad: 0.005,
            torque_lag_s: 0.015,
            ..Default::default()
        };
        let curve = RestoringCurve::constant(table);
        let dead_band = rig_model::hysteresis::AS5048A_COUNT_RAD;
        let ts = 1e-3;
        let t: Vec<f64> = (0..20_000).map(|i| i as f64 * ts).collect();
        let path = rig_sim::world::bench_path(t.len(), ts, 0.06, 3);
        let mut truth =
            LiveJoint::new(RestoringTorqueModel::new(curve.clone(), dead_band), effects);
        let now: Vec<f64> = t
            .iter()
            .zip(&path)
            .map(|(t, phi)| truth.update(*t, *phi, 0.009, None).torque_nm)
            .collect();
        // The torque sensor reads 15 ms late.
        let late = rig_model::identify::signals::shifted(&t, &now, 0.015);
        let run: Timed = (
            t.clone(),
            path.iter()
                .zip(&late)
                .map(|(phi, tau)| FitSample {
                    phi: *phi,
                    tau: *tau,
                    d: 0.009,
                })
                .collect(),
        );
        let opts = FitOptions {
            dead_band,
            ..FitOptions::default()
        };
        let with = fit_restoring(&spring_side(&run, &effects), &opts).unwrap();
        let k = with.groups[0].params.k;
        assert!((k - 2.5).abs() < 0.025, "k {k} for 2.5");
        let fitted = RestoringCurve::constant(with.groups[0].params);
        let live = rmse(&fitted, dead_band, &effects, std::slice::from_ref(&run));
        let none = rig_model::live::LiveEffects::default();
        let without = fit_restoring(&spring_side(&run, &none), &opts).unwrap();
        let bent = RestoringCurve::constant(without.groups[0].params);
        let ignored = rmse(&bent, dead_band, &none, std::slice::from_ref(&run));
        eprintln!("k {k}; live RMSE {live} N·m with the effects, {ignored} N·m ignoring them");
        assert!(
            live < 0.2 * ignored,
            "live {live} N·m vs {ignored} N·m ignoring the effects"
        );
    }

    #[test]
    fn a_fitted_point_replaces_the_config_points_near_it_and_the_others_are_named() {
        let config = [(0.0, p(0.2)), (9.0e-3, p(2.5)), (18.0e-3, p(50.0))];
        let (table, kept) = merge(&[(9.2e-3, p(3.0))], &config);
        assert_eq!(kept, [0.0, 18.0e-3]);
        let ds: Vec<f64> = table.iter().map(|(d, _)| *d).collect();
        assert_eq!(ds, [0.0, 9.2e-3, 18.0e-3]);
        assert_eq!(table[1].1.k, 3.0);
    }

    #[test]
    fn the_rewrite_replaces_only_the_joints_points_and_keeps_comments() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../rig-config/examples/bench.toml"
        ))
        .unwrap();
        let out = rewrite(
            &text,
            "j1",
            &[(9.0e-3, p(2.0)), (12.0e-3, p(6.0))],
            "# new\n",
        )
        .unwrap();
        // Everything before the table is as it was, comments included.
        let head = text
            .split("# Fitted on the simulated bench")
            .next()
            .unwrap();
        assert!(head.contains("[joint.restoring]"));
        assert!(out.starts_with(head));
        assert_eq!(out.matches("[[joint.restoring.point]]").count(), 2);
        assert!(out.contains("# new\n[[joint.restoring.point]]\nd_mm = 9.0\nk_nm_per_rad = 2.0"));
        // A table fitted before the lever envelope gets it with the new points.
        let linear = text.replace("envelope = \"lever\"", "envelope = \"linear\"");
        let out = rewrite(&linear, "j1", &[(9.0e-3, p(2.0))], "").unwrap();
        assert_eq!(out.matches("envelope = \"lever\"").count(), 1, "{out}");
        assert!(
            out.contains("[joint.limits]"),
            "the sections after the table stay"
        );
        let e = rewrite(&text, "j9", &[], "").unwrap_err().to_string();
        assert!(e.contains("no [[joint]] named \"j9\""), "{e}");
    }
}
