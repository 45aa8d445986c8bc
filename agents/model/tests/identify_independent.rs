//! `rig identify` on data it did not make: an independent generator (`plants/`) puts each
//! effect where it physically acts on three plants (a linear spring, paper B's lever with
//! Bouc-Wen friction, paper A's link equation), with random multi-sine and ramp-and-hold
//! motions, 100 Hz to 1 kHz, two noise levels, many seeds. Identification starts from the
//! plant's declared model, fits on one run and scores on a second run of the same plant.
//!
//! The asserted targets: each effect named alone, the held-out RMSE at least halved, and on
//! clean data nothing added. The full table of docs/IDENTIFY.md comes from
//! `cargo test --release -p rig-model --test identify_independent -- --ignored --nocapture`.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod plants;

use std::collections::HashMap;
use std::f64::consts::TAU;
use std::sync::{Mutex, OnceLock};

use plants::{Case, DryFriction, Inject, Motion, Plant, generate};
use rig_model::hysteresis::Envelope;
use rig_model::identify::{
    AT_SEARCH_BOUND, Declared, Holdout, Identified, Options, Place, Run, identify,
};
use rig_model::lever::LeverVsa;

fn run_of(name: &str, plant: Plant, d: &plants::Data) -> Run {
    let joint = plant != Plant::Link;
    Run {
        name: name.into(),
        t: d.t.clone(),
        tau: d.tau.clone(),
        phi: joint.then(|| d.x.clone()),
        // The lever's pivot position, as a recording of a lever joint carries it.
        d: (plant == Plant::Lever).then(|| vec![plants::PlantParams::of(plant).pivot; d.t.len()]),
        q: (!joint).then(|| d.x.clone()),
    }
}

fn lever_envelope() -> bool {
    std::env::var("LEVER_ENVELOPE").is_ok_and(|v| v == "1")
}

/// Identifies a case: fit on one run, held out on another (`BLOCKS=1`: the fit run alone,
/// its blocks held out, [`identify_one_file`]).
fn identify_case(c: &Case) -> Identified {
    if std::env::var_os("BLOCKS").is_some() {
        return identify_one_file(c);
    }
    let (a, b) = (generate(c, 0), generate(c, 1));
    let fit = [run_of("fit", c.plant, &a)];
    let held = [run_of("held", c.plant, &b)];
    identify_runs(&fit, &held, &options_of(c))
}

/// Identifies on the `fit` runs, the `held` runs held out.
fn identify_runs(fit: &[Run], held: &[Run], opts: &Options) -> Identified {
    identify(fit, Holdout::Runs(held), opts, &mut |_, _| {}).unwrap()
}

/// Identifies a case from its fit run alone, every fourth of its time blocks held out (as
/// `rig identify --data <one file>`).
fn identify_one_file(c: &Case) -> Identified {
    let fit = [run_of("fit", c.plant, &generate(c, 0))];
    identify(&fit, Holdout::Blocks, &options_of(c), &mut |_, _| {}).unwrap()
}

/// The options `rig identify` would use for a case's plant.
fn options_of(c: &Case) -> Options {
    Options {
        model: match c.plant {
            Plant::Linear => Declared::Linear,
            Plant::Lever => Declared::Restoring,
            Plant::Link => Declared::Link,
        },
        // As `rig identify` without a config: paper B's straight envelope lines, the lever
        // unknown. `LEVER_ENVELOPE=1`: as with a config naming the lever joint, whose table
        // follows the lever's curve (docs/IDENTIFY.md: the same names, a little lower held-out
        // errors, slower).
        lever: (c.plant == Plant::Lever && lever_envelope()).then(LeverVsa::paper_b),
        envelope: if c.plant == Plant::Lever && lever_envelope() {
            Envelope::Lever(LeverVsa::paper_b())
        } else {
            Envelope::Linear
        },
        min_gain: std::env::var("MIN_GAIN")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(Options::default().min_gain),
        rate_window: std::env::var("RATE_WINDOW")
            .ok()
            .and_then(|v| v.parse().ok()),
        // `STRAIGHT=1`: the restoring loop's lines kept straight (`rig identify --straight`).
        soften: std::env::var_os("STRAIGHT").is_none(),
        ..Options::default()
    }
}

/// The outcome of one case, beside its clean twin's (the same plant, motion and noise
/// without the effect: the floor no model can go under).
#[derive(Debug, Clone)]
struct Outcome {
    names: Vec<String>,
    /// The sensor each offset named sits on: "torque", "deflection", or "torque (or
    /// deflection)" where the report gives the encoder slip that fits as well.
    on: Vec<String>,
    before: f64,
    after: f64,
    floor: f64,
}

impl Outcome {
    /// For an offset named alone: whether the report's `on` is the sensor it was injected on
    /// (an encoder slip on a linear spring is a torque step k·δ: the library reports it on the
    /// torque). Not `strict`: also the torque where the report names the slip beside it as
    /// the alternative that fits as well.
    fn on_its_sensor(&self, inject: Inject, plant: Plant, strict: bool) -> bool {
        let want = match inject {
            Inject::EncoderSlip if plant != Plant::Linear => "deflection",
            _ => "torque",
        };
        match self.on.as_slice() {
            [on] => on.starts_with(want) || (!strict && on.contains(want)),
            _ => false,
        }
    }

    fn ratio(&self) -> f64 {
        self.after / self.before
    }

    /// The held-out RMSE at least halved, or down to the clean twin's floor (an effect
    /// smaller than the noise cannot halve it).
    fn paid_off(&self) -> bool {
        self.after <= (0.5 * self.before).max(1.25 * self.floor)
    }
}

/// The clean twin's held-out RMSE after identification, computed once per clean case (every
/// field of it: plant, motion, seed, rate, noise and its colour, encoder, amplitude).
fn floor_of(c: &Case) -> f64 {
    static FLOORS: OnceLock<Mutex<HashMap<String, f64>>> = OnceLock::new();
    // Without friction its holding makes no difference: one clean twin for both.
    let clean = Case {
        inject: None,
        friction: DryFriction::Released,
        ..*c
    };
    let key = format!("{clean:?}");
    let floors = FLOORS.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(f) = floors.lock().unwrap().get(&key) {
        return *f;
    }
    let f = identify_case(&clean).after.rmse;
    floors.lock().unwrap().insert(key, f);
    f
}

fn outcome(c: &Case) -> Outcome {
    outcome_of(c, &identify_case(c))
}

/// The outcome of `c` from its identification `r`.
fn outcome_of(c: &Case, r: &Identified) -> Outcome {
    let floor = if c.inject.is_some() {
        floor_of(c)
    } else {
        r.after.rmse
    };
    Outcome {
        names: r
            .effects
            .iter()
            .map(|e| e.effect.name().to_string())
            .collect(),
        on: r
            .effects
            .iter()
            .filter_map(|e| {
                let or_slip = e.params.iter().any(|(k, _)| k.starts_with("or_encoder"));
                match e.on? {
                    Place::Torque if or_slip => Some("torque (or deflection)".to_string()),
                    Place::Torque => Some("torque".to_string()),
                    Place::Deflection => Some("deflection".to_string()),
                }
            })
            .collect(),
        before: r.before.rmse,
        after: r.after.rmse,
        floor,
    }
}

/// Each effect of the plant on two seeds (a multi-sine and a ramp-and-hold motion, at 500
/// and 200 Hz, 0.5 % torque noise) and the clean plant on four: nothing added on clean data;
/// each effect named alone in at least the fraction `alone` of the cases, and named alone with
/// the held-out error paying off in `paid_off` of them. The full table (more seeds, 100 Hz to
/// 1 kHz, 2 % noise too) is in docs/IDENTIFY.md.
fn plant_meets_its_targets(plant: Plant, alone: f64, paid_off: f64) {
    let ci = |inject: Option<Inject>, seeds: std::ops::Range<u64>| -> Vec<Case> {
        seeds
            .map(|seed| {
                let rate_hz = if seed % 2 == 0 { 500.0 } else { 200.0 };
                case(plant, inject, 100 + seed, rate_hz, 0.005)
            })
            .collect()
    };
    for c in ci(None, 0..4) {
        let o = outcome(&c);
        assert!(o.names.is_empty(), "{c:?}: clean data, yet {:?}", o.names);
    }
    let (mut named, mut paid, mut total, mut report) = (0, 0, 0, Vec::new());
    for &inject in Inject::on(plant) {
        for c in ci(Some(inject), 0..2) {
            let o = outcome(&c);
            total += 1;
            // An offset is also a claim about which sensor moved: a torque offset is named on
            // the torque. (An encoder slip on the lever at ±0.06 rad fits as a torque step of
            // slope·δ within the noise, and is named there too: docs/IDENTIFY.md.)
            let alone = o.names == [inject.expected()]
                && (inject.expected() != "offset"
                    || inject == Inject::EncoderSlip
                    || o.on_its_sensor(inject, plant, true));
            named += usize::from(alone);
            paid += usize::from(alone && o.paid_off());
            report.push(format!(
                "{}: {:?} {:?}, held-out RMSE {:.5} → {:.5} (clean twin {:.5})",
                inject.label(),
                o.names,
                o.on,
                o.before,
                o.after,
                o.floor
            ));
        }
    }
    let (named_rate, paid_rate) = (named as f64 / total as f64, paid as f64 / total as f64);
    println!(
        "{}: named alone {named}/{total}, alone and paid off {paid}/{total}\n{}",
        plant.name(),
        report.join("\n")
    );
    assert!(
        named_rate >= alone && paid_rate >= paid_off,
        "{}: named alone in {named} of {total} cases ({:.0} %, want {:.0} %), alone and paid off in {paid} ({:.0} %, want {:.0} %):\n{}",
        plant.name(),
        100.0 * named_rate,
        100.0 * alone,
        100.0 * paid_rate,
        100.0 * paid_off,
        report.join("\n")
    );
}

#[test]
fn on_a_linear_spring_each_effect_is_named_alone_and_clean_data_gets_nothing() {
    plant_meets_its_targets(Plant::Linear, 0.9, 0.9);
}

#[test]
fn on_the_lever_with_bouc_wen_friction_each_effect_is_named_alone_and_clean_data_gets_nothing() {
    plant_meets_its_targets(Plant::Lever, 0.9, 0.9);
}

#[test]
fn on_the_link_equation_each_effect_is_named_alone_and_clean_data_gets_nothing() {
    // 12 of 14 on these seeds: the two lags left unnamed are within 1–3 % of the clean
    // twin's floor (under the noise: nothing can name them from these data).
    plant_meets_its_targets(Plant::Link, 0.8, 0.8);
}

#[test]
fn on_the_link_equation_an_encoders_noise_is_not_taken_for_a_lag() {
    // Two counts of encoder noise on slow ramps and holds: q̈ through ±10–80 ms windows was
    // more noise than signal, the inertia fitted low, and a lag of q̇ by −90 to −100 ms stood
    // in for it — named on every ramp-and-hold seed of clean data and beside every offset.
    // Wider windows where the narrow ones are still improving, and no lag that would take
    // the inertia's place.
    let noisy = |inject, seed, rate_hz, noise| Case {
        encoder_noise: 2.0,
        ..case(Plant::Link, inject, seed, rate_hz, noise)
    };
    for c in [noisy(None, 7, 100.0, 0.005), noisy(None, 9, 1000.0, 0.02)] {
        let o = outcome(&c);
        assert!(o.names.is_empty(), "{c:?}: clean data, yet {:?}", o.names);
    }
    let c = noisy(Some(Inject::TorqueOffset), 3, 200.0, 0.02);
    let o = outcome(&c);
    assert_eq!(o.names, ["offset"], "{c:?}");
    assert!(o.paid_off(), "{c:?}: {o:?}");
}

#[test]
fn on_the_link_equation_a_fast_motion_is_not_flattened_into_gravity_nor_a_lag_left_unfound() {
    // A multi-sine up to 4 Hz sampled at 200 Hz. Rates from a local quartic over ±80 ms took
    // q̈ 2 % short at 4 Hz: the clean model left 4× the torque noise and `gravity` (sin q is
    // −q̈/ω² on each sine) took part of it, named on clean data. In the weak form the torque
    // is smoothed as q̈ is, nothing is flattened: clean data gets nothing, the inertia within
    // 1 %, and a torque lag is named and reaches its clean twin's floor.
    let fast = |inject, seed, rate_hz| Case {
        f_max: 4.0,
        ..case(Plant::Link, inject, seed, rate_hz, 0.005)
    };
    let c = fast(None, 2, 200.0);
    let r = identify_case(&c);
    assert!(
        r.effects.is_empty(),
        "{c:?}: clean data, yet {:?}",
        r.effects
    );
    let inertia = r
        .base_after
        .iter()
        .find(|p| p.0 == "inertia_kgm2")
        .map(|p| p.1);
    assert!(
        inertia.is_some_and(|i| (i - 0.05).abs() < 0.0005),
        "{c:?}: inertia {inertia:?}, the plant's 0.05 kg·m²"
    );
    let c = fast(Some(Inject::TorqueLag), 4, 1000.0);
    let o = outcome(&c);
    assert_eq!(o.names, ["sensor_delay"], "{c:?}");
    assert!(o.paid_off() && o.after < 1.1 * o.floor, "{c:?}: {o:?}");
}

#[test]
fn on_the_link_equation_a_ripple_is_found_at_its_period_where_its_neighbours_on_the_grid_are_not() {
    // Ramps and holds at 100 Hz: the ripple's period was searched on a grid 11 % apart, and
    // over the link's range of 2 rad a period 0.30 rad off by half of that drifts 0.6 of a
    // period — both neighbours of the true period out of phase. A period of 0.25 rad won
    // (after/before 0.88, 22× the clean twin's floor). On a grid a quarter of a period over
    // the range apart, the ripple is found at its floor.
    let c = case(Plant::Link, Some(Inject::Ripple), 7, 100.0, 0.005);
    let o = outcome(&c);
    assert_eq!(o.names, ["periodic_ripple"], "{c:?}");
    assert!(o.after < 1.1 * o.floor, "{c:?}: {o:?}");
}

#[test]
fn on_the_link_equation_a_smoothed_residual_is_called_white_unless_something_is_left_in_it() {
    // In the weak form the residual is the smoothed torque's: noise alone has the smoother's
    // autocorrelation, which the whiteness test expects (it called every clean link residual
    // "not white: autocorrelation 1.00 at 1 ms"). A stop the link equation has no candidate
    // for is still found not white.
    for seed in [1, 2] {
        let c = case(Plant::Link, None, seed, 500.0, 0.005);
        let r = identify_case(&c);
        assert!(
            r.residual.white,
            "{c:?}: clean, yet {:?}",
            r.residual.structure
        );
    }
    let c = case(Plant::Link, Some(Inject::HardStop), 2, 500.0, 0.005);
    let r = identify_case(&c);
    assert!(
        !r.residual.white,
        "{c:?}: a stop left in the residual, called white"
    );
}

#[test]
fn an_encoders_noise_is_averaged_out_before_the_joint_models_see_it() {
    // Two counts rms of encoder noise (the measured springs' encoder carries one to three).
    // Read raw, every small retreat of the noise reversed the loop, and a lag "gained" by
    // averaging the noise it interpolated: clean lever data named a lag (at 0.55 of the
    // held-out error) or Coulomb friction, a linear spring's hysteresis came with a lag.
    let noisy = |plant, inject, seed, rate_hz| Case {
        encoder_noise: 2.0,
        ..case(plant, inject, seed, rate_hz, 0.005)
    };
    for c in [
        noisy(Plant::Lever, None, 1, 1000.0),
        noisy(Plant::Lever, None, 4, 500.0),
    ] {
        let o = outcome(&c);
        assert!(o.names.is_empty(), "{c:?}: clean data, yet {:?}", o.names);
    }
    let c = noisy(Plant::Linear, Some(Inject::Hysteresis), 1, 1000.0);
    let o = outcome(&c);
    assert_eq!(o.names, ["hysteresis"], "{c:?}");
    assert!(o.paid_off(), "{c:?}: {o:?}");
}

#[test]
fn under_an_encoders_noise_viscous_friction_is_not_taken_for_a_lag_of_the_deflection() {
    // On a joint model a lag of the deflection is, to first order, viscous friction
    // (τ̂(x(t + δ)) ≈ τ̂ + k·|δ|·ẋ). With two counts of encoder noise the lag validated up to
    // 10 % better — its shifted angle carries the angle's noise only, friction's column the
    // rate's as well — and was named for the friction on 7 of 10 seeds, or beside it.
    for (seed, rate_hz) in [(7, 100.0), (2, 200.0)] {
        let c = Case {
            encoder_noise: 2.0,
            ..case(Plant::Linear, Some(Inject::Viscous), seed, rate_hz, 0.005)
        };
        viscous_friction_is_named_alone_and_sized(&c);
    }
}

/// Viscous friction on a linear spring named alone, b within 10 % of the generator's, and the
/// held-out error within 15 % of the clean twin's.
fn viscous_friction_is_named_alone_and_sized(c: &Case) {
    let truth = generate(c, 0).size / plants::viscous_rate_scale(c);
    let id = identify_case(c);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["viscous_friction"], "{c:?}");
    let b = param_of(&id, "damping_nms_per_rad");
    assert!(
        (b / truth - 1.0).abs() < 0.1,
        "{c:?}: b {b} against {truth}"
    );
    within_the_clean_twin(c, &id, 1.15);
}

#[test]
fn with_paper_bs_14_bit_encoder_viscous_friction_is_not_taken_for_a_lag_of_the_deflection() {
    // Paper B's AS5048A (14 bits) over ±0.06 rad: its counts reach a 2 N·m/rad spring's torque
    // as k·q/√12, 12 % of 0.5 % torque noise in variance. A lag of the deflection interpolates
    // the counts (and its delay is chosen on the validation blocks, where the friction's b is
    // fitted low on a rate the counts make noisy): it validated 2–5 % better than the viscous
    // friction that was there and was named for it (1 kHz ramp-and-hold; 200 Hz ramp-and-hold
    // at 2 % noise), or beside it (200 Hz multi-sine).
    let fourteen_bit = |c: Case| Case {
        counts: 16384.0,
        amplitude: 0.0,
        ..c
    };
    let clean = fourteen_bit(cases(Plant::Linear, None, 1..2)[0]);
    let o = outcome(&clean);
    assert!(
        o.names.is_empty(),
        "{clean:?}: clean data, yet {:?}",
        o.names
    );
    for seed in [1, 2, 3] {
        let c = fourteen_bit(cases(Plant::Linear, Some(Inject::Viscous), seed..seed + 1)[0]);
        viscous_friction_is_named_alone_and_sized(&c);
    }
}

#[test]
fn a_stop_the_data_barely_passes_on_one_side_is_found_as_one_stop_on_both() {
    // Lever, 100 Hz ramp-and-hold: the wound side passes the stop's onset by little, and a
    // stop of its own there traded onset for rate (found at 0.3 of the rate, 5× the clean
    // twin's error held out). One stop on both sides, MODEL.md's k_s·max(|x| − x_s, 0)·sgn x,
    // is searched in its own family.
    // Linear spring, 500 Hz ramp-and-hold: the fit run holds 1282 samples 0.2 mrad past the
    // onset (39.80 mrad). With the one stop's onset refined to 47 µrad it landed 14 µrad off,
    // and a pair whose free side fitted the hold (38.34 mrad at the spring's own 2 N·m/rad,
    // against 8) validated better: 11× the clean twin's error held out. Now refined to
    // under a µrad.
    for (plant, seed, rate_hz) in [(Plant::Lever, 7, 100.0), (Plant::Linear, 5, 500.0)] {
        let c = case(plant, Some(Inject::HardStop), seed, rate_hz, 0.005);
        let truth = generate(&c, 0).size;
        let id = identify_case(&c);
        let up = param_of(&id, "onset_rad");
        let down = param_of(&id, "onset_negative_rad");
        assert!(
            (up / truth - 1.0).abs() < 0.03,
            "{c:?}: onset {up} against {truth}"
        );
        assert!(
            (-down / truth - 1.0).abs() < 0.03,
            "{c:?}: onset {down} against −{truth}"
        );
        let (k_up, k_down) = (
            param_of(&id, "stop_rate_nm_per_rad"),
            param_of(&id, "stop_rate_negative_nm_per_rad"),
        );
        assert!(
            (k_up / k_down - 1.0).abs() < 0.1,
            "{c:?}: rates {k_up}, {k_down}"
        );
        within_a_tenth_of_the_clean_twin(&c, &id);
    }
}

/// A parameter of the one effect a case's identification named.
fn param_of(id: &Identified, name: &str) -> f64 {
    assert_eq!(id.effects.len(), 1, "{:?}", id.effects);
    let e = &id.effects[0];
    e.param(name)
        .unwrap_or_else(|| panic!("no {name} in {:?}", e.params))
}

/// The held-out error of a case's identification within 10 % of its clean twin's.
fn within_a_tenth_of_the_clean_twin(c: &Case, id: &Identified) {
    within_the_clean_twin(c, id, 1.1);
}

/// The held-out error of a case's identification under `factor` × its clean twin's.
fn within_the_clean_twin(c: &Case, id: &Identified, factor: f64) {
    let floor = floor_of(c);
    assert!(
        id.after.rmse < factor * floor,
        "{c:?}: held-out {} against the clean twin's {floor}",
        id.after.rmse
    );
}

#[test]
fn on_the_lever_an_encoder_slip_is_sized_in_full_though_the_loop_can_hold_part_of_it() {
    // 100 Hz, ramp-and-hold, a 4.8 mrad slip at 20.2 s: alternating slip and loop settled at
    // 2.9 mrad (the loop stiffer and taller), and from the best jump instant after one round
    // the loop bent until it was no spring and nothing was named.
    let c = case(Plant::Lever, Some(Inject::EncoderSlip), 7, 100.0, 0.005);
    let truth = generate(&c, 0).size;
    let id = identify_case(&c);
    // On the encoder, or on the torque naming the slip that fits as well (at ±0.06 rad the
    // lever's slope hardly changes: docs/IDENTIFY.md).
    let on_encoder = id.effects.iter().any(|e| e.on == Some(Place::Deflection));
    let jump = param_of(
        &id,
        if on_encoder {
            "jump_rad"
        } else {
            "or_encoder_jump_rad"
        },
    );
    assert!(
        (jump.abs() / truth.abs() - 1.0).abs() < 0.05,
        "slip {jump} against {truth}"
    );
    within_a_tenth_of_the_clean_twin(&c, &id);
}

#[test]
fn under_a_torque_sensors_coloured_noise_a_step_is_placed_where_it_happened() {
    // 500 Hz multi-sine, the torque noise through a 20 ms low-pass: a step at 11.50 s lies
    // inside a train block, where every instant leaves the validation rows alike, and the
    // one they chose (11.27 s, their noise deciding) left the held-out run 1.7× its clean
    // twin's error. Placed by least squares on the fit rows: where it happened.
    for (plant, seed) in [(Plant::Linear, 4), (Plant::Link, 4)] {
        let c = Case {
            noise_tau_ms: 20.0,
            ..case(plant, Some(Inject::TorqueStep), seed, 500.0, 0.005)
        };
        let id = a_torque_offset_is_named_alone_and_sized(&c, "jump_nm", 0.05);
        let (at, truth) = (param_of(&id, "jump_at_s"), generate(&c, 0).jump_at_s);
        assert!(
            (at - truth).abs() < 0.05,
            "{c:?}: jump at {at} s against {truth} s"
        );
    }
}

#[test]
fn in_one_file_a_step_inside_a_held_out_block_is_named_and_put_at_the_blocks_middle() {
    // 1 kHz multi-sine, 2 % noise, fitted on its one run with every fourth of twelve blocks
    // held out: the step at 9.40 s lies in the held-out block [7.5, 10) s, where the fit rows
    // cannot place it. At the block's end (where the searches put it) the step was wrong over
    // most of the block, the held-out error rose, and the step was refused: nothing named.
    // At the block's middle it is named, and cuts the held-out error.
    let c = case(Plant::Linear, Some(Inject::TorqueStep), 0, 1000.0, 0.02);
    a_jump_in_a_held_out_block_is_named_alone_at_its_middle(&c, (7.5, 10.0));
}

/// Fitted on its one run with every fourth of twelve blocks held out, a case whose jump lies
/// in the held-out block `block` [s]: the offset named alone, at the block's middle (within
/// 10 ms), and the held-out error cut by a fifth at least.
fn a_jump_in_a_held_out_block_is_named_alone_at_its_middle(
    c: &Case,
    block: (f64, f64),
) -> Identified {
    let truth = generate(c, 0).jump_at_s;
    assert!((block.0..block.1).contains(&truth), "{truth}");
    let id = identify_one_file(c);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["offset"]);
    let at = param_of(&id, "jump_at_s");
    let middle = 0.5 * (block.0 + block.1);
    assert!((at - middle).abs() < 0.01, "jump at {at} s");
    assert!(
        id.after.rmse < 0.8 * id.before.rmse,
        "held out {} -> {}",
        id.before.rmse,
        id.after.rmse
    );
    id
}

#[test]
fn in_one_file_on_the_lever_a_jump_found_past_a_held_out_blocks_end_is_put_at_its_middle() {
    // The lever at 200 Hz, ramp-and-hold, 2 % noise, one run, every fourth of twelve blocks
    // held out: the encoder slips in the held-out block [17.5, 20) s. The slip's search refines
    // its instant between the instants it tried and ended 3 rows past the block's end, where
    // the step was wrong over most of the block and refused (nothing named). The fit rows fit
    // better with the jump anywhere in the block, so it goes to the block's middle.
    let c = case(Plant::Lever, Some(Inject::EncoderSlip), 3, 200.0, 0.02);
    let id = a_jump_in_a_held_out_block_is_named_alone_at_its_middle(&c, (17.5, 20.0));
    // The report says the jump is somewhere in the block: the fit rows either side of it.
    let (from, to) = (
        param_of(&id, "held_out_block_from_s"),
        param_of(&id, "held_out_block_to_s"),
    );
    assert!(
        (from - 17.5).abs() < 0.01 && (to - 20.0).abs() < 0.01,
        "{from}–{to}"
    );
}

#[test]
fn on_the_lever_viscous_friction_is_sized_in_full_and_not_taken_for_a_lag_of_the_angle() {
    // 200 Hz multi-sine: with loop and coefficient alternated, the loop kept part of the
    // friction as height and a 32 ms lag of the angle validated 5 % better than the friction.
    let c = case(Plant::Lever, Some(Inject::Viscous), 2, 200.0, 0.005);
    let truth = generate(&c, 0).size / plants::viscous_rate_scale(&c);
    let id = identify_case(&c);
    let b = param_of(&id, "damping_nms_per_rad");
    assert!((b / truth - 1.0).abs() < 0.1, "b {b} against {truth}");
    within_a_tenth_of_the_clean_twin(&c, &id);
}

#[test]
fn a_deflection_read_late_on_a_linear_spring_is_named_viscous_friction_with_the_lag_that_fits_as_well()
 {
    // τ = k·x(t) against an angle read δ late: τ = k·x_read(t + δ) ≈ k·x_read + k·δ·ẋ_read,
    // viscous friction b = k·δ to first order. The second order, ½·k·δ²·ẍ, is under the
    // noise at the generator's sines (up to 1 Hz): the data cannot tell the two apart. The
    // friction is named, and its params give the lag that validated as well.
    let c = case(Plant::Linear, Some(Inject::AngleLag), 2, 500.0, 0.005);
    let delta = generate(&c, 0).size;
    let id = identify_case(&c);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["viscous_friction"]);
    let lag = param_of(&id, "or_delay_s");
    assert!(
        (lag / -delta - 1.0).abs() < 0.1,
        "lag alike {lag} s against the deflection's {delta} s late"
    );
    let k = plants::PlantParams::for_case(&c).k_linear;
    let b = param_of(&id, "damping_nms_per_rad");
    assert!(
        (b / (k * delta) - 1.0).abs() < 0.1,
        "b {b} against k·δ {}",
        k * delta
    );
    within_a_tenth_of_the_clean_twin(&c, &id);
}

#[test]
fn on_the_lever_a_torque_lag_that_runs_the_residual_loop_backwards_is_named_though_it_gains_little()
{
    // 100 Hz, ramp-and-hold, 0.5 % noise: the loop absorbs most of the lag (3.7 % validation
    // gain, under the 5 % floor), but what is left gives energy back — a loop no passive part
    // draws, which the selection takes as evidence for a lag of the torque path.
    let c = case(Plant::Lever, Some(Inject::TorqueLag), 7, 100.0, 0.005);
    let truth = generate(&c, 0).size;
    let id = identify_case(&c);
    assert!(
        id.residual.loop_before < -0.1,
        "{}",
        id.residual.loop_before
    );
    let delay = param_of(&id, "delay_s");
    assert!(
        (delay / truth - 1.0).abs() < 0.3,
        "lag {delay} s against {truth} s"
    );
}

#[test]
fn on_a_lever_that_softens_over_its_travel_a_torque_offset_is_named_not_held_by_a_taller_loop() {
    // ±0.15 rad at the 9 mm pivot, 13 % softer at the ends than at rest; 200 Hz multi-sine,
    // 0.5 % noise. Without the offset beside it the loop fitted 5× taller and its transitions,
    // whose power law follows the softening as well, carried the offset from reversal to
    // reversal: the fit run explained, the offset's column gained nothing beside that loop,
    // and the held-out run (another motion) was 10× its clean twin's floor with nothing named.
    let c = Case {
        amplitude: 0.15,
        ..case(Plant::Lever, Some(Inject::TorqueOffset), 2, 200.0, 0.005)
    };
    a_torque_offset_is_named_alone_and_sized(&c, "bias_nm", 0.1);
}

#[test]
fn a_torque_offset_under_three_times_the_noise_is_named_from_its_tare_where_the_held_out_data_confirms_it()
 {
    // The lever at 1 kHz ramp-and-hold, 3 % noise: the offset (8 % of the peak torque) is
    // 2.7 times the noise at rest, its mean over the rest (half a second or more of 1 kHz
    // samples) over 60 standard errors out. It was tared and not named: a tare was named
    // only over three times the noise, sample by sample. That it lowers the held-out error by
    // far more than `min_gain` now names it.
    let c = case(Plant::Lever, Some(Inject::TorqueOffset), 1, 1000.0, 0.03);
    let id = a_torque_offset_is_named_alone_and_sized(&c, "bias_nm", 0.05);
    assert!(
        id.tare
            .iter()
            .all(|t| t.torque_zero.abs() < 3.0 * t.torque_noise),
        "{:?}",
        id.tare
    );
    assert_eq!(param_of(&id, "from_tare"), 1.0);
}

#[test]
fn on_a_lever_that_softens_a_tare_of_micronewton_metres_leaves_the_declared_loop_where_it_was() {
    // ±0.15 rad, 1 kHz ramp-and-hold with a torque lag: the tare (26 µN·m) changed the data
    // by a thousandth of its noise, yet the declared loop refitted from the grid landed in
    // another least squares, 8 % worse held out than the data as given (7.23 against
    // 6.66 mN·m) with nothing named. The loop fitted untared is a start too now, and a fresh
    // fit runs from the grid's best four starts: both reach 6.13 mN·m, within a thousandth.
    let c = Case {
        amplitude: 0.15,
        ..case(Plant::Lever, Some(Inject::TorqueLag), 1, 1000.0, 0.005)
    };
    let id = identify_case(&c);
    assert!(
        id.tare.iter().all(|t| t.torque_zero.abs() < 1e-4),
        "{:?}",
        id.tare
    );
    assert!(
        id.tared.rmse <= 1.001 * id.before.rmse,
        "tared {} against {} as given",
        id.tared.rmse,
        id.before.rmse
    );
    assert!(id.after.rmse <= 1.001 * id.before.rmse);
}

#[test]
fn a_spring_that_reseats_part_way_is_named_a_stiffness_step_at_its_instant_not_a_drift() {
    // The spring's stiffness changes at once part-way. 1 kHz ramp-and-hold: a step placed
    // among the grid's instants refined between neighbours (12.890 s, 15 ms from where the
    // residual points) left 1.27× the clean twin's error held out; 100 Hz multi-sine at 2 %
    // noise: a drift over the run (+36 %) validated better than a step placed on the grid
    // (1.56×). Its instant is now also where the residual points (the step's column with the
    // spring's own projected out), placed on the fit rows.
    for seed in [1, 6] {
        let c = cases(Plant::Linear, Some(Inject::StiffnessStep), seed..seed + 1)[0];
        let data = generate(&c, 0);
        let id = identify_case(&c);
        let step = param_of(&id, "stiffness_step");
        assert!(
            (step / data.size - 1.0).abs() < 0.05,
            "{c:?}: step {step} against {}",
            data.size
        );
        let at = param_of(&id, "step_at_s");
        assert!(
            (at - data.jump_at_s).abs() < 0.1,
            "{c:?}: step at {at} s against {} s",
            data.jump_at_s
        );
        within_a_tenth_of_the_clean_twin(&c, &id);
    }
}

/// Case `c` (a torque offset or step) names the offset alone, on the torque, its parameter
/// `param` within `tolerance` of the truth, the held-out error within a tenth of the clean
/// twin's. Returns the identification.
fn a_torque_offset_is_named_alone_and_sized(c: &Case, param: &str, tolerance: f64) -> Identified {
    let truth = generate(c, 0).size;
    let id = identify_case(c);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["offset"]);
    assert_eq!(id.effects[0].on, Some(Place::Torque));
    let size = param_of(&id, param);
    assert!(
        (size / truth - 1.0).abs() < tolerance,
        "{param} {size} against {truth}"
    );
    within_a_tenth_of_the_clean_twin(c, &id);
    id
}

#[test]
fn dry_friction_that_holds_its_force_where_the_motion_stops_is_named_alone_and_said_to_be_held() {
    // Ramp-and-hold motions whose friction keeps its force through each hold (a stuck contact,
    // as a bristle or elastoplastic model has), the linear spring at 200 Hz and 2 % noise, the
    // link equation at 1 kHz: with the force released at rest the only shape tried, the
    // holds' ±F_c was taken up by a narrow `hysteresis` stop (the spring) or by `gravity` (the
    // link) beside the friction, at 1.6× and 54× the clean twins' errors. The same cases with
    // the force released at rest are still named so.
    for (plant, seed, rate_hz, noise) in [
        (Plant::Linear, 3, 200.0, 0.02),
        (Plant::Link, 1, 1000.0, 0.005),
    ] {
        for held in [true, false] {
            let c = Case {
                friction: if held {
                    DryFriction::Held
                } else {
                    DryFriction::Released
                },
                ..case(plant, Some(Inject::Coulomb), seed, rate_hz, noise)
            };
            let id = dry_friction_named_alone_and_sized(&c, 0.1);
            assert_eq!(param_of(&id, "held_at_rest"), f64::from(held), "{c:?}");
        }
    }
}

#[test]
fn a_held_contact_turns_where_its_torque_steps_before_the_counted_angle_has_moved() {
    // Ramp-and-hold motions start from rest as quintics: the angle moves less than a count for
    // tens of milliseconds while the held friction has already turned. With the turn placed
    // where the counted rate took the new sign, the few samples between were left to a
    // `sensor_delay` beside the friction (these two cases, and 3 of the table's 10 linear and
    // 2 of its 10 link seeds with FRICTION=held). The linear spring at 500 Hz and the link
    // equation at 100 Hz, 0.5 % noise.
    for (plant, seed, rate_hz) in [(Plant::Linear, 5, 500.0), (Plant::Link, 7, 100.0)] {
        let c = Case {
            friction: DryFriction::Held,
            ..case(plant, Some(Inject::Coulomb), seed, rate_hz, 0.005)
        };
        let id = dry_friction_named_alone_and_sized(&c, 0.05);
        assert_eq!(param_of(&id, "held_at_rest"), 1.0, "{c:?}");
    }
}

#[test]
fn dry_friction_built_up_over_a_small_speed_is_named_alone_with_that_speed() {
    // F_c·tanh(ẋ/v_s), v_s a twentieth of the rms rate scale: a contact that slides a little
    // before it slips. Read as F_c·sgn(ẋ), the force's build-up through every reversal was
    // left to viscous friction beside it (this linear case, and 3 of the table's 10 linear
    // seeds), or the friction was named alone at 1.7× (linear spring) and 5.5× (link) the clean
    // twin's error (medians). The linear spring at 200 Hz on a multi-sine, the link equation at
    // 1 kHz ramp-and-hold and multi-sine, 0.5 % noise; the same cases with the force released
    // at rest are still named dry friction alone. On the link's multi-sine (seed 8) the speed
    // is judged on rows smoothed over ±40 ms: on the ±0.16 s the inertia's noise chose, the
    // build-up was averaged into the sign's step, the speed did not pay, and the sign left
    // 12.8× the clean twin's error held out.
    for (plant, seed, rate_hz) in [
        (Plant::Linear, 10, 200.0),
        (Plant::Link, 1, 1000.0),
        (Plant::Link, 8, 1000.0),
    ] {
        for shape in [DryFriction::Smooth(0.05), DryFriction::Released] {
            let c = Case {
                friction: shape,
                ..case(plant, Some(Inject::Coulomb), seed, rate_hz, 0.005)
            };
            let id = dry_friction_named_alone_and_sized(&c, 0.1);
            if let DryFriction::Smooth(frac) = shape {
                let v_s = param_of(&id, "builds_over_rad_per_s");
                let v_true = frac * plants::viscous_rate_scale(&c);
                assert!(
                    (v_s / v_true).ln().abs() < 1.5f64.ln(),
                    "{c:?}: v_s {v_s} against {v_true}"
                );
            }
        }
    }
}

#[test]
fn a_lag_found_at_the_bound_of_the_lags_searched_is_named_but_said_not_to_be_located() {
    // A linear spring with a Stribeck peak (1 kHz ramp-and-hold, 2 % noise; docs/IDENTIFY.md,
    // Left): the validation error of a lag of the deflection falls all the way to the bound of
    // the ±100 ms searched. The lag is named, it lowers the held-out error, and the report flags
    // its δ as the bound, not a located lag, so `--apply` leaves the rig's timing alone.
    // (Refusing such lags named nothing on 3 of 10 link seeds under encoder noise.)
    let c = Case {
        friction: DryFriction::Stribeck(0.05),
        ..case(Plant::Linear, Some(Inject::Coulomb), 9, 1000.0, 0.02)
    };
    let id = identify_case(&c);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["sensor_delay"], "{c:?}");
    let delay = param_of(&id, "delay_s");
    assert!((delay + 0.1).abs() < 1e-9, "{c:?}: δ {delay} s");
    assert_eq!(param_of(&id, AT_SEARCH_BOUND), 1.0, "{c:?}");
    assert!(id.after.rmse < id.before.rmse, "{c:?}: {id:?}");
    // Lags inside the range carry no flag: the link's angle lagging under two counts of encoder
    // noise, seed 1 (28.6 ms; at the bound until jittered samples were read onto a uniform
    // grid) and seed 2 (−18.5 ms). Seed 1's is located: within 5 % of the generator's.
    for seed in 1..3 {
        let c = Case {
            encoder_noise: 2.0,
            ..cases(Plant::Link, Some(Inject::AngleLag), seed..seed + 1)[0]
        };
        let id = identify_case(&c);
        let lag = id
            .effects
            .iter()
            .find(|e| e.effect.name() == "sensor_delay");
        assert!(
            lag.is_some_and(|e| e.params.iter().all(|p| p.0 != AT_SEARCH_BOUND)),
            "{c:?}: {:?}",
            id.effects
        );
        if seed == 1 {
            let (truth, delay) = (generate(&c, 0).size, param_of(&id, "delay_s"));
            assert!(
                (-delay / truth - 1.0).abs() < 0.05,
                "{c:?}: δ {delay} s, the generator's lag {truth} s"
            );
        }
    }
}

/// Identifies `c`, whose injected effect is dry friction, and checks that it is named alone,
/// its F_c within `tolerance` (relative) of the generator's, and that it paid off held out.
fn dry_friction_named_alone_and_sized(c: &Case, tolerance: f64) -> Identified {
    let truth = generate(c, 0).size;
    let id = identify_case(c);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["coulomb_friction"], "{c:?}");
    let f = param_of(&id, "friction_nm");
    assert!(
        (f / truth - 1.0).abs() < tolerance,
        "{c:?}: F_c {f} against {truth}"
    );
    let o = outcome_of(c, &id);
    assert!(o.paid_off(), "{c:?}: {o:?}");
    id
}

#[test]
fn with_paper_bs_14_bit_encoder_a_torque_steps_instant_is_found_again_from_the_loop_fitted_with_it()
{
    // The lever at 1 kHz, 2 % noise, a 12.7 mN·m step at 9.4 s: the instants tried were read
    // against a loop that held the step, and the one that validated best (7.7 s) lay a train
    // block early — the validation blocks cannot place a jump inside a train block — leaving a
    // residual so correlated (N_eff 51 of 29 000 rows) that the criterion refused a 24 % gain.
    let c = Case {
        counts: 16384.0,
        ..case(Plant::Lever, Some(Inject::TorqueStep), 0, 1000.0, 0.02)
    };
    a_torque_offset_is_named_alone_and_sized(&c, "jump_nm", 0.05);
}

#[test]
fn on_a_link_turning_where_gravitys_sine_is_flat_an_offset_is_named_an_offset_and_gravity_gravity()
{
    // ±0.3 rad at 500 Hz, multi-sine: sin(q + q₀) with q₀ near π/2 is a constant to 4 % over
    // that swing, and gravity's second column fitted what the rates' smoothing left: the
    // torque offset was named gravity (its held-out error 5 % over the clean twin's floor).
    // Tied on validation, the offset is named; a real gravity over the same swing still is.
    let offset = Case {
        amplitude: 0.3,
        ..case(Plant::Link, Some(Inject::TorqueOffset), 4, 500.0, 0.005)
    };
    a_torque_offset_is_named_alone_and_sized(&offset, "bias_nm", 0.05);
    let gravity = Case {
        inject: Some(Inject::Gravity),
        ..offset
    };
    let id = identify_case(&gravity);
    let names: Vec<&str> = id.effects.iter().map(|e| e.effect.name()).collect();
    assert_eq!(names, ["gravity"]);
    let mgl = param_of(&id, "mgl_nm");
    let truth = generate(&gravity, 0).size;
    assert!(
        (mgl / truth - 1.0).abs() < 0.02,
        "m·g·l {mgl} against {truth}"
    );
    // Within 30 % of the clean twin's error: its floor is 0.24 mN·m since the 14-bit angle is
    // read as the taut string through its counts (1.2 mN·m as a staircase; 0.28 until the
    // jittered samples were read onto a uniform grid), and what gravity leaves over it,
    // 0.2 mN·m, is a tenth of a per cent of gravity's torque (the string cuts inside the
    // swing's turns by up to half a count; an 18-bit encoder fitted m·g·l 0.4 % over where
    // this one fitted it 1 % over).
    within_the_clean_twin(&gravity, &id, 1.3);
}

/// One case: even seeds a multi-sine, odd ones ramp-and-hold.
fn case(plant: Plant, inject: Option<Inject>, seed: u64, rate_hz: f64, noise: f64) -> Case {
    Case {
        plant,
        inject,
        motion: if seed.is_multiple_of(2) {
            Motion::MultiSine
        } else {
            Motion::RampHold
        },
        rate_hz,
        noise,
        encoder_noise: 0.0,
        counts: 0.0,
        amplitude: 0.0,
        noise_tau_ms: 0.0,
        f_max: 0.0,
        friction: DryFriction::Released,
        seed,
    }
}

fn cases(plant: Plant, inject: Option<Inject>, seeds: std::ops::Range<u64>) -> Vec<Case> {
    seeds
        .map(|seed| {
            let rate_hz = [1000.0, 200.0, 500.0, 100.0][(seed / 2 % 4) as usize];
            let noise = if seed % 3 == 0 { 0.02 } else { 0.005 };
            case(plant, inject, seed, rate_hz, noise)
        })
        .collect()
}

#[test]
#[ignore = "prints the table of docs/IDENTIFY.md (minutes): run with --ignored --nocapture"]
fn table_over_many_seeds() {
    let only: Option<String> = std::env::var("PLANT").ok();
    let seeds: u64 = std::env::var("SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(12);
    // VERBOSE=1 lists every case's names on stderr; SEED0 starts the seeds elsewhere. Stress
    // runs change the generator (plants/mod.rs): SIZE_SCALE scales every effect (a larger stop
    // engages earlier), NOISE_SCALE the torque noise, DURATION_S the runs' length, and the
    // plants' own parameters move with AMPLITUDE_SCALE, K_LINEAR, PIVOT_MM, BW_SHARE, BW_YIELD,
    // BW_N, BW_GAMMA, INERTIA, DAMPING, COUNTS and F_MAX (`plants::PlantParams`), the torque
    // noise's colour with NOISE_TAU_MS (a sensor's low-pass, same rms), dry friction held at
    // rest with FRICTION=held or built up over TANH_VS of the rms rate with FRICTION=tanh (else
    // released). BLOCKS=1 fits each case on its one run with every fourth of its twelve time
    // blocks held out (`rig identify --data <one file>`), clean twins likewise. MIN_GAIN
    // overrides identify's smallest validation gain (default 5 %), RATE_WINDOW fixes the rates'
    // half-window [s] (else identify chooses it).
    println!(
        "| plant (declared model) | effect | named alone | alone and paid off | held-out RMSE after/before (median) | after / clean twin's (median) | what else was named | offset on its sensor (or the slip named beside it) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for plant in [Plant::Linear, Plant::Lever, Plant::Link] {
        if only
            .as_deref()
            .is_some_and(|o| !plant.name().starts_with(o))
        {
            continue;
        }
        let mut rows: Vec<Option<Inject>> = vec![None];
        rows.extend(Inject::on(plant).iter().copied().map(Some));
        for inject in rows {
            // EFFECT=<label prefix> keeps one row (with its clean twins).
            if std::env::var("EFFECT")
                .is_ok_and(|e| !inject.map_or("none (clean)", Inject::label).starts_with(&e))
            {
                continue;
            }
            let seed0: u64 = std::env::var("SEED0")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(0);
            let outs: Vec<Outcome> = cases(plant, inject, seed0..seed0 + seeds)
                .iter()
                .map(outcome)
                .collect();
            if std::env::var_os("VERBOSE").is_some() {
                for (seed, o) in outs.iter().enumerate() {
                    eprintln!(
                        "  {} seed {seed}: {:?} {:?} after/before {:.2} after/floor {:.2}",
                        inject.map_or("none (clean)", Inject::label),
                        o.names,
                        o.on,
                        o.ratio(),
                        o.after / o.floor
                    );
                }
            }
            let want: Vec<String> = inject
                .map(|i| vec![i.expected().to_string()])
                .unwrap_or_default();
            let alone = outs.iter().filter(|o| o.names == want).count();
            let paid = outs
                .iter()
                .filter(|o| o.names == want && o.paid_off())
                .count();
            let mut ratios: Vec<f64> = outs.iter().map(Outcome::ratio).collect();
            ratios.sort_by(f64::total_cmp);
            let mut floors: Vec<f64> = outs.iter().map(|o| o.after / o.floor).collect();
            floors.sort_by(f64::total_cmp);
            let mut other: Vec<String> = outs
                .iter()
                .filter(|o| o.names != want)
                .map(|o| {
                    if o.names.is_empty() {
                        "nothing".into()
                    } else {
                        o.names.join("+")
                    }
                })
                .collect();
            other.sort();
            other.dedup();
            let sensor = match inject {
                Some(i) if i.expected() == "offset" => {
                    let alone: Vec<&Outcome> = outs.iter().filter(|o| o.names == want).collect();
                    let on = |strict| {
                        alone
                            .iter()
                            .filter(|o| o.on_its_sensor(i, plant, strict))
                            .count()
                    };
                    format!("{}/{} ({})", on(true), alone.len(), on(false))
                }
                _ => String::new(),
            };
            println!(
                "| {} | {} | {}/{} | {}/{} | {:.2} | {:.2} | {} | {sensor} |",
                plant.name(),
                inject.map_or("none (clean)", Inject::label),
                alone,
                outs.len(),
                paid,
                outs.len(),
                ratios[ratios.len() / 2],
                floors[floors.len() / 2],
                other.join(", ")
            );
        }
    }
}

#[test]
#[ignore = "debugging aid: CASE=plant,effect,seed[,rate_hz,noise]"]
fn one_case() {
    let spec = std::env::var("CASE").unwrap_or_default();
    let parts: Vec<&str> = spec.split(',').collect();
    let plant = match parts[0] {
        "linear" => Plant::Linear,
        "lever" => Plant::Lever,
        _ => Plant::Link,
    };
    let inject = Inject::on(plant)
        .iter()
        .copied()
        .find(|i| i.label() == parts[1]);
    let seed: u64 = parts[2].parse().unwrap();
    // CASE=plant,effect,seed,rate_hz,noise sets the rate and the torque noise as a test's case
    // does (else the table's for that seed).
    let at = |k: usize| parts.get(k).and_then(|v| v.parse::<f64>().ok());
    for inj in [None, inject] {
        let mut c = cases(plant, inj, seed..seed + 1)[0];
        c.rate_hz = at(3).unwrap_or(c.rate_hz);
        c.noise = at(4).unwrap_or(c.noise);
        let r = identify_case(&c);
        println!(
            "{c:?}\n size {:.5} before {:.5} tared {:.5} after {:.5}",
            generate(&c, 0).size,
            r.before.rmse,
            r.tared.rmse,
            r.after.rmse
        );
        for e in &r.effects {
            println!(
                "  + {} {:?} {:?} gain {:.5} val {:.4}",
                e.effect, e.on, e.params, e.gain_rmse, e.validation_gain
            );
        }
        for e in &r.refused {
            println!("  - {} {:.4} {}", e.effect, e.best_gain, e.why);
        }
        println!("  tare {:?}", r.tare);
        println!(
            "  rate window {:.4} s, angle noise {:.2e} rad",
            r.rate_window, r.angle_noise
        );
        println!(
            "  loop {:.3} {:.3} base {:?}\n  base before {:?}",
            r.residual.loop_before, r.residual.loop_after, r.base_after, r.base_before
        );
    }
}

/// A run of a two-tone deflection x = a₁·sin(w₁·t + φ) + a₂·sin(w₂·t + 2φ) (φ: `phase`), `n`
/// samples `dt` apart, read by an encoder of 0.1 mrad counts; the torque is `torque(x)` plus
/// uniform noise of total width `noise` (its own generator, seeded by `seed` and the phase).
fn two_tone(
    name: &str,
    phase: f64,
    tones: [(f64, f64); 2],
    (n, dt): (usize, f64),
    (seed, noise): (u64, f64),
    d: Option<f64>,
    torque: impl Fn(f64) -> f64,
) -> Run {
    let mut seed = seed ^ phase.to_bits();
    let mut noise = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * noise
    };
    let [(a1, w1), (a2, w2)] = tones;
    let (mut t, mut tau, mut phi) = (vec![], vec![], vec![]);
    for i in 0..n {
        let s = i as f64 * dt;
        let x = a1 * (w1 * s + phase).sin() + a2 * (w2 * s + 2.0 * phase).sin();
        t.push(s);
        phi.push((x / 1e-4).round() * 1e-4);
        tau.push(torque(x) + noise());
    }
    Run {
        name: format!("{name}-{phase}"),
        t,
        tau,
        phi: Some(phi),
        d: d.map(|d| vec![d; n]),
        q: None,
    }
}

/// A linear spring that stiffens past +60 mrad only (a stop on the wound side, none on the
/// other), written here without the library's effect code: 1 % torque noise, an encoder of
/// 0.1 mrad counts.
fn spring_with_one_stop(phase: f64) -> Run {
    let (k, at, rate) = (50.0, 0.06, 400.0);
    two_tone(
        "stop",
        phase,
        [(0.06, 0.9), (0.035, 2.3)],
        (6000, 0.002),
        (0x9E37_79B9_7F4A_7C15, 0.2),
        None,
        |x| k * x + rate * (x - at).max(0.0),
    )
}

#[test]
fn a_stop_on_one_side_only_is_named_with_its_onset_and_nothing_stiffens_the_other_side() {
    let fit = [spring_with_one_stop(0.3)];
    let held = [spring_with_one_stop(1.7)];
    let opts = Options {
        model: Declared::Linear,
        ..Options::default()
    };
    let id = identify_runs(&fit, &held, &opts);
    let names: Vec<&str> = id.effects.iter().map(|f| f.effect.name()).collect();
    assert_eq!(names, ["hard_stop"], "{:?}", id.effects);
    let p = &id.effects[0].params;
    let get = |k: &str| p.iter().find(|(n, _)| *n == k).map(|(_, v)| *v);
    let at = get("onset_rad").unwrap();
    assert!((at - 0.06).abs() < 0.004, "onset {at}");
    let rate = get("stop_rate_nm_per_rad").unwrap();
    assert!((rate - 400.0).abs() < 0.15 * 400.0, "rate {rate}");
    // The other side: no stop, or one whose rate is noise (the bound keeps it ≥ 0).
    let other = get("stop_rate_negative_nm_per_rad").unwrap_or(0.0);
    assert!(other < 0.01 * rate, "{p:?}");
    assert!(
        id.after.rmse < 0.2 * id.before.rmse,
        "{} → {}",
        id.before.rmse,
        id.after.rmse
    );
}

/// The lever at its 9 mm pivot with no friction and no effect (the generator's own lever law):
/// the spring's torque through the lever, a slow two-tone deflection of ±0.13 rad at 200 Hz,
/// uniform torque noise of 0.4 % of the peak (standard deviation), an encoder of 0.1 mrad
/// counts, and the pivot column.
fn bare_lever(phase: f64) -> Run {
    let peak = plants::lever_torque(0.13);
    two_tone(
        "lever",
        phase,
        [(0.09, 0.7), (0.04, 1.9)],
        (4000, 0.005),
        (0xD1B5_4A32_D192_ED03, 0.004 * peak * 12f64.sqrt()),
        Some(plants::LEVER_PIVOT_M),
        plants::lever_torque,
    )
}

#[test]
fn with_the_configs_lever_envelope_the_loops_stiffness_is_the_levers_at_rest_and_without_it_the_lines_bend_as_the_lever_does()
 {
    let fit = [bare_lever(0.4)];
    let held = [bare_lever(2.1)];
    let vsa = LeverVsa::paper_b();
    let k_rest = vsa.stiffness_at_rest(plants::LEVER_PIVOT_M);
    let run = |envelope: Envelope| {
        let opts = Options {
            model: Declared::Restoring,
            lever: Some(vsa),
            envelope,
            ..Options::default()
        };
        identify_runs(&fit, &held, &opts)
    };
    let k_of = |id: &Identified| {
        id.base_after
            .iter()
            .find(|(n, _)| *n == "stiffness_nm_per_rad")
            .map(|(_, v)| *v)
            .unwrap()
    };
    let curved = run(Envelope::Lever(vsa));
    // The loop's k is G(0)²·k_α at the pivot (MODEL.md §1), not a secant of the stroke.
    let k = k_of(&curved);
    assert!((k / k_rest - 1.0).abs() < 0.02, "k {k} against {k_rest}");
    assert!(curved.effects.is_empty(), "{:?}", curved.effects);
    // The lever's geometry is the declared loop's own: not a candidate, and it says why.
    let (_, why) = curved
        .not_applicable
        .iter()
        .find(|(e, _)| e.name() == "geometric_stiffness")
        .unwrap();
    assert!(why.contains("envelope"), "{why}");
    // Paper B's straight lines with the same lever known: the loop misses the lever's curve
    // (a held-out error over twice the curved loop's) and identify names it, the lever's
    // geometry at its own scale; after that the two predict alike.
    let straight = run(Envelope::Linear);
    let names: Vec<&str> = straight.effects.iter().map(|f| f.effect.name()).collect();
    assert_eq!(names, ["geometric_stiffness"], "{:?}", straight.effects);
    let scale = straight.effects[0].params[0].1;
    assert!((scale - 1.0).abs() < 0.02, "{:?}", straight.effects);
    assert!(
        straight.before.rmse > 2.0 * curved.before.rmse,
        "{} against {}",
        straight.before.rmse,
        curved.before.rmse
    );
    assert!(
        curved.after.rmse < 1.05 * straight.after.rmse,
        "{} against {}",
        curved.after.rmse,
        straight.after.rmse
    );
    // The curved loop's residual is not read for a bend: its lines are not straight.
    assert_eq!(curved.residual.bend, None);
    // No lever known (no config): the declared loop's lines bent toward the ends, as much as
    // the lever's own closed form k(φ)/k(0) says at the fit rows' largest deflection (27.0 %
    // against 28.3 % at ±0.130 rad), and then as good held out as the lever's curve (within
    // 0.3 %), with nothing named.
    let no_config = |soften: bool| {
        identify_runs(
            &fit,
            &held,
            &Options {
                model: Declared::Restoring,
                soften,
                ..Options::default()
            },
        )
    };
    let unknown = no_config(true);
    let bent = unknown
        .softening
        .expect("lines bent where straight ones miss the lever");
    let d = plants::LEVER_PIVOT_M;
    let softer = |x: f64| 1.0 - vsa.stiffness_exact(x, d) / vsa.stiffness_at_rest(d);
    assert!(
        (bent.softer / softer(bent.x_max) - 1.0).abs() < 0.1,
        "{bent:?} against the lever's {}",
        softer(bent.x_max)
    );
    assert!(unknown.effects.is_empty(), "{:?}", unknown.effects);
    assert!(
        unknown.after.rmse < 1.03 * curved.after.rmse,
        "{} against {}",
        unknown.after.rmse,
        curved.after.rmse
    );
    assert_eq!(unknown.residual.bend, None);
    // Kept straight (`--straight`): nothing can name the geometry, and the report says the
    // joint softens toward the ends, by about the lever's own closed form at the largest
    // deflection held out.
    let kept = no_config(false);
    assert_eq!(kept.softening, None);
    let b = kept.residual.bend.expect("a bend beside straight lines");
    let want = -softer(b.x_max);
    assert!(want < -0.05, "the lever's own change {want}");
    assert!(
        b.share > 0.5 && (b.change / want - 1.0).abs() < 0.15,
        "{b:?} against {want}"
    );
    let said = &kept.residual.structure;
    assert!(
        said.iter()
            .any(|t| t.contains("bends with the deflection") && t.contains("softer")),
        "{said:?}"
    );
    assert!(
        kept.after.rmse > 1.5 * unknown.after.rmse,
        "straight {} against bent {}",
        kept.after.rmse,
        unknown.after.rmse
    );
}

/// Four sines (amplitude, angular frequency [rad/s], phase) of amplitudes 0.6–1 × `amplitude`
/// and frequencies 0.2 Hz – `top_hz`, drawn in that order from `rng`.
fn random_sines(rng: &mut plants::Rng, amplitude: f64, top_hz: f64) -> Vec<(f64, f64, f64)> {
    (0..4)
        .map(|_| {
            (
                amplitude * rng.range(0.6, 1.0),
                TAU * rng.range(0.2, top_hz),
                rng.range(0.0, TAU),
            )
        })
        .collect()
}

/// The gain and phase of 1/(1 + j·ω·tc), a first-order low-pass at angular frequency `w`.
fn low_pass_at(w: f64, tc: f64) -> (f64, f64) {
    (1.0 / (1.0 + (w * tc).powi(2)).sqrt(), -(w * tc).atan())
}

/// A link (I = 0.03 kg·m², N = 0.02 N·m·s/rad: light damping) swung ±1.4 rad by four sines of
/// up to 2.4 Hz at 1 kHz for 25 s, one of its sensor paths read through a first-order low-pass
/// of time constant `tc` (`angle`: the encoder's; else the torque sensor's), written in closed
/// form: each sine's steady state through 1/(1 + j·ω·tc), the sensor having run long before
/// the recording. The angle counts 4096 per turn; the torque has uniform noise of 1 % of its
/// peak (rms). `draw` changes the sines (fit and held-out runs).
fn filtered_link(draw: u64, angle: bool, tc: f64) -> Run {
    let (inertia, damping): (f64, f64) = (0.03, 0.02);
    let mut rng = plants::Rng::new(0xF11_7E2 + draw);
    let sines = random_sines(&mut rng, 0.35, 2.4);
    let (n, dt) = (25_000, 0.001);
    let mut t = Vec::with_capacity(n);
    let (mut q, mut tau) = (vec![0.0; n], vec![0.0; n]);
    for i in 0..n {
        let s = i as f64 * dt;
        t.push(s);
        for &(a, w, p) in &sines {
            // τ of a sine q = a·sin(w·s + p): a·w·(N·cos − I·w·sin) = a·w·√((I·w)² + N²)·
            // sin(w·s + p + θ).
            let (g, lag) = low_pass_at(w, tc);
            let theta = damping.atan2(-inertia * w);
            let r = a * w * (inertia * w).hypot(damping);
            if angle {
                // The plant moves as the sine; the encoder reads it low-passed.
                q[i] += g * a * (w * s + p + lag).sin();
                tau[i] += r * (w * s + p + theta).sin();
            } else {
                q[i] += a * (w * s + p).sin();
                tau[i] += g * r * (w * s + p + theta + lag).sin();
            }
        }
    }
    let peak = tau.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let count = TAU / 4096.0;
    for i in 0..n {
        q[i] = (q[i] / count).round() * count;
        tau[i] += 0.01 * peak * 3f64.sqrt() * (2.0 * rng.uniform() - 1.0);
    }
    Run {
        name: format!("filtered-{draw}"),
        t,
        tau,
        phi: None,
        d: None,
        q: Some(q),
    }
}

#[test]
fn on_a_lightly_damped_link_a_sensors_first_order_filter_is_named_a_filtered_lag_alone_at_its_time_constant()
 {
    let tc = 0.034;
    for angle in [true, false] {
        let fit = [filtered_link(1, angle, tc)];
        let held = [filtered_link(2, angle, tc)];
        let opts = Options {
            model: Declared::Link,
            ..Options::default()
        };
        let id = identify_runs(&fit, &held, &opts);
        // A filter undone on the angle carries the counts' noise through its jerk T·q⃛: found
        // first at the smoother quiet for q̈ alone (0.16 s), the angle's lag is identified again
        // at the one quiet for the filter (0.32 s), and named a filter there. The torque's
        // filter is not undone: nothing to widen.
        match (angle, id.widened_from) {
            (true, Some((from, lag))) => assert!(
                id.rate_window > from && (lag / tc - 1.0).abs() < 0.03,
                "{} from {from}, for a lag of {lag}",
                id.rate_window
            ),
            (false, None) => {}
            (_, w) => panic!("angle {angle}: widened {w:?}"),
        }
        let names: Vec<&str> = id.effects.iter().map(|f| f.effect.name()).collect();
        // As a pure delay the lag leaves I·tc²·q⁗/2, and a "gravity" of 0.1 % of the torque
        // came beside it (so on the fourth generator's two such seeds: 0.14 and 0.11 of the
        // error before, against the filter's 0.02).
        assert_eq!(names, ["sensor_delay"], "angle {angle}: {:?}", id.effects);
        assert_eq!(param_of(&id, "first_order_filter"), 1.0, "{:?}", id.effects);
        let delay = param_of(&id, "delay_s");
        let want = if angle { -tc } else { tc };
        assert!(
            (delay - want).abs() < 0.03 * tc,
            "angle {angle}: {delay} against {want}"
        );
        let inertia = id.base_after[0].1;
        assert!((inertia / 0.03 - 1.0).abs() < 0.03, "{:?}", id.base_after);
        assert!(
            id.after.rmse < 0.05 * id.before.rmse,
            "angle {angle}: {} → {}",
            id.before.rmse,
            id.after.rmse
        );
    }
}

/// A linear spring (k = 43 N·m/rad) wound ±0.14 rad by four sines of up to 4 Hz at 1 kHz for
/// 24 s, its torque read through a first-order low-pass of time constant `tc` (each sine's
/// steady state through 1/(1 + j·ω·tc)), the deflection as 18-bit counts, the torque with
/// uniform noise of 0.3 % of its peak (rms). Returns the run and the noise's rms [N·m].
fn filtered_spring(draw: u64, tc: f64) -> (Run, f64) {
    let k = 43.0;
    let mut rng = plants::Rng::new(0x5_F11 + draw);
    let sines = random_sines(&mut rng, 0.035, 4.0);
    let (n, dt) = (24_000, 0.001);
    let count = TAU / f64::from(1u32 << 18);
    let mut t = Vec::with_capacity(n);
    let (mut phi, mut tau) = (vec![0.0; n], vec![0.0; n]);
    for i in 0..n {
        let s = i as f64 * dt;
        t.push(s);
        for &(a, w, p) in &sines {
            let (g, lag) = low_pass_at(w, tc);
            phi[i] += a * (w * s + p).sin();
            tau[i] += g * k * a * (w * s + p + lag).sin();
        }
    }
    let peak = tau.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let noise = 0.003 * peak;
    for i in 0..n {
        phi[i] = (phi[i] / count).round() * count;
        tau[i] += noise * 3f64.sqrt() * (2.0 * rng.uniform() - 1.0);
    }
    let run = Run {
        name: format!("filtered-spring-{draw}"),
        t,
        tau,
        phi: Some(phi),
        d: None,
        q: None,
    };
    (run, noise)
}

#[test]
fn on_a_linear_spring_a_torque_sensors_first_order_filter_is_named_a_filter_at_its_time_constant() {
    let tc = 0.025;
    let ((fit, noise), (held, _)) = (filtered_spring(1, tc), filtered_spring(2, tc));
    let opts = Options {
        model: Declared::Linear,
        ..Options::default()
    };
    let id = identify_runs(&[fit], &[held], &opts);
    let names: Vec<&str> = id.effects.iter().map(|f| f.effect.name()).collect();
    assert_eq!(names, ["sensor_delay"], "{:?}", id.effects);
    // As a pure delay the filter leaves k·tc²·φ̈/2 (a delay of 24.8 ms on the third
    // generator's like case: 3.1× its clean twin's error held out; the filter 1.01×).
    assert_eq!(param_of(&id, "first_order_filter"), 1.0, "{:?}", id.effects);
    let delay = param_of(&id, "delay_s");
    assert!((delay / tc - 1.0).abs() < 0.02, "{delay} against {tc}");
    assert!(
        id.after.rmse < 1.1 * noise,
        "held out {} against the noise's {noise}",
        id.after.rmse
    );
}

/// `r` with the samples `keep` refuses dropped (given each sample's index and time from the
/// run's start), every column alike: a recording with dropped samples or a gap.
fn thinned(r: &Run, keep: impl Fn(usize, f64) -> bool) -> Run {
    let kept: Vec<usize> = (0..r.t.len())
        .filter(|&j| keep(j, r.t[j] - r.t[0]))
        .collect();
    let pick = |v: &Vec<f64>| kept.iter().map(|&j| v[j]).collect::<Vec<f64>>();
    Run {
        name: r.name.clone(),
        t: pick(&r.t),
        tau: pick(&r.tau),
        phi: r.phi.as_ref().map(pick),
        d: r.d.as_ref().map(pick),
        q: r.q.as_ref().map(pick),
    }
}

#[test]
fn on_the_link_equation_a_recording_with_a_gap_or_dropped_samples_is_read_as_the_whole_one() {
    // A logger that paused for 0.3 s mid-run, or one that dropped a tenth of its samples, on
    // a link at 250 Hz. The weak form's smoother summed over the samples there were: across
    // the pause as if its two sides were neighbours (1.20 times the whole recording's error
    // held out), and over uneven spacing wherever a sample was dropped. q̈ is a derivative,
    // and its smoothed sum cancels into the angle (by parts) only over evenly spaced slots:
    // with a counted angle, read as the taut string whose q̈ is its bends, 10.5 and 9.2 times
    // the whole recording's error. Now each stretch between gaps is smoothed on its own (its
    // ends left out like a run's), on its whole grid, a dropped slot filled in between its
    // neighbours.
    let whole_and_holed = |c: &Case, keep: &dyn Fn(usize, f64) -> bool| {
        let runs = |k| run_of(["fit", "held"][k], c.plant, &generate(c, k as u64));
        let (fit, held) = ([runs(0)], [runs(1)]);
        let opts = options_of(c);
        let whole = identify_runs(&fit, &held, &opts);
        let (fit, held) = ([thinned(&fit[0], keep)], [thinned(&held[0], keep)]);
        let holed = identify_runs(&fit, &held, &opts);
        (whole, holed)
    };
    let names =
        |id: &Identified| -> Vec<&str> { id.effects.iter().map(|e| e.effect.name()).collect() };
    let at = |inject, seed, counts| Case {
        counts,
        ..case(Plant::Link, Some(inject), seed, 250.0, 0.005)
    };
    // A tenth of the samples, scattered by a hash of their index.
    let a_tenth = |j: usize| {
        (j as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(29)
            .is_multiple_of(10)
    };
    let paused = |_: usize, t: f64| !(10.0..10.3).contains(&t);
    let dropping = |j: usize, _: f64| !a_tenth(j);
    // A pause takes 1 % of the data away and nothing else; a tenth dropped leaves 5 % more
    // noise in what the smoother averages, and less to fit on.
    for (c, keep, how, bound) in [
        (
            at(Inject::Gravity, 0, 16384.0),
            &paused as &dyn Fn(usize, f64) -> bool,
            "paused 0.3 s",
            1.1,
        ),
        (
            at(Inject::Gravity, 0, 4096.0),
            &dropping,
            "a tenth dropped",
            1.25,
        ),
        (
            at(Inject::Coulomb, 0, 4096.0),
            &dropping,
            "a tenth dropped",
            1.25,
        ),
    ] {
        let (whole, holed) = whole_and_holed(&c, keep);
        let name = c.inject.map_or("", Inject::expected);
        assert_eq!(names(&whole), [name], "{c:?}: the whole recording");
        assert_eq!(names(&holed), names(&whole), "{c:?}: {how}");
        let (a, b) = (holed.after.rmse, whole.after.rmse);
        assert!(
            a < bound * b,
            "{c:?}: {how}, held-out error {a} against the whole recording's {b}"
        );
    }
}
