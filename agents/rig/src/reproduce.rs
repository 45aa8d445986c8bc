//! `rig reproduce paper-a|paper-b`: the papers' experiments in simulation, our numbers beside
//! the papers'. The experiments themselves are `rig_sim::reproduce`.

use clap::ValueEnum;
use rig_sim::reproduce::paper_a::{self, PaperAOptions, PaperAReport};
use rig_sim::reproduce::paper_b::{self, PaperBOptions, PaperBReport};

use crate::error::CliError;
use crate::progress;

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Paper {
    /// Paper A: the decoupled impedance observer on AWAS
    PaperA,
    /// Paper B: restoring torque, force estimation, decoupled stiffness on planar robots
    PaperB,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which paper
    paper: Paper,
    /// Print one JSON object
    #[arg(long)]
    json: bool,
    /// Shorter runs (as the tests use)
    #[arg(long)]
    quick: bool,
    /// Seed of every noise source and excitation path
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Paper B: stroke amplitude along each guide line [mm] (default 6)
    #[arg(long, value_name = "MM")]
    stroke_mm: Option<f64>,
    /// Paper B: hysteretic fraction of the simulated spring torque, 1 − a of Bouc-Wen
    /// (default 0.05)
    #[arg(long, value_name = "F")]
    hysteresis_fraction: Option<f64>,
}

fn json<T: serde::Serialize>(v: &T) -> Result<(), CliError> {
    println!(
        "{}",
        serde_json::to_string_pretty(v).map_err(|e| CliError::Io(std::io::Error::other(e)))?
    );
    Ok(())
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let (pb, mut stage) = progress::stages();
    match args.paper {
        Paper::PaperA => {
            let o = PaperAOptions {
                seed: args.seed,
                ..if args.quick {
                    PaperAOptions::quick()
                } else {
                    PaperAOptions::full()
                }
            };
            let cfg = rig_config::examples::load("awas")?;
            let r = paper_a::run(&cfg, &o, &mut stage)?;
            pb.finish_and_clear();
            if args.json { json(&r) } else { print_a(&r, &o) }
        }
        Paper::PaperB => {
            let mut o = PaperBOptions {
                seed: args.seed,
                ..if args.quick {
                    PaperBOptions::quick()
                } else {
                    PaperBOptions::full()
                }
            };
            if let Some(mm) = args.stroke_mm {
                if !(mm.is_finite() && mm > 0.0 && mm <= 50.0) {
                    return Err(CliError::Invalid(format!(
                        "--stroke-mm {mm} must be in (0, 50]"
                    )));
                }
                o.stroke_amplitude_m = mm * 1e-3;
            }
            if let Some(f) = args.hysteresis_fraction {
                if !(f.is_finite() && (0.0..1.0).contains(&f)) {
                    return Err(CliError::Invalid(format!(
                        "--hysteresis-fraction {f} must be in [0, 1)"
                    )));
                }
                o.hysteresis.a = 1.0 - f;
            }
            let serial = rig_config::examples::load("serial")?;
            let parallel = rig_config::examples::load("parallel")?;
            let r = paper_b::run(&serial, &parallel, &o, &mut stage)?;
            pb.finish_and_clear();
            if args.json { json(&r) } else { print_b(&r, &o) }
        }
    }
}

fn pct(x: f64) -> String {
    format!("{:.2} %", 100.0 * x)
}

fn print_a(r: &PaperAReport, o: &PaperAOptions) -> Result<(), CliError> {
    println!(
        "Paper A — decoupled impedance observer on simulated AWAS ({} s at {} Hz per run)",
        o.duration_s, o.rate_hz
    );
    println!("mean relative errors over the second half of each run\n");
    println!(
        "{:<16} {:<7} {:>11} {:>11} {:>11} {:>13}",
        "scenario", "tuning", "stiffness", "damping", "inertia", "converged"
    );
    for s in &r.scenarios {
        let tuning = format!("{:?}", s.tuning).to_lowercase();
        let conv = s
            .convergence_s
            .map_or("never".to_string(), |t| format!("{t:.2} s"));
        println!(
            "{:<16} {:<7} {:>11} {:>11} {:>11} {:>13}",
            s.name,
            tuning,
            pct(s.stiffness_rel_err),
            pct(s.damping_rel_err),
            pct(s.inertia_rel_err),
            conv
        );
    }
    println!(
        "\npaper A on hardware (experimental tuning): damping 9.4 %, inertia 12.2 %, stiffness a few % (digit lost in the OCR)"
    );
    println!(
        "quantised-noisy: 14-bit link and motor encoders, torque-sensor noise σ = {} N·m",
        o.torque_noise_nm
    );
    Ok(())
}

fn print_b(r: &PaperBReport, o: &PaperBOptions) -> Result<(), CliError> {
    println!(
        "Paper B — simulated lever VSAs (lever + Bouc-Wen spring + 43° stop), sensor data only\n"
    );
    println!(
        "Restoring-torque model per pivot position (paper B Table 1 layout; its numbers are lost in the OCR)"
    );
    println!(
        "{:>7} {:>10} {:>10} {:>8} | {:>9} {:>9} {:>9} {:>6}",
        "d [mm]", "MAE [N·m]", "peak", "MAE %", "k", "h", "A_s", "n"
    );
    for t in &r.torque_mae {
        println!(
            "{:>7.2} {:>10.4} {:>10.3} {:>7.2}% | {:>9.3} {:>9.4} {:>9.3} {:>6.3}",
            t.d_mm,
            t.mae_nm,
            t.peak_nm,
            100.0 * t.mae_nm / t.peak_nm,
            t.k_nm_per_rad,
            t.h_nm,
            t.a_s,
            t.n
        );
    }
    println!(
        "\nForce estimation along {} mm strokes (paper B §5.3–5.4: figures only)",
        o.stroke_amplitude_m * 1e3
    );
    println!(
        "{:<9} {:<5} {:>14} {:>10} {:>9}",
        "robot", "axis", "RMSE % peak", "RMSE [N]", "peak [N]"
    );
    for f in &r.force {
        println!(
            "{:<9} {:<5} {:>13.2}% {:>10.4} {:>9.3}",
            f.robot, f.axis, f.rmse_pct_of_peak, f.rmse_n, f.peak_n
        );
    }
    println!(
        "\nCross-axis force spike, equal joint stiffness vs decoupled allocation (paper B Table 2 layout)"
    );
    println!(
        "{:>9} {:>12} {:>12} {:>10}",
        "percent", "before [N]", "after [N]", "reduced"
    );
    for d in &r.decoupling {
        println!(
            "{:>8.1}% {:>12.3} {:>12.3} {:>9.1}%",
            d.percent,
            d.spike_before_n,
            d.spike_after_n,
            100.0 * (1.0 - d.spike_after_n / d.spike_before_n)
        );
    }
    println!("\npaper B: spikes \"almost reduced to zero\"; allocation residual 6.2e-16 (lsqlin)");
    Ok(())
}
