//! The papers' reproductions on short runs, against the targets of the simulation issue:
//! paper A (noisy, quantised, our tuning): stiffness ≤ 1 %, damping ≤ 2 %, inertia ≤ 2 %;
//! paper B: force RMSE ≤ 5 % of peak on every stroke, cross-axis spike reduced ≥ 90 %.

// Test helpers may panic: a failed helper is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use rig_sim::reproduce::paper_a::{self, PaperAOptions, Tuning};
use rig_sim::reproduce::paper_b::{self, PIVOTS_MM, PaperBOptions};

#[test]
fn paper_a_targets_on_a_short_run() {
    let cfg = rig_config::examples::load("awas").unwrap();
    let r = paper_a::run(&cfg, &PaperAOptions::quick(), &mut |_, _, _| {}).unwrap();
    assert_eq!(r.scenarios.len(), 4);
    let find = |noisy: bool, t: Tuning| {
        r.scenarios
            .iter()
            .find(|s| s.noisy == noisy && s.tuning == t)
            .unwrap()
    };
    let ours = find(true, Tuning::Ours);
    assert!(
        ours.stiffness_rel_err <= 0.01,
        "stiffness {}",
        ours.stiffness_rel_err
    );
    assert!(
        ours.damping_rel_err <= 0.02,
        "damping {}",
        ours.damping_rel_err
    );
    assert!(
        ours.inertia_rel_err <= 0.02,
        "inertia {}",
        ours.inertia_rel_err
    );
    assert!(ours.convergence_s.is_some_and(|t| t < 10.0));
    // On clean data the paper's own simulation tuning converges too.
    let clean = find(false, Tuning::Paper);
    assert!(
        clean.stiffness_rel_err < 0.01
            && clean.damping_rel_err < 0.01
            && clean.inertia_rel_err < 0.01,
        "{clean:?}"
    );
    // The paper's experimental gains on the same noisy data: errors of the order paper A
    // reports on hardware (9.4 % damping, 12.2 % inertia), far above ours.
    let paper = find(true, Tuning::Paper);
    assert!(
        paper.damping_rel_err > 5.0 * ours.damping_rel_err
            && paper.inertia_rel_err > 5.0 * ours.inertia_rel_err,
        "{paper:?}"
    );
}

#[test]
fn paper_a_noisy_targets_hold_for_other_seeds() {
    let cfg = rig_config::examples::load("awas").unwrap();
    for seed in [2, 3] {
        let o = PaperAOptions {
            seed,
            ..PaperAOptions::quick()
        };
        let s = paper_a::run_scenario(&cfg, true, Tuning::Ours, &o).unwrap();
        assert!(
            s.stiffness_rel_err <= 0.01 && s.damping_rel_err <= 0.02 && s.inertia_rel_err <= 0.02,
            "seed {seed}: {s:?}"
        );
    }
}

#[test]
fn paper_b_targets_on_a_short_run() {
    let serial = rig_config::examples::load("serial").unwrap();
    let parallel = rig_config::examples::load("parallel").unwrap();
    let r = paper_b::run(
        &serial,
        &parallel,
        &PaperBOptions::quick(),
        &mut |_, _, _| {},
    )
    .unwrap();
    // Table 1 layout: one row per calibrated pivot, the model within 15 % of peak everywhere.
    assert_eq!(r.torque_mae.len(), PIVOTS_MM.len());
    for t in &r.torque_mae {
        assert!(
            t.mae_nm < 0.15 * t.peak_nm,
            "d = {} mm: MAE {} of peak {}",
            t.d_mm,
            t.mae_nm,
            t.peak_nm
        );
    }
    // The fitted stiffness rises with the pivot position, as the lever's does.
    assert!(
        r.torque_mae
            .windows(2)
            .all(|w| w[1].k_nm_per_rad > w[0].k_nm_per_rad)
    );
    assert_eq!(r.force.len(), 4);
    for f in &r.force {
        assert!(
            f.rmse_pct_of_peak <= 5.0,
            "{} {}: {} %",
            f.robot,
            f.axis,
            f.rmse_pct_of_peak
        );
        assert!(
            f.peak_n > 0.1,
            "the stroke must load the robot: peak {}",
            f.peak_n
        );
    }
    assert_eq!(r.decoupling.len(), 3);
    for d in &r.decoupling {
        let reduction = 1.0 - d.spike_after_n / d.spike_before_n;
        assert!(
            reduction >= 0.90,
            "{} %: {} → {} N ({:.1} %)",
            d.percent,
            d.spike_before_n,
            d.spike_after_n,
            100.0 * reduction
        );
    }
}
