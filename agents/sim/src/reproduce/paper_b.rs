//! Paper B in simulation: the restoring-torque model per pivot position (its Table 1), force
//! estimation on the serial and parallel robots (§5.3–5.4), and the cross-axis force spike with
//! and without the decoupled allocation (§5.5, Table 2).
//!
//! The estimator sees sensor data only: quantised deflections, motor angles, pivot positions,
//! a noisy torque sensor on the calibration bench and a noisy force sensor at the end
//! effector. The truth is the simulator's lever + Bouc-Wen + hard-stop joint.

use nalgebra::DVector;
use rig_config::{JointKind, RigConfig};
use rig_model::allocation::AllocationProblem;
use rig_model::estimator::{JointReadings, RobotEstimator};
use rig_model::hysteresis::{
    Envelope, FitOptions, FitSample, RestoringCurve, RestoringTorqueModel, fit_restoring,
};
use rig_model::lever::LeverVsa;
use rig_model::planar::{PlanarRobot, s_matrix};
use serde::Serialize;

use super::{Progress, ReproduceError};
use crate::effects::Effects;
use crate::lever_joint::{LeverJointPlant, SpringHysteresis};
use crate::noise::{Noise, quantize};
use crate::planar_rig::{PlanarRigSim, PlanarSensors, Stroke};
use crate::world::bench_path;

/// Lengths and noise of the runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperBOptions {
    pub rate_hz: f64,
    /// Bench run per pivot position, to fit the model [s].
    pub calibration_s: f64,
    /// Held-out bench run per pivot position, to score it [s].
    pub evaluation_s: f64,
    /// Each stroke (x, then y) [s].
    pub stroke_s: f64,
    /// Stroke amplitude along the guide line [m]. 6 mm keeps the stiffest joints (α up to
    /// ≈ 0.15 rad) where the lever is nearly linear; at 12 mm its softening alone leaves
    /// 5–10 % of the coupling (see the README).
    pub stroke_amplitude_m: f64,
    /// Torque-sensor noise on the bench [N·m].
    pub torque_noise_nm: f64,
    /// Force-sensor noise at the end effector [N].
    pub force_noise_n: f64,
    /// Largest bench deflection [rad]: covers the robots' working range (6 mm strokes deflect
    /// the joints by up to ≈ 0.03 rad), capped at 80 % of each pivot's usable range.
    pub calibration_amplitude_rad: f64,
    /// Friction in the lever and spring of the simulated joints.
    pub hysteresis: SpringHysteresis,
    pub seed: u64,
}

impl PaperBOptions {
    /// The full reproduction.
    pub fn full() -> Self {
        Self {
            rate_hz: 1000.0,
            calibration_s: 40.0,
            evaluation_s: 20.0,
            stroke_s: 8.0,
            stroke_amplitude_m: 0.006,
            torque_noise_nm: 0.003,
            force_noise_n: 0.01,
            calibration_amplitude_rad: 0.06,
            hysteresis: SpringHysteresis::default(),
            seed: 1,
        }
    }

    /// A short run for tests.
    pub fn quick() -> Self {
        Self {
            calibration_s: 10.0,
            evaluation_s: 6.0,
            stroke_s: 3.0,
            ..Self::full()
        }
    }
}

/// The pivot positions of the calibration (paper B's cases span the 18 mm travel).
pub const PIVOTS_MM: [f64; 9] = [0.0, 2.25, 4.5, 6.75, 9.0, 11.25, 13.5, 15.75, 18.0];
/// Pivot position of every joint during the force-estimation strokes.
pub const STROKE_PIVOT_MM: f64 = 9.0;
/// The decoupling percentages of paper B Table 2.
pub const PERCENTS: [f64; 3] = [12.5, 25.0, 37.5];

#[derive(Debug, Clone, Serialize)]
pub struct TorqueRow {
    pub d_mm: f64,
    pub mae_nm: f64,
    pub peak_nm: f64,
    pub k_nm_per_rad: f64,
    pub h_nm: f64,
    pub a_s: f64,
    pub n: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ForceRow {
    pub robot: &'static str,
    pub axis: &'static str,
    pub rmse_pct_of_peak: f64,
    pub rmse_n: f64,
    pub peak_n: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct DecouplingRow {
    pub percent: f64,
    pub spike_before_n: f64,
    pub spike_after_n: f64,
    pub k_before_nm_per_rad: Vec<f64>,
    pub k_after_nm_per_rad: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct PaperBReport {
    pub torque_mae: Vec<TorqueRow>,
    pub force: Vec<ForceRow>,
    pub decoupling: Vec<DecouplingRow>,
}

fn lever_of(cfg: &RigConfig) -> Result<LeverVsa, ReproduceError> {
    match cfg.joints.first().map(|j| &j.kind) {
        Some(JointKind::Lever { vsa, .. }) => Ok(*vsa),
        _ => Err(ReproduceError::Config("paper B needs lever joints".into())),
    }
}

/// One bench run at pivot `d`: measured (quantised φ, noisy τ) samples.
fn bench_run(
    vsa: LeverVsa,
    d: f64,
    seconds: f64,
    o: &PaperBOptions,
    seed: u64,
) -> Result<Vec<FitSample>, ReproduceError> {
    let ts = 1.0 / o.rate_hz;
    let n = (seconds * o.rate_hz) as usize;
    let amplitude = (0.8 * vsa.deflection_limit(d)).min(o.calibration_amplitude_rad);
    let mut plant = LeverJointPlant::new(vsa, o.hysteresis, Effects::default(), d, 1.0)?;
    let mut noise = Noise::new(seed ^ 0x5eed);
    let res = rig_model::hysteresis::AS5048A_COUNT_RAD;
    Ok(bench_path(n, ts, amplitude, seed)
        .into_iter()
        .enumerate()
        .map(|(i, phi)| {
            let tau = plant.torque(phi, i as f64 * ts, ts);
            FitSample {
                phi: quantize(phi, res),
                tau: tau + noise.gaussian(o.torque_noise_nm),
                d,
            }
        })
        .collect())
}

/// Calibrates the restoring-torque model on the bench and scores it on held-out runs.
pub fn calibrate(
    vsa: LeverVsa,
    o: &PaperBOptions,
    progress: &mut Progress<'_>,
) -> Result<(RestoringCurve, Vec<TorqueRow>), ReproduceError> {
    let mut data = Vec::new();
    for (i, &d_mm) in PIVOTS_MM.iter().enumerate() {
        progress(
            "paper B: bench calibration runs",
            i as u64,
            PIVOTS_MM.len() as u64,
        );
        data.extend(bench_run(
            vsa,
            d_mm * 1e-3,
            o.calibration_s,
            o,
            o.seed + i as u64,
        )?);
    }
    progress("paper B: fitting the restoring-torque model", 0, 1);
    // The envelope lines follow the lever's curve (restoring.rs: paper B's straight lines
    // fitted over a stroke report a secant; k is then the stiffness at rest).
    let fit = fit_restoring(
        &data,
        &FitOptions {
            envelope: Envelope::Lever(vsa),
            ..FitOptions::default()
        },
    )?;
    let mut rows = Vec::new();
    for (i, g) in fit.groups.iter().enumerate() {
        let eval = bench_run(vsa, g.d, o.evaluation_s, o, o.seed + 100 + i as u64)?;
        let mut m =
            RestoringTorqueModel::new(fit.curve.clone(), rig_model::hysteresis::AS5048A_COUNT_RAD);
        let mae = eval
            .iter()
            .map(|s| (m.update(s.phi, s.d) - s.tau).abs())
            .sum::<f64>()
            / eval.len() as f64;
        let peak = eval.iter().fold(0.0_f64, |a, s| a.max(s.tau.abs()));
        let p = fit.curve.at(g.d);
        rows.push(TorqueRow {
            d_mm: g.d * 1e3,
            mae_nm: mae,
            peak_nm: peak,
            k_nm_per_rad: p.k,
            h_nm: p.h,
            a_s: p.a_s,
            n: p.n,
        });
    }
    Ok((fit.curve, rows))
}

/// Per stroke: the measured and estimated forces.
struct StrokeTrace {
    axis: usize,
    measured: Vec<[f64; 2]>,
    estimated: Vec<[f64; 2]>,
    truth: Vec<[f64; 2]>,
}

/// Runs an x stroke then a y stroke with every joint's pivot at `pivots`, estimating the force
/// from sensor data with `curve`.
fn strokes(
    robot: &PlanarRobot,
    vsa: LeverVsa,
    home: (f64, f64),
    pivots: &[f64],
    curve: &RestoringCurve,
    o: &PaperBOptions,
    seed: u64,
) -> Result<Vec<StrokeTrace>, ReproduceError> {
    let ts = 1.0 / o.rate_hz;
    let joints = pivots
        .iter()
        .map(|&d| LeverJointPlant::new(vsa, o.hysteresis, Effects::default(), d, 0.02))
        .collect::<Result<Vec<_>, _>>()?;
    let sensors = PlanarSensors {
        encoder_resolution_rad: rig_model::hysteresis::AS5048A_COUNT_RAD,
        force_noise_n: o.force_noise_n,
    };
    let mut sim = PlanarRigSim::new(robot.clone(), joints, home, sensors, seed, ts)?;
    let models = pivots
        .iter()
        .map(|_| {
            RestoringTorqueModel::new(curve.clone(), rig_model::hysteresis::AS5048A_COUNT_RAD)
                .into()
        })
        .collect();
    let mut est = RobotEstimator::new(robot.clone(), models)?;
    let n = (o.stroke_s * o.rate_hz) as usize;
    let mut out = Vec::new();
    for axis in 0..2 {
        let stroke = Stroke {
            axis,
            amplitude_m: o.stroke_amplitude_m,
            cycles: 2.0,
            duration_s: o.stroke_s,
        };
        let mut trace = StrokeTrace {
            axis,
            measured: Vec::with_capacity(n),
            estimated: Vec::with_capacity(n),
            truth: Vec::with_capacity(n),
        };
        for i in 0..n {
            let s = sim.step(stroke.offset(i as f64 * ts))?;
            let e = est.update(&JointReadings {
                t_s: i as f64 * ts,
                motor: &s.motor_rad,
                deflection: &s.deflection_rad,
                pivot: &s.pivot_m,
            })?;
            trace.measured.push([s.force_n[0], s.force_n[1]]);
            trace.estimated.push([e.force[0], e.force[1]]);
            trace.truth.push([s.true_force_n[0], s.true_force_n[1]]);
        }
        out.push(trace);
    }
    Ok(out)
}

fn robot_of(cfg: &RigConfig) -> Result<(PlanarRobot, (f64, f64)), ReproduceError> {
    match (cfg.robot(), cfg.geometry) {
        (Some(r), Some(g)) => Ok((r, g.home)),
        _ => Err(ReproduceError::Config(format!(
            "rig \"{}\" has no robot geometry",
            cfg.name
        ))),
    }
}

/// Runs the three parts of paper B.
pub fn run(
    serial: &RigConfig,
    parallel: &RigConfig,
    o: &PaperBOptions,
    progress: &mut Progress<'_>,
) -> Result<PaperBReport, ReproduceError> {
    let vsa = lever_of(parallel)?;
    let (curve, torque_mae) = calibrate(vsa, o, progress)?;

    let mut force = Vec::new();
    for (name, cfg) in [("serial", serial), ("parallel", parallel)] {
        progress(
            "paper B: force estimation strokes",
            force.len() as u64 / 2,
            2,
        );
        let (robot, home) = robot_of(cfg)?;
        let pivots = vec![STROKE_PIVOT_MM * 1e-3; robot.actuated()];
        for trace in strokes(
            &robot,
            lever_of(cfg)?,
            home,
            &pivots,
            &curve,
            o,
            o.seed + 200,
        )? {
            let a = trace.axis;
            let peak = trace
                .measured
                .iter()
                .fold(0.0_f64, |m, f| m.max(f[a].abs()));
            let mse = trace
                .measured
                .iter()
                .zip(&trace.estimated)
                .map(|(m, e)| (m[a] - e[a]).powi(2))
                .sum::<f64>()
                / trace.measured.len() as f64;
            force.push(ForceRow {
                robot: name,
                axis: ["x", "y"][a],
                rmse_pct_of_peak: 100.0 * mse.sqrt() / peak,
                rmse_n: mse.sqrt(),
                peak_n: peak,
            });
        }
    }

    let (robot, home) = robot_of(parallel)?;
    let c = robot.at_position(home.0, home.1)?;
    // As paper B: joint stiffness maps to pivot position through the lever model (eq. 3),
    // within the config's joint-stiffness bounds.
    let n = parallel.joints.len();
    let k_min = DVector::from_iterator(n, parallel.joints.iter().map(|j| j.limits.k_min));
    let k_max = DVector::from_iterator(n, parallel.joints.iter().map(|j| j.limits.k_max));
    let problem = AllocationProblem::new(s_matrix(&c.g_u_a), k_min.clone(), k_max.clone())?;
    let mut decoupling = Vec::new();
    for (i, &p) in PERCENTS.iter().enumerate() {
        progress(
            "paper B: decoupling strokes",
            i as u64,
            PERCENTS.len() as u64,
        );
        let target = problem.decoupled_target(p)?;
        let after = problem.solve(target)?;
        if !after.feasible {
            return Err(ReproduceError::Config(format!(
                "the decoupled target at {p} % is not feasible at home"
            )));
        }
        // "Before": every joint equally stiff, at the same overall level (trace of K_uu) as
        // the target, so that only the coupling differs.
        let col_trace: f64 = (0..problem.s.ncols())
            .map(|j| problem.s[(0, j)] + problem.s[(2, j)])
            .sum();
        let k_bar = (target.xx + target.yy) / col_trace;
        let before: Vec<f64> = (0..k_min.len())
            .map(|j| k_bar.clamp(k_min[j], k_max[j]))
            .collect();
        let spike = |k: &[f64]| -> Result<f64, ReproduceError> {
            let pivots = k
                .iter()
                .map(|&k| vsa.pivot_for_stiffness(k))
                .collect::<Result<Vec<_>, _>>()?;
            let traces = strokes(
                &robot,
                vsa,
                home,
                &pivots,
                &curve,
                o,
                o.seed + 300 + i as u64,
            )?;
            // The spike is read off the true force: the sensor's noise would add a floor that
            // has nothing to do with coupling.
            Ok(traces
                .iter()
                .map(|t| {
                    t.truth
                        .iter()
                        .fold(0.0_f64, |m, f| m.max(f[1 - t.axis].abs()))
                })
                .fold(0.0, f64::max))
        };
        decoupling.push(DecouplingRow {
            percent: p,
            spike_before_n: spike(&before)?,
            spike_after_n: spike(after.k.as_slice())?,
            k_before_nm_per_rad: before,
            k_after_nm_per_rad: after.k.as_slice().to_vec(),
        });
    }
    progress("paper B: done", 1, 1);
    Ok(PaperBReport {
        torque_mae,
        force,
        decoupling,
    })
}
