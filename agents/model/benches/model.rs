//! Criterion benchmarks of the hot paths of the model core:
//! one EKF + stiffness-observer step, one restoring-torque step, one fit of the restoring loop
//! (straight envelope lines and a lever's curve), one parallel (five-bar) force estimate from
//! joint angles and torques, one allocation solve.
//!
//! Run: `cargo bench -p rig-model --bench model`.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::DVector;
use rig_model::allocation::AllocationProblem;
use rig_model::hysteresis::{
    AS5048A_COUNT_RAD, Envelope, FitOptions, FitSample, RestoringCurve, RestoringParams,
    RestoringTorqueModel, fit_restoring,
};
use rig_model::lever::LeverVsa;
use rig_model::observer::{DecoupledObserver, EkfConfig, ImpedanceSample};
use rig_model::planar::{FiveBar, PlanarRobot, end_effector_force, s_matrix};

fn five_bar() -> PlanarRobot {
    PlanarRobot::FiveBar(FiveBar::example())
}

fn observer_step(c: &mut Criterion) {
    let mut obs =
        DecoupledObserver::new(EkfConfig::paper_a_simulation(1e-3), 2000.0, 0.0, None).unwrap();
    let mut i = 0u64;
    c.bench_function("observer/ekf+stiffness step", |b| {
        b.iter(|| {
            i += 1;
            let t = i as f64 * 1e-3;
            let q = 0.1 * t.sin();
            let theta1 = 0.09 * t.sin();
            let s = ImpedanceSample {
                q,
                theta1,
                tau_e: Some(300.0 * (q - theta1)),
                tau1: None,
                tau_ext: 0.0,
            };
            black_box(obs.step(black_box(&s)).unwrap())
        })
    });
}

fn restoring_step(c: &mut Criterion) {
    let table: Vec<(f64, RestoringParams)> = (0..5)
        .map(|i| {
            let d = i as f64 * 0.0045;
            (
                d,
                RestoringParams {
                    k: 0.25 + 15.0 * i as f64,
                    h: 0.01,
                    a_s: 2.0,
                    n: 0.5,
                },
            )
        })
        .collect();
    let mut m = RestoringTorqueModel::new(RestoringCurve::new(&table).unwrap(), AS5048A_COUNT_RAD);
    let mut i = 0u64;
    c.bench_function("restoring torque step", |b| {
        b.iter(|| {
            i += 1;
            let phi = 0.1 * (i as f64 * 0.01).sin();
            black_box(m.update(black_box(phi), black_box(0.009)))
        })
    });
}

/// One fit of the loop (`rig identify`'s inner step, run hundreds of times per case) on 4000
/// samples of paper B's lever at a 9 mm pivot swung ±0.12 rad: with a config the envelope
/// follows the lever's curve, whose s(φ, d) the fit evaluates once per sample; straight lines
/// beside it for the ratio.
fn restoring_fit(c: &mut Criterion) {
    let vsa = LeverVsa::paper_b();
    let d = 0.009;
    let truth = RestoringParams {
        k: vsa.stiffness_at_rest(d),
        h: 0.004,
        a_s: 3.0,
        n: 0.7,
    };
    let mut m = RestoringTorqueModel::new(
        RestoringCurve::constant(truth).with_envelope(Envelope::Lever(vsa)),
        AS5048A_COUNT_RAD,
    );
    let samples: Vec<FitSample> = (0..4000)
        .map(|i| {
            let t = i as f64 * 1e-3;
            let phi = 0.12 * (0.7 + 0.3 * (0.9 * t).cos()) * (2.1 * t).sin();
            FitSample {
                phi,
                tau: m.update(phi, d),
                d,
            }
        })
        .collect();
    let mut g = c.benchmark_group("restoring fit, 4000 samples");
    g.sample_size(10);
    for (name, envelope) in [
        ("lever envelope", Envelope::Lever(vsa)),
        ("straight lines", Envelope::Linear),
    ] {
        let opts = FitOptions {
            envelope,
            ..FitOptions::default()
        };
        g.bench_function(name, |b| {
            b.iter(|| black_box(fit_restoring(black_box(&samples), &opts).unwrap()))
        });
    }
    g.finish();
}

fn parallel_force(c: &mut Criterion) {
    let robot = five_bar();
    let home = robot.at_position(0.075, 0.2).unwrap();
    let (t1, t2) = (home.theta[0], home.theta[1]);
    let tau = [0.3, -0.2, 0.5, 0.1];
    c.bench_function(
        "parallel force estimate (loop closure + Jacobians + F)",
        |b| {
            b.iter(|| {
                let cfg = robot
                    .from_independent(black_box(t1 + 1e-3), black_box(t2))
                    .unwrap();
                black_box(end_effector_force(&cfg.g_u_a, black_box(&tau)).unwrap())
            })
        },
    );
}

fn allocation_solve(c: &mut Criterion) {
    let cfg = five_bar().at_position(0.075, 0.2).unwrap();
    let problem = AllocationProblem::new(
        s_matrix(&cfg.g_u_a),
        DVector::from_vec(vec![0.258, 0.175, 0.258, 0.183]),
        DVector::from_vec(vec![50.0, 50.0, 60.0, 50.0]),
    )
    .unwrap();
    let target = problem.decoupled_target(25.0).unwrap();
    // The solver the allocator calls (closed form along the null space here) and the
    // reference it must agree with, in one run: their ratio is the figure to read.
    c.bench_function("allocation solve (closed form along the null space)", |b| {
        b.iter(|| black_box(problem.solve(black_box(target)).unwrap()))
    });
    c.bench_function("allocation solve (BVLS + active-set tie-break)", |b| {
        b.iter(|| black_box(problem.solve_by_active_sets(black_box(target)).unwrap()))
    });
}

criterion_group!(
    benches,
    observer_step,
    restoring_step,
    restoring_fit,
    parallel_force,
    allocation_solve
);
criterion_main!(benches);
