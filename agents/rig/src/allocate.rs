//! `rig allocate`: joint stiffnesses and pivot positions for a wanted operational stiffness.
//!
//! The pose gives G_u^A (rig_model::planar), hence S; the bounded least-squares solve and its
//! tie-break are rig_model::allocation; each joint stiffness becomes a pivot position through
//! the lever's inverse (rig_model::lever). Nothing is clamped silently: an unreachable pose, a
//! target outside the range or a target that cannot be met exactly is an error (exit 3),
//! printed with the best compromise.
//!
//! With `--live` the rig's running allocator is asked instead (the `allocate` query): it solves
//! the same problem, commands the joints and answers; this is how an operator moves a rig that
//! `rig launch` started, from any machine that reaches it.

use std::path::PathBuf;

use rig_allocator::plan::{Plan, PlanError, Target, allocate};
use rig_config::RigConfig;
use rig_model::allocation::OperationalStiffness;
use serde_json::{Value, json};

use crate::error::CliError;

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["k", "percent"])))]
pub struct Args {
    /// Rig config (a serial or parallel robot), e.g. rig-config/examples/parallel.toml
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// End-effector position in millimetres, X_MM,Y_MM (default: the config's home_mm)
    #[arg(long, value_name = "X_MM,Y_MM", value_parser = parse_pair, allow_hyphen_values = true)]
    at: Option<(f64, f64)>,
    /// Wanted operational stiffness in N/m: KXX,KYY or KXX,KYY,KXY (k_xy defaults to 0)
    #[arg(long, value_name = "KXX,KYY[,KXY]", value_parser = parse_k, allow_hyphen_values = true)]
    k: Option<OperationalStiffness>,
    /// Paper B's decoupled target: k_xx and k_yy at P % of the range S·k_min..S·k_max, k_xy = 0
    #[arg(long, value_name = "P", value_parser = percent_of_range, allow_negative_numbers = true)]
    percent: Option<f64>,
    /// Print one JSON object instead of the table
    #[arg(long)]
    json: bool,
    /// Ask the rig's running allocator instead of solving here: it solves, commands the joints
    /// (the pivots move) and answers, and its answer is printed. Joins the rig as the config's
    /// [zenoh] says, or as --connect/--listen/--mode say (from another machine: --connect
    /// tcp/HOST:7447, HOST the machine whose hub the allocator's machine listens on)
    #[arg(long)]
    live: bool,
    /// How long to wait for the allocator's answer with --live
    #[arg(long, value_name = "SECONDS", default_value = "5", value_parser = rig_runtime::cli::positive_seconds, requires = "live")]
    within: std::time::Duration,
    #[command(flatten)]
    net: rig_runtime::NetArgs,
}

fn numbers(s: &str) -> Result<Vec<f64>, String> {
    s.split(',')
        .map(|t| {
            let v: f64 = t
                .trim()
                .parse()
                .map_err(|_| format!("\"{t}\" is not a number"))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!("\"{t}\" is not a finite number"))
            }
        })
        .collect()
}

fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    match numbers(s)?.as_slice() {
        [x, y] => Ok((*x, *y)),
        v => Err(format!(
            "expected X_MM,Y_MM (two numbers), got {} values",
            v.len()
        )),
    }
}

/// Parses a percentage of the stiffness range: a finite number from 0 to 100.
pub(crate) fn percent_of_range(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(p) if (0.0..=100.0).contains(&p) => Ok(p),
        _ => Err(format!(
            "{s} is not a percentage of the stiffness range (0 to 100)"
        )),
    }
}

fn parse_k(s: &str) -> Result<OperationalStiffness, String> {
    match numbers(s)?.as_slice() {
        [xx, yy] => Ok(OperationalStiffness {
            xx: *xx,
            xy: 0.0,
            yy: *yy,
        }),
        [xx, yy, xy] => Ok(OperationalStiffness {
            xx: *xx,
            xy: *xy,
            yy: *yy,
        }),
        v => Err(format!(
            "expected KXX,KYY or KXX,KYY,KXY in N/m, got {} values",
            v.len()
        )),
    }
}

/// Everything `rig allocate` prints.
struct Report {
    cfg: RigConfig,
    plan: Plan,
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let cfg = rig_config::load(&args.config)?;
    let home = cfg.geometry.map(|g| g.home);
    let at_m = match (args.at, home) {
        (Some((x, y)), _) => (x * 1e-3, y * 1e-3),
        (None, Some(h)) => h,
        (None, None) => (0.0, 0.0),
    };
    let target = match (args.k, args.percent) {
        (Some(k), _) => Target::Stiffness(k),
        (None, Some(p)) => Target::Percent(p),
        (None, None) => return Err(CliError::Unsupported("give --k or --percent".into())),
    };
    let net = &args.net;
    if args.live {
        return live(args, &cfg, at_m, target);
    } else if !(net.listen.is_empty() && net.connect.is_empty() && net.mode.is_none()) {
        return Err(CliError::Unsupported(
            "--listen, --connect and --mode join a running rig: they need --live".into(),
        ));
    }
    let plan = allocate(&cfg, at_m, target).map_err(|e| match e {
        PlanError::Unsupported(m) => {
            CliError::Unsupported(format!("{}: {m}", args.config.display()))
        }
        PlanError::Infeasible(m) => CliError::Infeasible(m),
    })?;
    let failure = plan.failure(cfg.topology);
    let report = Report { cfg, plan };
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&to_json(&report, failure.as_deref()))
                .map_err(|e| CliError::Io(std::io::Error::other(e)))?
        );
    } else {
        print_table(&report);
    }
    match failure {
        None => Ok(()),
        Some(msg) => Err(CliError::Infeasible(msg)),
    }
}

/// `--live`: the request to the rig's allocator (`rig/<rig>/allocate`), its answer printed.
fn live(args: &Args, cfg: &RigConfig, at_m: (f64, f64), target: Target) -> Result<(), CliError> {
    use rig_protocol::{AllocationRequest, AllocationResult, Keys, decode, encode};
    let keys = Keys::new(&cfg.name)?;
    let req = AllocationRequest {
        // Distinct across operators and runs: the answer names it.
        id: rig_runtime::now_ns(),
        x_m: at_m.0,
        y_m: at_m.1,
        target: target.into(),
    };
    let bytes = encode(&req).map_err(|e| CliError::Invalid(format!("the request: {e}")))?;
    let within = args.within;
    let answer: Result<Vec<u8>, String> = rig_runtime::tokio_runtime(Some(1))?.block_on(async {
        let session =
            rig_runtime::open(cfg, &args.net.overrides(), &rig_config::Identity::Operator).await?;
        let replies = session
            .get(keys.allocate())
            .payload(bytes)
            .timeout(within)
            .await
            .map_err(rig_runtime::zenoh_err)?;
        let answer = match tokio::time::timeout(within, replies.recv_async()).await {
            Ok(Ok(reply)) => match reply.result() {
                Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
                Err(e) => Err(format!(
                    "the allocator refused the request: {}",
                    String::from_utf8_lossy(&e.payload().to_bytes())
                )),
            },
            _ => Err(format!(
                "no allocator answered on {} within {} s: is `rig allocator` (or `rig launch` on \
                 the machine that runs it) up, and does --connect reach its machine's hub?",
                keys.allocate(),
                within.as_secs_f64()
            )),
        };
        let _ = session.close().await;
        Ok::<_, CliError>(answer)
    })?;
    let result = decode::<AllocationResult>(&answer.map_err(CliError::Rig)?)
        .map_err(|e| CliError::Rig(format!("the allocator's answer: {e}")))?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&result)
                .map_err(|e| CliError::Io(std::io::Error::other(e)))?
        );
    } else {
        println!(
            "the rig's allocator answered request {} ({}):",
            result.id,
            if result.feasible {
                "applied: the joints are commanded"
            } else {
                "not applied"
            }
        );
        let (w, a) = (&result.target, &result.achieved);
        println!(
            "  wanted   K = [{:.1} {:.1}; {:.1} {:.1}] N/m\n  achieved K = [{:.1} {:.1}; {:.1} {:.1}] N/m (residual {:.3} N/m)",
            w.xx, w.xy, w.xy, w.yy, a.xx, a.xy, a.xy, a.yy, result.residual
        );
        for ((j, k), d) in cfg
            .joints
            .iter()
            .zip(&result.k_joint_nm_per_rad)
            .zip(&result.pivot_m)
        {
            println!("  {}: k = {k:.3} N·m/rad, pivot {:.3} mm", j.name, d * 1e3);
        }
    }
    if result.feasible {
        Ok(())
    } else {
        Err(CliError::Infeasible(result.error))
    }
}

fn triple(k: OperationalStiffness) -> Value {
    json!({"xx": k.xx, "xy": k.xy, "yy": k.yy})
}

fn to_json(r: &Report, error: Option<&str>) -> Value {
    let a = &r.plan.allocation;
    let g = r
        .cfg
        .geometry
        .unwrap_or_else(|| unreachable!("checked in compute"));
    let s: Vec<Vec<f64>> = (0..3)
        .map(|i| r.plan.problem.s.row(i).iter().copied().collect())
        .collect();
    json!({
        "rig": r.cfg.name,
        "topology": r.cfg.topology.name(),
        "pose_m": {"x": r.plan.at_m.0, "y": r.plan.at_m.1},
        "joint_angles_rad": r.plan.configuration.theta,
        "geometry_m": {"l1": g.l1, "l2": g.l2, "l3": g.l3, "l4": g.l4, "l5": g.l5, "lb": g.lb},
        "s_matrix": s,
        "k_bounds_nm_per_rad": {"min": r.plan.problem.k_min.as_slice(), "max": r.plan.problem.k_max.as_slice()},
        "range_n_per_m": {"min": triple(r.plan.range.min), "max": triple(r.plan.range.max)},
        "target_n_per_m": triple(a.target),
        "k_joint_nm_per_rad": a.k.as_slice(),
        "pivot_mm": r.plan.pivots_m.iter().map(|p| p.as_ref().ok().map(|d| d * 1e3)).collect::<Vec<_>>(),
        "k_operational_n_per_m": triple(a.achieved),
        "residual": a.residual,
        "feasible": a.feasible,
        "at_bound": a.at_bound,
        "optimal_set_dim": a.optimal_set_dim,
        "tie_break": "closest to the centre of each joint's range, in fractions of the range",
        "error": error,
    })
}

fn print_table(r: &Report) {
    let a = &r.plan.allocation;
    println!(
        "Allocation for rig \"{}\" ({}, {} VSAs) with the end effector at ({:.1}, {:.1}) mm",
        r.cfg.name,
        r.cfg.topology.name(),
        r.cfg.joints.len(),
        r.plan.at_m.0 * 1e3,
        r.plan.at_m.1 * 1e3
    );
    println!();
    println!("                 k_xx [N/m]   k_xy [N/m]   k_yy [N/m]");
    for (label, k) in [
        ("range min (0 %)", r.plan.range.min),
        ("range max (100%)", r.plan.range.max),
        ("target", a.target),
        ("achieved", a.achieved),
    ] {
        println!("{label:<16} {:>11.3}  {:>11.3}  {:>11.3}", k.xx, k.xy, k.yy);
    }
    println!(
        "residual {:.3e} N/m — {}",
        a.residual,
        if a.feasible {
            "target met"
        } else {
            "target NOT met"
        }
    );
    println!();
    println!("joint  θ [deg]   k [N·m/rad]   bounds [N·m/rad]       pivot d [mm]");
    for (i, j) in r.cfg.joints.iter().enumerate() {
        let bound = match a.at_bound[i] {
            -1 => " (at min)",
            1 => " (at max)",
            _ => "",
        };
        let pivot = match &r.plan.pivots_m[i] {
            Ok(d) => format!("{:.3}", d * 1e3),
            Err(e) => format!("— ({e})"),
        };
        println!(
            "{:<6} {:>7.2}   {:>11.4}   [{:>7.4}, {:>7.3}]   {pivot}{bound}",
            j.name,
            r.plan.configuration.theta[i].to_degrees(),
            a.k[i],
            r.plan.problem.k_min[i],
            r.plan.problem.k_max[i],
        );
    }
    if r.plan.configuration.theta.len() > r.cfg.joints.len() {
        let passive: Vec<String> = r.plan.configuration.theta[r.cfg.joints.len()..]
            .iter()
            .map(|t| format!("{:.2}", t.to_degrees()))
            .collect();
        println!("passive joint(s) θ [deg]: {}", passive.join(", "));
    }
    if a.optimal_set_dim > 0 {
        println!();
        println!(
            "{} joint stiffnesses, 3 targets: the exact solutions form a {}-dimensional set; the one closest to the centre of every joint's range was chosen.",
            r.cfg.joints.len(),
            a.optimal_set_dim
        );
    }
}
