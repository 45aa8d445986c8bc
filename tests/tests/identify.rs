//! `rig identify` on simulated data with an effect the declared model lacks (the simulator's
//! injectable effects, which no config declares): for each, the identify step names it and
//! at least halves the held-out RMSE; on clean data it adds nothing. End to end: `rig sim`
//! writes the CSV, `rig identify` reads it and writes the report. (Data that shares no code
//! with the simulator or the library: `agents/model/tests/identify_independent.rs`.)

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::bin;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

fn workspace(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

fn scratch(name: &str) -> PathBuf {
    common::test_dir("identify").join(name)
}

/// A lever-bench run (paper B's bench at a 9 mm pivot, 30 s at 1 kHz, 14-bit encoder, 1 mN·m
/// torque noise; peak torque about 0.16 N·m at 0.06 rad).
fn lever_bench(name: &str, hysteresis: bool, amplitude: f64, effects: &str) -> PathBuf {
    lever_bench_noise(name, hysteresis, amplitude, 0.001, effects)
}

fn lever_bench_noise(
    name: &str,
    hysteresis: bool,
    amplitude: f64,
    noise_nm: f64,
    effects: &str,
) -> PathBuf {
    scenario(
        name,
        &format!(
            "kind = \"lever-bench\"\nduration_s = 30.0\nseed = 3\n[lever_bench]\npivot_mm = 9.0\namplitude_rad = {amplitude}\nhysteresis = {hysteresis}\n[sensors]\nencoder_bits = 14\ntorque_noise_nm = {noise_nm}\n[effects]\n{effects}\n"
        ),
    )
}

/// Paper A's AWAS driven by sinusoidal motor torques (30 s at 1 kHz).
fn awas(name: &str, effects: &str) -> PathBuf {
    scenario(
        name,
        &format!(
            "kind = \"awas\"\nduration_s = 30.0\nseed = 1\n[awas]\ntau1 = [[6.0, 0.7], [3.0, 2.3], [1.5, 9.0]]\ntau2 = [[0.004, 0.05]]\n[sensors]\nencoder_bits = 14\ntorque_noise_nm = 0.05\n[effects]\n{effects}\n"
        ),
    )
}

fn scenario(name: &str, toml: &str) -> PathBuf {
    let (sc, csv) = (
        scratch(&format!("{name}.toml")),
        scratch(&format!("{name}.csv")),
    );
    std::fs::write(&sc, toml).unwrap();
    let o = Command::new(bin("rig"))
        .args(["sim", "--scenario"])
        .arg(&sc)
        .arg("--out")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    csv
}

fn identify(csv: &Path, extra: &[&str]) -> Value {
    let mut c = Command::new(bin("rig"));
    c.arg("identify").args(extra).arg("--data").arg(csv);
    report_of(c, &csv.with_extension("json"))
}

/// Runs a `rig identify` command with `--report report`; the report, once it succeeded.
fn report_of(mut c: Command, report: &Path) -> Value {
    let o = c.arg("--report").arg(report).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&std::fs::read(report).unwrap()).unwrap()
}

fn names(v: &Value) -> Vec<String> {
    v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_string())
        .collect()
}

fn rmse(v: &Value, when: &str) -> f64 {
    v[when]["rmse"].as_f64().unwrap()
}

fn param(v: &Value, effect: &str, p: &str) -> f64 {
    v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["name"] == effect)
        .and_then(|e| e["params"][p].as_f64())
        .unwrap_or_else(|| panic!("{effect}.{p} not in {v}"))
}

/// The held-out RMSE after is at most `share` of the declared model's before.
fn held_out_at_most(v: &Value, share: f64) {
    assert!(
        rmse(v, "after") <= share * rmse(v, "before"),
        "held-out RMSE {} → {}: over {share} of it",
        rmse(v, "before"),
        rmse(v, "after")
    );
}

/// The effect is named first and the held-out RMSE at least halves.
fn finds(v: &Value, effect: &str) {
    let n = names(v);
    assert_eq!(
        n.first().map(String::as_str),
        Some(effect),
        "effects {n:?}: {v:#}"
    );
    held_out_at_most(v, 0.5);
    let gain = v["effects"][0]["gain_rmse"].as_f64().unwrap();
    assert!(
        gain > 0.0,
        "the effect must pay off on held-out data: {gain}"
    );
}

/// Nothing added: the error after is the declared model's on the data the effects saw (tared,
/// and the deflection's counts averaged out where they reach the torque: the simulator's
/// 14-bit AS5048A over ±0.06 rad), which is no worse than on the data as given.
fn adds_nothing(v: &Value) {
    assert!(
        names(v).is_empty(),
        "clean data, yet effects {:?}",
        names(v)
    );
    assert_eq!(rmse(v, "tared"), rmse(v, "after"));
    held_out_at_most(v, 1.01);
}

// Declared: paper B's restoring-torque model; plant: the lever with Bouc-Wen hysteresis.

#[test]
fn a_lever_swung_far_without_its_geometry_gets_lines_that_soften_as_the_lever_does() {
    // ±0.15 rad at the 9 mm pivot, no effect: paper B's straight lines cannot follow the
    // lever's curve. Without a config the lines bent toward the ends are kept, about as much
    // softer at the fit's largest deflection as the lever's closed form k(φ)/k(0) says, and
    // the report says so; `--straight` keeps paper B's lines and only notes the bend.
    let csv = lever_bench("r-far", true, 0.15, "");
    let v = identify(&csv, &[]);
    assert_eq!(v["envelope"], "softening", "{v:#}");
    let s = &v["softening"];
    let x = s["x_max_rad"].as_f64().unwrap();
    let softer = s["softer_at_x_max"].as_f64().unwrap();
    let vsa = rig_model::lever::LeverVsa::paper_b();
    let want = 1.0 - vsa.stiffness_exact(x, 0.009) / vsa.stiffness_at_rest(0.009);
    assert!(
        (softer / want - 1.0).abs() < 0.25,
        "{softer} softer at ±{x} rad against the lever's {want}"
    );
    let md = std::fs::read_to_string(csv.with_extension("md")).unwrap();
    assert!(md.contains("declared loop's lines bent"), "{md}");
    let straight = identify(&csv, &["--straight"]);
    assert_eq!(straight["envelope"], "linear");
    assert!(straight["softening"].is_null());
    assert!(
        rmse(&straight, "after") > 1.3 * rmse(&v, "after"),
        "straight {} against bent {}",
        rmse(&straight, "after"),
        rmse(&v, "after")
    );
}

#[test]
fn restoring_model_on_clean_data_adds_nothing() {
    let v = identify(&lever_bench("r-clean", true, 0.06, ""), &[]);
    adds_nothing(&v);
    assert_eq!(v["model"], "restoring");
    // The report's other required parts.
    assert!(v["samples"].as_u64().unwrap() == 30_000);
    assert!(v["holdout"]["fraction"].as_f64().unwrap() > 0.2);
    assert!(v["residual"]["white"].is_boolean());
    assert!(v["residual"]["max_autocorr"].as_f64().unwrap() < 1.0);
}

#[test]
fn restoring_model_finds_viscous_friction() {
    let v = identify(
        &lever_bench("r-visc", true, 0.06, "viscous_friction_nms_per_rad = 0.1"),
        &[],
    );
    finds(&v, "viscous_friction");
    let b = param(&v, "viscous_friction", "damping_nms_per_rad");
    assert!((b - 0.1).abs() < 0.02, "{b}");
}

#[test]
fn restoring_model_finds_sensor_delay() {
    let v = identify(
        &lever_bench("r-delay", true, 0.06, "sensor_delay_s = 0.02"),
        &[],
    );
    finds(&v, "sensor_delay");
    let d = param(&v, "sensor_delay", "delay_s");
    // The restoring model's loop and a lag trade off (both open the loop); refitting the
    // model against the delayed input brings the estimate near the truth.
    assert!((d - 0.02).abs() < 0.0025, "{d}");
}

#[test]
fn restoring_model_finds_a_torque_offset() {
    let v = identify(
        &lever_bench("r-bias", true, 0.06, "torque_offset_nm = 0.02"),
        &[],
    );
    finds(&v, "offset");
    assert_eq!(v["effects"][0]["params"]["on"], "torque", "{v:#}");
    let b = param(&v, "offset", "bias_nm");
    assert!((b - 0.02).abs() < 0.002, "{b}");
}

#[test]
fn restoring_model_finds_an_encoder_slip() {
    let v = identify(
        &lever_bench(
            "r-jump",
            true,
            0.06,
            "offset_jump_at_s = 13.0\noffset_jump_rad = 0.01",
        ),
        &[],
    );
    finds(&v, "offset");
    let at = param(&v, "offset", "jump_at_s");
    assert!((at - 13.0).abs() < 0.3, "{at}");
    // The encoder slipped by 0.01 rad. At 0.06 rad paper B's lever is nearly linear, so the
    // slip and a torque step of −k·0.01 fit alike (docs/IDENTIFY.md): either place is right,
    // with the size it implies.
    let k = v["base"]["after"]["stiffness_nm_per_rad"].as_f64().unwrap();
    match v["effects"][0]["params"]["on"].as_str() {
        Some("deflection") => {
            let jump = param(&v, "offset", "jump_rad");
            assert!((jump - 0.01).abs() < 0.001, "{jump}");
        }
        Some("torque") => {
            let jump = param(&v, "offset", "jump_nm");
            assert!(
                (jump + k * 0.01).abs() < 0.15 * k * 0.01,
                "{jump} vs k = {k}"
            );
            // Named in the slip's place, the report gives the slip that fits as well.
            if let Some(slip) = v["effects"][0]["params"]["or_encoder_jump_rad"].as_f64() {
                assert!((slip - 0.01).abs() < 0.001, "{slip}");
            }
        }
        other => panic!("offset on {other:?}: {v:#}"),
    }
}

#[test]
fn restoring_model_finds_stiffness_drift() {
    let v = identify(
        &lever_bench("r-drift", true, 0.06, "stiffness_drift_per_s = 0.01"),
        &[],
    );
    finds(&v, "stiffness_drift");
    // The spring's stiffness scales by (1 + 0.01·t): the declared model's torque times that.
    let c = param(&v, "stiffness_drift", "stiffness_rate_per_s");
    assert!((c - 0.01).abs() < 0.001, "{c}");
}

#[test]
fn restoring_model_finds_periodic_ripple() {
    let v = identify(
        &lever_bench(
            "r-ripple",
            true,
            0.06,
            "ripple_nm = 0.02\nripple_period_rad = 0.01",
        ),
        &[],
    );
    finds(&v, "periodic_ripple");
    let p = param(&v, "periodic_ripple", "period_rad");
    assert!((p - 0.01).abs() < 2e-4, "{p}");
    let a = param(&v, "periodic_ripple", "amplitude_nm");
    assert!((a - 0.02).abs() < 0.002, "{a}");
}

#[test]
fn restoring_model_finds_a_hard_stop() {
    let v = identify(
        &lever_bench(
            "r-stop",
            true,
            0.06,
            "stop_at_rad = 0.04\nstop_rate_nm_per_rad = 20.0",
        ),
        &[],
    );
    finds(&v, "hard_stop");
    let at = param(&v, "hard_stop", "onset_rad");
    assert!((at - 0.04).abs() < 0.003, "{at}");
}

// Declared: the linear spring; plant: the exact lever spring without hysteresis.

#[test]
fn linear_model_on_a_clean_small_deflection_spring_adds_nothing() {
    // At 0.03 rad the lever is linear within the noise (at 0.06 rad its geometric stiffness
    // already shows, and is found: see below).
    let cfg = workspace("rig-config/examples/parallel.toml");
    let v = identify(
        &lever_bench("l-clean", false, 0.03, ""),
        &["--model", "linear", "--config", cfg.to_str().unwrap()],
    );
    adds_nothing(&v);
}

#[test]
fn linear_model_finds_coulomb_friction() {
    let v = identify(
        &lever_bench("l-coulomb", false, 0.06, "coulomb_friction_nm = 0.02"),
        &["--model", "linear"],
    );
    finds(&v, "coulomb_friction");
    let f = param(&v, "coulomb_friction", "friction_nm");
    assert!((f - 0.02).abs() < 0.002, "{f}");
}

/// A file of `t,phi,tau` at 500 Hz for 20 s: at rest for 1 s, then deflection `phi(t)`, the
/// torque a 2 N·m/rad spring with viscous friction of 0.02 N·m·s/rad and ±0.5 mN·m of noise.
fn spring_file(name: &str, phi: impl Fn(f64) -> f64) -> PathBuf {
    let mut noise = rig_sim::noise::Noise::new(12345);
    let mut csv = String::from("t,phi,tau\n");
    for k in 0..10_000 {
        let t = k as f64 / 500.0;
        let (x, rate) = (phi(t), (phi(t + 1e-4) - phi(t - 1e-4)) / 2e-4);
        csv.push_str(&format!(
            "{t},{x},{}\n",
            2.0 * x + 0.02 * rate + (noise.uniform() - 0.5) * 1e-3
        ));
    }
    let path = scratch(&format!("{name}.csv"));
    std::fs::write(&path, csv).unwrap();
    path
}

#[test]
fn a_fit_at_one_speed_is_said_to_be_one_where_rate_and_friction_cannot_be_told_apart() {
    use std::f64::consts::PI;
    // A 0.3 Hz triangle of ±0.05 rad moves at 4·0.05·0.3 = 0.06 rad/s on every stroke.
    let moving = |t: f64| (t - 1.0).max(0.0);
    let tri = spring_file("speed-tri", |t| {
        0.05 * (2.0 / PI) * (2.0 * PI * 0.3 * moving(t)).sin().asin()
    });
    let v = identify(&tri, &["--model", "linear"]);
    let speed = note_that(&v, |n| n.starts_with("speed:"));
    assert!(speed.contains("0.06"), "{speed}");
    // A sine of the same swing moves at every speed up to its peak: nothing to say.
    let sine = spring_file("speed-sine", |t| 0.05 * (2.0 * PI * 0.3 * moving(t)).sin());
    let v = identify(&sine, &["--model", "linear"]);
    let notes = v["notes"].as_array().unwrap();
    assert!(
        notes
            .iter()
            .all(|n| !n.as_str().unwrap().starts_with("speed:")),
        "{notes:?}"
    );
}

#[test]
fn linear_model_finds_backlash() {
    let v = identify(
        &lever_bench("l-backlash", false, 0.06, "backlash_rad = 0.006"),
        &["--model", "linear"],
    );
    finds(&v, "backlash");
    let w = param(&v, "backlash", "width_rad");
    assert!((w - 0.006).abs() < 5e-4, "{w}");
}

#[test]
fn linear_model_finds_hysteresis() {
    // Paper B's loop is 5 % of the torque: a quieter sensor (0.2 mN·m) lets it stand out.
    let v = identify(
        &lever_bench_noise("l-hyst", true, 0.06, 0.0002, ""),
        &["--model", "linear"],
    );
    finds(&v, "hysteresis");
}

/// One case of the third generator (`scripts/third-generator.py`: a linear spring written from
/// issue 11's words, sharing no code with the library or the simulator), its jump at the same
/// instant in both runs; `rig identify --model linear` fitted on its first run and scored on
/// its second. The report, and the generator's truth (a Python dict literal, read as text).
fn third_generator(effect: &str, seed: u32) -> (Value, String) {
    generated(
        "third-generator.py",
        "linear",
        effect,
        seed,
        &[("SAMEJUMP", "1")],
    )
}

/// One case of the fifth generator (`scripts/lever-generator.py`: paper B's lever with
/// Bouc-Wen friction in its spring, written from MODEL.md alone), `rig identify --model
/// restoring` without a config. The report and the truth, as [`third_generator`]'s.
fn lever_generator(effect: &str, seed: u32) -> (Value, String) {
    generated("lever-generator.py", "restoring", effect, seed, &[])
}

/// One case of the fourth generator (`scripts/link-generator.py`: paper A's link equation
/// with one effect, written from the issue's words and MODEL.md), `rig identify --model link`,
/// and its clean twin's report (the same link, motions and noise without the effect:
/// `TWIN=1`), beside the report and the truth.
fn link_generator_with_twin(effect: &str, seed: u32) -> (Value, String, Value) {
    generated_with_twin("link-generator.py", "link", effect, seed)
}

/// A generator script's case with its clean twin (`TWIN=1`): the case's report, its truth and
/// the twin's report, each identified under `model`.
fn generated_with_twin(
    script: &str,
    model: &str,
    effect: &str,
    seed: u32,
) -> (Value, String, Value) {
    let (v, truth) = generated(script, model, effect, seed, &[("TWIN", "1")]);
    let twin = scratch(&format!(
        "{}-{effect}-{seed}",
        script.trim_end_matches(".py")
    ))
    .join("twin");
    (v, truth, identified_case(model, &twin))
}

/// A generated case's lag named alone (its clean twin nothing), its δ within `within` of the
/// plant's `d`, and a filter (`filter` 1) or a pure delay (0) as the plant's is.
fn a_lag_alone_at_the_plants(v: &Value, truth: &str, twin: &Value, within: f64, filter: f64) {
    assert_eq!(names(v), ["sensor_delay"], "{v:#}");
    adds_nothing(twin);
    let (delay, d) = (param(v, "sensor_delay", "delay_s"), truth_value(truth, "d"));
    assert!(
        (delay / d - 1.0).abs() < within,
        "delay {delay} s against {d} s"
    );
    assert_eq!(param(v, "sensor_delay", "first_order_filter"), filter);
}

/// The case's held-out error after is under `factor` times its clean twin's (1 is as low as
/// the data allow).
fn held_out_within(v: &Value, twin: &Value, factor: f64) {
    let floor = rmse(twin, "after");
    assert!(
        rmse(v, "after") < factor * floor,
        "held out {} against the twin's {floor}",
        rmse(v, "after")
    );
}

/// `rig identify --model <model>` on a generated case's `fit.csv` with `ho.csv` held out: the
/// report.
fn identified_case(model: &str, dir: &Path) -> Value {
    let mut c = Command::new(bin("rig"));
    c.args(["identify", "--model", model, "--data"])
        .arg(dir.join("fit.csv"))
        .arg("--holdout")
        .arg(dir.join("ho.csv"));
    report_of(c, &dir.join("r.json"))
}

/// A generator script's case (`scripts/<script> OUTDIR EFFECT SEED`, with `env`), identified
/// under `model` on its `fit.csv` with `ho.csv` held out.
fn generated(
    script: &str,
    model: &str,
    effect: &str,
    seed: u32,
    env: &[(&str, &str)],
) -> (Value, String) {
    let dir = scratch(&format!(
        "{}-{effect}-{seed}",
        script.trim_end_matches(".py")
    ));
    let out = common::tool("python3")
        .arg(workspace(&format!("scripts/{script}")))
        .arg(&dir)
        .arg(effect)
        .arg(seed.to_string())
        .envs(env.iter().copied())
        .output()
        .expect("python3 runs the generator (.ci/run installs it)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = identified_case(model, &dir);
    (v, std::fs::read_to_string(dir.join("truth.txt")).unwrap())
}

/// The report's first note that `has` accepts (all of them in the panic where none does).
fn note_that(v: &Value, has: impl Fn(&str) -> bool) -> &str {
    v["notes"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|n| n.as_str())
        .find(|n| has(n))
        .unwrap_or_else(|| panic!("{:#}", v["notes"]))
}

/// The report has no note that `has`.
fn no_note_that(v: &Value, has: impl Fn(&str) -> bool) {
    let notes = v["notes"].as_array().unwrap();
    assert!(
        !notes.iter().filter_map(|n| n.as_str()).any(has),
        "{:#}",
        v["notes"]
    );
}

/// The report refused `effect` for a reason of its own that says `because`.
fn refused_because(v: &Value, effect: &str, because: &str) {
    let r = v["refused"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["name"] == effect)
        .unwrap_or_else(|| panic!("{effect} among the refused: {v:#}"));
    assert!(
        r["why"].as_str().is_some_and(|w| w.contains(because)),
        "{r:#}"
    );
}

/// The report does not list `effect` among the refused (named, it was judged again and kept).
fn never_refused(v: &Value, effect: &str) {
    let refused = v["refused"].as_array().unwrap();
    assert!(
        !refused.iter().any(|r| r["name"] == effect),
        "{effect} among the refused: {refused:#?}"
    );
}

/// A number of the generator's truth (a Python dict as `str` prints it): the first `'key': value`.
fn truth_value(truth: &str, key: &str) -> f64 {
    let at = truth
        .find(&format!("'{key}': "))
        .unwrap_or_else(|| panic!("{key} in {truth}"));
    let rest = &truth[at + key.len() + 4..];
    let end = rest.find([',', '}']).unwrap();
    rest[..end].trim().parse().unwrap()
}

#[test]
fn a_companion_that_another_motion_barely_shows_is_refused_and_the_effect_named_alone() {
    // Two cases of the third generator where the fit run validates a second effect beside
    // the right one and the held-out run, another motion of the same spring, gains under 5 %
    // from it: a stiffness step of −1.3 % beside a stop whose onset is placed a count out
    // (100 Hz ramps and holds), and dry friction beside a small loop (a 4096-count encoder).
    // Each is named alone, the companion refused for it in the report, and the error held out
    // at least halves.
    for (effect, seed, name, companion) in [
        ("stop", 2, "hard_stop", "stiffness_drift"),
        ("hysteresis", 7, "hysteresis", "coulomb_friction"),
    ] {
        let (v, truth) = third_generator(effect, seed);
        finds(&v, name);
        assert_eq!(names(&v), [name], "{effect} seed {seed}: {v:#}");
        let refused = v["refused"].as_array().unwrap();
        assert!(
            refused.iter().any(
                |r| r["name"] == companion && r["why"].as_str().unwrap().contains("--min-gain")
            ),
            "{effect} seed {seed}: {companion} not refused as immaterial: {refused:#?}"
        );
        if effect == "stop" {
            // The onset within two counts of the 16384-count encoder (0.77 mrad).
            let at = truth_value(&truth, "at");
            let onset = param(&v, "hard_stop", "onset_rad");
            assert!((onset - at).abs() < 8e-4, "onset {onset} against {at}");
        }
    }
}

#[test]
fn a_tare_that_lets_the_loops_fit_find_another_basin_does_not_make_after_worse_than_before() {
    // The fifth generator's clean seed 4: a lever with Bouc-Wen friction fitted on a triangle
    // wave (one speed, one amplitude), a multi-sine held out. The tare (0.2 mN·m, under a
    // tenth of the noise) let the loop's refit leave the basin the data as given were fitted
    // in, for a loop that fits the fit rows a third better and the held-out run nearly twice as
    // badly; reported against the first basin, nothing added came out 1.47 times worse than
    // before. `before` is now the best loop found from the same starts on the data as given.
    let (v, _) = lever_generator("none", 4);
    adds_nothing(&v);
}

#[test]
fn a_lever_whose_torque_at_rest_is_its_ripples_value_there_is_not_tared_and_the_ripple_is_named() {
    // The fifth generator's ripple, seed 6: a lever with Bouc-Wen friction and a ripple of 9.8
    // mN·m every 39.8 mrad of deflection, whose value at rest is −8.2 mN·m; 250 Hz ramps and
    // holds fitted, a multi-sine held out, 0.3 % noise. The tare took −8.2 mN·m as the sensor's
    // zero in both files, and the loop widened to hold the constant that left on the ramps:
    // nothing was named, and the held-out error rose from 8.3 to 12.2 mN·m, 11 times the clean
    // twin's. The fit rows and the held-out run both fit the data as given better, so they are
    // used as given, and the ripple is named.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "ripple", 6);
    assert_eq!(names(&v), ["periodic_ripple"], "{v:#}");
    adds_nothing(&twin);
    let tare = v["tare"].as_str().unwrap_or_default();
    assert!(tare.starts_with("not tared"), "{v:#}");
    let (period, want) = (
        param(&v, "periodic_ripple", "period_rad"),
        truth_value(&truth, "P"),
    );
    assert!(
        (period / want - 1.0).abs() < 0.05,
        "period {period} against {want}"
    );
    held_out_at_most(&v, 0.6);
    held_out_within(&v, &twin, 5.0);
}

#[test]
fn on_the_lever_an_encoder_slip_whose_linearised_size_overshoots_is_sized_by_search() {
    // The fifth generator's slip, seed 6: a lever with Bouc-Wen friction whose deflection
    // encoder slips 1.89 mrad at 12.77 s (100 Hz triangle waves fitted and held out, 1 %
    // noise). Linearised against the loop fitted without it, the slip came out 3.7 mrad;
    // linearised again against the loop refitted for that, 2·10⁵ rad: the loop could not be
    // fitted, the true instant was dropped, and nothing was named (held out 1.09× the clean
    // twin's). The size is now searched between 0 and twice the first linearised one.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "slip", 6);
    assert_eq!(names(&v), ["offset"], "{v:#}");
    assert!(names(&twin).is_empty(), "{twin:#}");
    let ((jump, s), (at, t_j)) = slip_against_truth(&v, &truth);
    assert!((jump / s - 1.0).abs() < 0.05, "slip {jump} against {s}");
    assert!((at - t_j).abs() < 0.05, "slip at {at} s against {t_j} s");
    held_out_within(&v, &twin, 1.04);
}

/// The slip the report names on the torque, beside the torque step (`or_encoder_jump_rad`), and
/// its instant [s], against the generator's truth: (named, plant's) each.
fn slip_against_truth(v: &Value, truth: &str) -> ((f64, f64), (f64, f64)) {
    (
        (
            param(v, "offset", "or_encoder_jump_rad"),
            truth_value(truth, "s"),
        ),
        (
            param(v, "offset", "jump_at_s"),
            truth_value(truth, "jump_fit_s"),
        ),
    )
}

#[test]
fn on_the_lever_a_slip_the_second_starts_loop_took_in_is_found_beside_the_first_loop() {
    // The fifth generator's slip, seed 9 (never tuned on): a 1.93 mrad slip at 11.33 s, 500 Hz
    // multi-sines fitted and held out, 0.3 % noise. Tared, the loop fitted afresh (12.1 N·m/rad,
    // 0.15 N·m high) was refitted from the loop of the data as given and landed on one that had
    // taken the slip in (5.3 N·m/rad, 0.35 N·m high: the fit rows 2.4 times better, held out
    // worse), beside which no slip paid: nothing named, 18.6 times the twin's error held out.
    // The slip is now searched beside the first loop too, and chosen on the validation rows.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "slip", 9);
    assert_eq!(names(&v), ["offset"], "{v:#}");
    adds_nothing(&twin);
    let ((jump, s), (at, t_j)) = slip_against_truth(&v, &truth);
    assert!((jump / s - 1.0).abs() < 0.02, "slip {jump} against {s}");
    assert!((at - t_j).abs() < 0.01, "slip at {at} s against {t_j} s");
    assert!(v["effects"][0]["params"]["named_on_held_out_likelihood_ratio"].is_null());
    held_out_within(&v, &twin, 1.1);
}

#[test]
fn on_the_lever_a_slip_a_loop_holds_as_well_on_validation_is_named_where_the_held_out_run_confirms_it()
 {
    // The fifth generator's slip, seed 7: a 7.6 mrad slip at 23.86 s, 100 Hz chirps fitted and
    // held out, 0.3 % noise. Tared, the second start's loop fitted the fit rows 6 times better
    // than the first and the validation blocks as well as the first loop with the slip (0.974
    // against 0.980 mN·m): nothing named, 3.1 times the twin's error held out. The slip found
    // beside the first loop fits the fit rows better by the criterion and the held-out run
    // confirms it (1.7 against 2.0 mN·m): named, and the report says the held-out data chose.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "slip", 7);
    assert_eq!(names(&v), ["offset"], "{v:#}");
    adds_nothing(&twin);
    assert!(param(&v, "offset", "named_on_held_out_likelihood_ratio") > 6.63);
    let ((jump, s), (at, t_j)) = slip_against_truth(&v, &truth);
    // Sized from a loop the slip settles from, not the plant's: 20 % short.
    assert!((jump / s - 1.0).abs() < 0.25, "slip {jump} against {s}");
    assert!((at - t_j).abs() < 0.05, "slip at {at} s against {t_j} s");
    assert!(rmse(&v, "after") < 0.9 * rmse(&v, "before"), "{v:#}");
    note_that(&v, |n| {
        n.starts_with("slip: ") && n.contains("named on the held-out data's evidence")
    });
}

#[test]
fn on_a_clean_lever_friction_that_only_gave_the_loop_a_better_start_is_not_named() {
    // The fifth generator's slip, seed 300 (never tuned on), and its clean twin: a lever with
    // Bouc-Wen friction (n = 2), 200 Hz chirps fitted, a triangle wave held out, 1 % noise.
    // From its grid the loop stopped at 3.33 mN·m on the twin's fit rows; dry friction, with
    // the loop refitted for it, gained 49 % on validation and was named on the clean twin, and
    // beside the slip on the case. That loop alone, without the friction, fitted the fit rows
    // better still (1.69 mN·m). The loop's fit now starts from friction's loops as well.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "slip", 300);
    adds_nothing(&twin);
    // `before` is the best loop from the same starts: 1.80 mN·m held out (1.26 times the
    // torque sensor's noise), was 3.26 (2.3 times).
    let noise = truth_value(&truth, "noise");
    assert!(rmse(&twin, "before") < 1.5 * noise, "{twin:#}");
    assert_eq!(names(&v), ["offset"], "{v:#}");
    let ((jump, s), (at, t_j)) = slip_against_truth(&v, &truth);
    assert!((jump / s - 1.0).abs() < 0.05, "slip {jump} against {s}");
    assert!((at - t_j).abs() < 0.01, "slip at {at} s against {t_j} s");
    held_out_within(&v, &twin, 1.05);
}

/// The deflection φ > 0 at which the fifth generator's spring has turned `alpha` [rad] through
/// its lever (scripts/lever-generator.py: arm 31.5 mm, pivot 9.6 mm + `d` [m]), by bisection.
fn deflection_at_spring_angle(alpha: f64, d: f64) -> f64 {
    let spring = |phi: f64| {
        let (p, d_a) = (0.0315, 0.0096 + d);
        (p * phi.sin()).atan2(p * phi.cos() - d_a) - phi
    };
    let (mut lo, mut hi) = (0.0, 0.2);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if spring(mid).abs() < alpha {
            lo = mid
        } else {
            hi = mid
        }
    }
    lo
}

/// A fifth-generator gap case's `backlash` half-width as found, and the plant's: the
/// deflection at which the spring's angle, through the lever, reaches the gap's r.
fn gap_half_width(v: &Value, truth: &str) -> (f64, f64) {
    let (r, d) = (truth_value(truth, "r"), truth_value(truth, "d_mm") * 1e-3);
    (
        param(v, "backlash", "half_width_rad"),
        deflection_at_spring_angle(r, d),
    )
}

#[test]
fn on_the_lever_a_stop_its_loop_stiffened_to_hold_is_named_once_given_a_loop_of_its_own() {
    // The fifth generator's stop, seed 40: a lever with Bouc-Wen friction whose spring meets a
    // stop 6.8 times as stiff as itself on the top holds of 1 kHz ramps (2 % noise, a triangle
    // wave held out). Against the loop fitted without it, the stop left a slow residual (6–13
    // effective samples) and the criterion refused it: nothing named, 10.6 times the clean
    // twin's error held out. A pair of stops that validated a little better than the one the
    // same on both sides also took the symmetric one's place, with a wrong second onset.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "stop", 40);
    assert_eq!(names(&v), ["hard_stop"], "{v:#}");
    adds_nothing(&twin);
    // The deflection at which the spring's angle reaches the stop, through the generator's
    // lever (scripts/lever-generator.py: arm 31.5 mm, pivot 9.6 mm + d).
    let (at, d) = (
        truth_value(&truth, "at"),
        truth_value(&truth, "d_mm") * 1e-3,
    );
    let lo = deflection_at_spring_angle(at, d);
    let (onset, negative) = (
        param(&v, "hard_stop", "onset_rad"),
        param(&v, "hard_stop", "onset_negative_rad"),
    );
    assert!(
        (onset / lo - 1.0).abs() < 0.01,
        "onset {onset} against {lo}"
    );
    assert_eq!(negative, -onset, "one stop the same on both sides");
    held_out_within(&v, &twin, 1.1);
}

#[test]
fn on_the_lever_a_stop_left_carrying_nothing_beside_a_gap_is_not_named() {
    // The fifth generator's backlash, seed 5: a lever with Bouc-Wen friction whose spring has a
    // gap of ±12.4 mrad in its own angle (500 Hz triangle waves fitted and held out, 0.3 %
    // noise). A symmetric stop was chosen first, against its own refitted loop; once the gap
    // and viscous friction were in beside it, its rates fitted to 0 on both sides and it was
    // still named, with viscous friction, ahead of the gap. A stop none of whose sides
    // stiffens is no stop: only the gap is named.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "backlash", 5);
    assert_eq!(names(&v), ["backlash"], "{v:#}");
    // (Its clean twin is named viscous friction: on a triangle wave's one speed a torque in
    // proportion to the rate is a constant height on each stroke, and the report says the fit
    // cannot tell it from dry friction or the loop. Its held-out error is still the floor the
    // gap is judged against.)
    refused_because(&v, "hard_stop", "no side of it stiffens");
    // Found 8 % narrower (the friction element's yield blurs the gap's edges).
    let (half, lo) = gap_half_width(&v, &truth);
    assert!(
        (half / lo - 1.0).abs() < 0.12,
        "half-width {half} against {lo}"
    );
    held_out_within(&v, &twin, 1.0);
}

#[test]
fn on_the_lever_a_gap_that_validates_and_fits_better_than_a_stop_for_less_is_named_over_it() {
    // The fifth generator's backlash, seed 300 (never tuned on): a lever with Bouc-Wen
    // friction at a 14.6 mm pivot whose spring has a gap of ±14.8 mrad in its own angle (1 kHz
    // ramps and holds fitted, a multi-sine held out, 0.3 % noise). The gap validated at
    // 3.5 mN·m and a symmetric stop at 5.5, too few effective samples apart to call either
    // clearly better; the criterion broke the tie for the stop (150 against 99) on its own
    // residual's effective samples (69 against 36), though the gap left the fit rows half the
    // stop's RSS with a parameter fewer. The stop was named, a stiffness step beside it, 2.3
    // times the clean twin's error held out.
    let (v, truth, twin) = generated_with_twin("lever-generator.py", "restoring", "backlash", 300);
    assert_eq!(names(&v), ["backlash"], "{v:#}");
    adds_nothing(&twin);
    // Found 21 % narrower: the generator's friction element (a sixth of the torque here) is
    // not in series with the gap and still loads inside it, where the declared loop's input
    // has none.
    let (half, at) = gap_half_width(&v, &truth);
    assert!(
        (half / at - 1.0).abs() < 0.25,
        "half-width {half} against {at}"
    );
    // 1.62 times the twin's (the same friction inside the gap); the stop and step left 2.35.
    held_out_within(&v, &twin, 1.8);
}

#[test]
fn on_the_lever_a_spring_that_softens_in_a_hold_is_named_a_stiffness_step_at_its_instant_in_each_run()
 {
    // The fifth generator's stiffness step, seed 0: a lever with Bouc-Wen friction whose spring
    // softens 11 % in a hold part-way (250 Hz ramps and holds fitted, a chirp held out, 0.3 %
    // noise). The loop fitted without the step bends to hold what it can of it, and against
    // that loop the step's instant did not pay over a drift (11 effective samples): nothing
    // was named, the held-out error 9.7 times the noise. Each family now gets a loop of its
    // own before they are weighed.
    let (v, truth) = lever_generator("kstep", 0);
    assert_eq!(names(&v), ["stiffness_drift"], "{v:#}");
    let (c, step) = (
        truth_value(&truth, "c"),
        param(&v, "stiffness_drift", "stiffness_step"),
    );
    assert!((step / c - 1.0).abs() < 0.05, "step {step} against {c}");
    let at = param(&v, "stiffness_drift", "step_at_s");
    let t_fit = truth_value(&truth, "jump_fit_s");
    assert!(
        (at - t_fit).abs() < 0.05,
        "step at {at} s against {t_fit} s"
    );
    let held = v["effects"][0]["held_out_at_s"][0]["at_s"]
        .as_f64()
        .unwrap();
    let t_ho = truth_value(&truth, "jump_ho_s");
    assert!(
        (held - t_ho).abs() < 0.05,
        "held out at {held} s against {t_ho} s"
    );
    // Within twice the torque's noise held out (the loop's own misfit of Bouc-Wen is the rest).
    let (after, noise) = (
        v["after"]["rmse"].as_f64().unwrap(),
        truth_value(&truth, "noise"),
    );
    assert!(
        after < 2.0 * noise,
        "held out {after} against the noise {noise}"
    );
}

#[test]
fn on_a_link_whose_damping_outweighs_its_inertia_a_torque_lag_that_gives_the_inertia_back_is_named()
{
    // The fourth generator's torque lag, seed 5: a link of I = 0.006 kg·m² and N = 0.33
    // N·m·s/rad whose torque sensor reports 21 ms late, fitted on moves with a trapezoidal
    // speed profile at 2 % noise, a multi-sine held out. The lag makes the link look
    // I − δ·N = −0.0007 kg·m² heavy: with the inertia free the fit took a negative one, which
    // held the lag's first-order share, and the lag that gave the inertia back was refused as
    // its stand-in; nothing was named, the held-out error 1.10 times its clean twin's. A
    // link's inertia is now held ≥ 0, and a torque lag that gives it back need only pay by
    // the criterion (as a lag that runs a joint's loop backwards does).
    let (v, truth, twin) = link_generator_with_twin("tlag", 5);
    a_lag_alone_at_the_plants(&v, &truth, &twin, 0.05, 0.0);
    let (i, i_true) = (
        v["base"]["after"]["inertia_kgm2"].as_f64().unwrap(),
        truth_value(&truth, "I"),
    );
    assert!(
        (i / i_true - 1.0).abs() < 0.15,
        "inertia {i} kg·m² against {i_true}"
    );
    assert_eq!(v["base"]["before"]["inertia_kgm2"].as_f64(), Some(0.0));
    // At its clean twin's floor held out (it was 1.10 times it).
    held_out_within(&v, &twin, 1.03);
}

#[test]
fn on_a_link_fitted_on_moves_between_holds_a_torque_filter_that_the_held_out_motion_confirms_is_named()
 {
    // The fourth generator's torque lag, seed 11: a link (I = 0.062 kg·m², N = 0.061
    // N·m·s/rad) whose torque sensor is a first-order filter of 27.4 ms, fitted on moves with a
    // trapezoidal speed profile at 200 Hz and 2 % noise, a multi-sine held out. To first order
    // a lag is a change of inertia (I − δ·N, here 3 % of I); the rest shows only at the moves'
    // corners, so the lag lowered the validation error by 1.1 %, under the 5 % bar, and
    // nothing was named: 4.6 times its clean twin's error held out. The lag the fit run found
    // is now tried on the held-out run, which confirms it at 1 % and loses 85 % of its error.
    let (v, truth, twin) = link_generator_with_twin("tlag", 11);
    a_lag_alone_at_the_plants(&v, &truth, &twin, 0.1, 1.0);
    // Said to be the held-out run's choice, with the likelihood ratio it passed.
    assert!(
        param(&v, "sensor_delay", "named_on_held_out_likelihood_ratio") > 6.63,
        "{v:#}"
    );
    assert!(v["effects"][0]["validation_gain"].as_f64().unwrap() < 0.05);
    held_out_within(&v, &twin, 1.3);
}

#[test]
fn on_a_link_moved_between_holds_dry_friction_built_up_over_a_speed_near_the_moves_own_is_sized_in_full()
 {
    // The fourth generator's dry friction, seed 7: a link (I = 0.059 kg·m², N = 0.105
    // N·m·s/rad) whose friction builds up as 0.42 N·m·tanh(q̇ / 0.146 rad/s), fitted and held
    // out on moves between holds at 250 Hz, 0.3 % noise. The holds pull the rate's rms down to
    // 0.24 rad/s, and the speeds searched stopped at 0.3 of it: the fit took the grid's top,
    // 0.072 rad/s, a friction of 0.29 N·m and the rest as damping, 9.2 times its clean twin's
    // error held out. The speeds now reach half the fastest the motion went.
    let (v, truth, twin) = link_generator_with_twin("coulomb", 7);
    assert_eq!(names(&v), ["coulomb_friction"], "{v:#}");
    adds_nothing(&twin);
    for (param_name, key, within) in [
        ("builds_over_rad_per_s", "vs", 0.10),
        ("friction_nm", "F", 0.05),
    ] {
        let (got, want) = (
            param(&v, "coulomb_friction", param_name),
            truth_value(&truth, key),
        );
        assert!(
            (got / want - 1.0).abs() < within,
            "{param_name} {got} against the plant's {want}"
        );
    }
    assert_eq!(param(&v, "coulomb_friction", "held_at_rest"), 0.0);
    held_out_within(&v, &twin, 1.3);
}

#[test]
fn on_a_spring_moved_at_one_speed_damping_is_not_taken_for_dry_friction_built_up_over_half_that_speed()
 {
    // The third generator's viscous friction, seed 6: a linear spring with damping, fitted on
    // a triangle wave at 333 Hz (one speed, 0.19 rad/s), ramps held out. A triangle passes
    // speeds below its own only while it turns, and with the speeds searched reaching half
    // the fastest the motion went, dry friction built up over 0.096 rad/s fitted it better
    // than the damping and was named: 0.70 of the error before held out, where the damping
    // gives 0.26. Past 30 % of the rms rate a speed is now tried only where the motion dwells
    // near it.
    let (v, _) = generated("third-generator.py", "linear", "viscous", 6, &[]);
    assert_eq!(names(&v), ["viscous_friction"], "{v:#}");
    held_out_at_most(&v, 0.4);
}

#[test]
fn on_a_spring_with_a_stiff_stop_a_ripple_of_the_longest_period_searched_is_not_named_beside_it() {
    // The third generator's stop, seed 72: a linear spring (574 N·m/rad) meeting a stop 5.6
    // times as stiff at 12.8 mrad, a 250 Hz chirp fitted and a triangle wave held out, a
    // 16-bit encoder whose steps the stop multiplies into torque. The stop was found, and
    // beside it a `periodic_ripple` of exactly five periods over the range — the longest
    // period searched, its error still falling towards longer ones: a smooth function of
    // the deflection, not a located period (the ripples of the generators' own ripple cases
    // sit at 6.9–15.8 periods). It gained 7 % held out. Only the stop is named now.
    let (v, truth, twin) = generated_with_twin("third-generator.py", "linear", "stop", 72);
    assert_eq!(names(&v), ["hard_stop"], "{v:#}");
    adds_nothing(&twin);
    refused_because(&v, "periodic_ripple", "longest searched");
    // The onset where the generator put it (one count of the 16-bit encoder is 96 µrad, 0.75 %).
    let (got, want) = (
        param(&v, "hard_stop", "onset_rad"),
        truth_value(&truth, "at"),
    );
    assert!(
        (got / want - 1.0).abs() < 0.015,
        "onset {got} rad against {want}"
    );
    // The twin's floor is the spring's; beside the stop the encoder's steps cost 5.6 times as
    // much torque: the generator's own stop on the measured deflection leaves 2.0 times the
    // twin's error, the stop found 2.9 times.
    held_out_within(&v, &twin, 3.3);
    // A contact five times as stiff as the spring: the name stands without a doubt beside it.
    no_note_that(&v, |n| n.starts_with("stop:"));
}

#[test]
fn a_stop_the_fit_run_never_reaches_is_not_named_and_the_report_says_the_held_out_run_goes_beyond()
{
    // The third generator's stop, seed 71: a stop at 214 mrad, the fit run's ramps reaching
    // 208, the held-out run's 263. Nothing in the fit data shows the stop, so nothing can be
    // named for it; the held-out error beyond the fit's range is what the report must point
    // to, rather than leave it as unexplained slow structure.
    let (v, truth) = generated("third-generator.py", "linear", "stop", 71, &[]);
    assert!(names(&v).is_empty(), "{v:#}");
    assert!(truth_value(&truth, "at") > 0.208, "{truth}");
    note_that(&v, |n| n.contains("go beyond the fit data's deflection"));
}

#[test]
fn a_backwards_residual_loop_that_a_stiffness_drift_accounts_for_is_not_blamed_on_a_lag_or_a_sign()
{
    // The third generator's stiffness drift, seed 70: a linear spring growing 26 % stiffer
    // over 100 Hz ramps and holds. It unloads stiffer than it loaded, so the linear spring's
    // residual loops the other way round (about −0.14), which the report called "the torque
    // lagging the deflection, or a sign error". The drift is named, the held-out residual no
    // longer loops, and the report says the loop was the drift's.
    let (v, _) = generated("third-generator.py", "linear", "drift", 70, &[]);
    assert_eq!(names(&v), ["stiffness_drift"], "{v:#}");
    let before = v["residual"]["loop_before"].as_f64().unwrap();
    let after = v["residual"]["loop_after"].as_f64().unwrap();
    assert!(before < -0.1 && after > -0.1, "{before} {after}");
    let said = note_that(&v, |n| n.contains("other way round"));
    assert!(
        said.contains("(stiffness_drift)") && !said.contains("sign error"),
        "{said}"
    );
    // A real torque lag on the same spring keeps the lag's wording.
    let (v, _) = generated("third-generator.py", "linear", "lag", 70, &[]);
    assert_eq!(names(&v), ["sensor_delay"], "{v:#}");
    note_that(&v, |n| {
        n.contains("the torque lagging the deflection (found: sensor_delay)")
    });
}

#[test]
fn a_gap_that_a_levers_softening_ends_hide_on_straight_lines_is_found_with_the_lines_bent() {
    // The fifth generator's backlash seed 4: paper B's lever at a 3.9 mm pivot with Bouc-Wen
    // friction and a gap in its spring, ramps to ±0.20 rad fitted, a chirp to ±0.24 rad held
    // out, 2 % noise. The gap makes the joint softer at rest, the lever softer at its ends: on
    // straight lines the two make one secant. The gap alone fitted the fit run better and the
    // held-out chirp worse (held-out RSS 14 % up), and no bend paid alone (0.0 % on
    // validation), so nothing was named. Beside the gap, lines that soften pay on validation
    // and held out, and the identification run again with them names the gap.
    let (v, truth) = lever_generator("backlash", 4);
    assert_eq!(names(&v), ["backlash"], "{v:#}");
    assert_eq!(v["envelope"], "softening", "{v:#}");
    held_out_at_most(&v, 0.8);
    // The generator's gap is in the spring's angle α; near rest α = φ·d_a/(p − d_a) (paper
    // B's lever, p = 31.5 mm, d_a = 9.6 mm + d), so the joint sees a gap of r·(p − d_a)/d_a.
    let d_a = 0.0096 + truth_value(&truth, "d_mm") * 1e-3;
    let want = truth_value(&truth, "r") * (0.0315 - d_a) / d_a;
    let got = param(&v, "backlash", "half_width_rad");
    assert!(
        (got / want - 1.0).abs() < 0.25,
        "half-width {got} rad against the generator's {want}"
    );
    // About as much softer at the fit's reach as the lever: its closed form there is 31 %.
    let softer = v["softening"]["softer_at_x_max"].as_f64().unwrap();
    assert!((0.1..0.4).contains(&softer), "{softer}");
}

#[test]
fn linear_model_finds_the_levers_geometric_stiffness() {
    let cfg = workspace("rig-config/examples/parallel.toml");
    let v = identify(
        &lever_bench("l-geo", false, 0.2, ""),
        &["--model", "linear", "--config", cfg.to_str().unwrap()],
    );
    finds(&v, "geometric_stiffness");
    let s = param(&v, "geometric_stiffness", "scale");
    assert!((s - 1.0).abs() < 0.01, "{s}");
    // Without the lever's geometry it is not a candidate, and the report says why.
    let v = identify(
        &lever_bench("l-geo2", false, 0.2, ""),
        &["--model", "linear"],
    );
    let na = v["not_applicable"].as_array().unwrap();
    assert!(na.iter().any(|e| e["name"] == "geometric_stiffness"), "{v}");
}

#[test]
fn with_a_config_the_restoring_loop_follows_the_levers_curve_and_holds_its_geometry() {
    // The bench config's table is fitted with the lever's envelope (`envelope = "lever"`):
    // identify fits its loop the same way, so the lever's curve is no residual to name, and
    // the loop's k is the joint's stiffness at rest at the 9 mm pivot, G(0)²·k_α = 2.711
    // N·m/rad (paper B's lever, MODEL.md §1), not a secant of the ±0.2 rad stroke.
    let cfg = workspace("rig-config/examples/bench.toml");
    let v = identify(
        &lever_bench("r-geo", false, 0.2, ""),
        &["--config", cfg.to_str().unwrap()],
    );
    assert_eq!(v["envelope"], "lever", "{v}");
    adds_nothing(&v);
    let na = v["not_applicable"].as_array().unwrap();
    let geo = na
        .iter()
        .find(|e| e["name"] == "geometric_stiffness")
        .unwrap();
    assert!(geo["why"].as_str().unwrap().contains("envelope"), "{geo}");
    let k = v["base"]["after"]["stiffness_nm_per_rad"].as_f64().unwrap();
    assert!((k / 2.7114 - 1.0).abs() < 0.02, "k {k}");
    // A joint the config does not have is named, with the ones it has.
    let o = Command::new(bin("rig"))
        .args([
            "identify",
            "--joint",
            "j9",
            "--config",
            cfg.to_str().unwrap(),
            "--data",
        ])
        .arg(lever_bench("r-geo", false, 0.2, ""))
        .arg("--report")
        .arg(scratch("r-geo-j9.json"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--joint j9") && err.contains("j1"),
        "{err}"
    );
    // Without the config: lines bent toward the ends (`softening`), whose k is the stiffness
    // at rest again (2.734, 0.8 % off); kept straight (`--straight`, paper B's lines), k is a
    // secant of the stroke.
    let csv = lever_bench("r-geo2", false, 0.2, "");
    let v = identify(&csv, &[]);
    assert_eq!(v["envelope"], "softening", "{v}");
    let k = v["base"]["after"]["stiffness_nm_per_rad"].as_f64().unwrap();
    assert!((k / 2.7114 - 1.0).abs() < 0.02, "k {k}");
    let v = identify(&csv, &["--straight"]);
    assert_eq!(v["envelope"], "linear", "{v}");
    let k = v["base"]["after"]["stiffness_nm_per_rad"].as_f64().unwrap();
    assert!((k / 2.7114 - 1.0).abs() > 0.05, "k {k}");
}

// Declared: paper A's link equation; plant: the AWAS.

fn link_parameters_match_the_config(v: &Value) {
    // rig-config/examples/awas.toml: I = 0.05 kg·m², N = 0.4 N·m·s/rad.
    let (i, n) = (
        v["inertia"].as_f64().unwrap(),
        v["damping"].as_f64().unwrap(),
    );
    assert!((i - 0.05).abs() < 0.05 * 0.05, "inertia {i}");
    assert!((n - 0.4).abs() < 0.05 * 0.4, "damping {n}");
}

#[test]
fn link_equation_on_clean_data_adds_nothing_and_fits_inertia_and_damping() {
    let v = identify(&awas("a-clean", ""), &["--model", "link"]);
    adds_nothing(&v);
    link_parameters_match_the_config(&v);
    // The 14-bit link angle is read as the taut string through its counts, and the report
    // names the run it was done for.
    let strung = &v["weak_form"]["angle_read_as_taut_string"];
    assert_eq!(strung.as_array().map(Vec::len), Some(1), "{strung}");
}

#[test]
fn link_equation_finds_gravity() {
    let v = identify(
        &awas("a-gravity", "gravity_mass_kg = 1.0\ngravity_com_m = 0.1"),
        &["--model", "link"],
    );
    finds(&v, "gravity");
    let mgl = param(&v, "gravity", "mgl_nm");
    assert!((mgl - 0.981).abs() < 0.05, "{mgl}");
    link_parameters_match_the_config(&v);
}

#[test]
fn link_equation_finds_coulomb_friction() {
    let v = identify(
        &awas("a-coulomb", "coulomb_friction_nm = 0.5"),
        &["--model", "link"],
    );
    finds(&v, "coulomb_friction");
    link_parameters_match_the_config(&v);
}

#[test]
fn link_equation_finds_sensor_delay() {
    let v = identify(
        &awas("a-delay", "sensor_delay_s = 0.01"),
        &["--model", "link"],
    );
    finds(&v, "sensor_delay");
    link_parameters_match_the_config(&v);
}

// Real data: the torsion springs of ../shared/data (see its README).

/// The measured springs, or None (with instructions) outside CI when they are not there.
fn springs() -> Option<PathBuf> {
    let dir = workspace("../shared/data/sea-torsion-springs");
    if dir.is_dir() {
        return Some(dir);
    }
    let how = format!(
        "the measured data is not at {}: put the project's shared data beside the clone \
         (../shared/data/sea-torsion-springs, from the public repository \
         ITregear/SeriesElasticActuation-FYP, Python/TestData/StiffnessTesting; see \
         docs/IDENTIFY.md). The synthetic tests do not need it.",
        dir.display()
    );
    assert!(std::env::var_os("CI").is_none(), "{how}");
    eprintln!("skipped: {how}");
    None
}

#[test]
fn measured_spring_5_at_9_nm_linear_start_names_what_it_lacks_and_says_what_is_messy() {
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-9-1-70-5-09032023-143520.csv")],
        &dir.join("kt-9-2-71-5-09032023-143611.csv"),
        "spring5-9nm.json",
    );
    // The data README: a linear fit leaves about 1.1 N·m against a 10 N·m peak (fitted on
    // the same test); fitted on one test and scored on the other it is a little worse.
    let (before, after) = (rmse(&v, "before"), rmse(&v, "after"));
    assert!((1.0..1.5).contains(&before), "before {before}");
    assert!(after < 0.5 * before, "after {after}");
    // The loop is the largest missing effect, and every added effect pays off held out.
    let n = names(&v);
    assert!(n.iter().any(|e| e == "hysteresis"), "{n:?}");
    for e in v["effects"].as_array().unwrap() {
        assert!(e["gain_rmse"].as_f64().unwrap() > 0.0, "{e}");
    }
    // Both tests rest for their first 5 s (the data's README): each rest is found and read
    // as a state of the loop; the loop holds both (no torque zero left over).
    let tare = v["tare"]
        .as_array()
        .expect("both files start at rest: a tare per file");
    assert_eq!(tare.len(), 2, "{tare:?}");
    for t in tare {
        let w = t["window_s"].as_f64().unwrap();
        assert!((4.0..5.5).contains(&w), "rest of {w} s: {t}");
        assert!(t["torque_zero"].as_f64().unwrap().abs() < 0.2, "{t}");
        let lam = t["loop_state"].as_f64().expect("a state of the loop");
        assert!((-1.0..=1.0).contains(&lam), "{t}");
    }
    // The held-out test's encoder was zeroed at its start, where the fit test had left the
    // spring: read from there (0.35 mrad on), no bias is left on it (the rest rule, taking
    // each rest for the zeros, left 0.29 N·m and an "offset:" note).
    let shift =
        tare[1]["deflection_zero"].as_f64().unwrap() - tare[0]["deflection_zero"].as_f64().unwrap();
    assert!(
        (1e-4..1e-3).contains(&shift.abs()),
        "frame shift {shift} rad"
    );
    let bias = v["bias"][0]["mean_residual_nm"].as_f64().unwrap();
    assert!(bias.abs() < 0.1, "held-out bias {bias} N·m");
    // Irregular sampling is reported, and the messy parts are said, not hidden.
    assert_eq!(v["sampling"][0]["irregular"], true);
    note_that(&v, |n| n.starts_with("steps:"));
    assert_eq!(v["residual"]["white"], false);
    for f in [
        "spring5-9nm.md",
        "spring5-9nm-fit.png",
        "spring5-9nm-residual.png",
    ] {
        let p = scratch(f);
        assert!(
            std::fs::metadata(&p).unwrap().len() > 1000,
            "{}",
            p.display()
        );
    }
}

#[test]
fn measured_spring_1_at_2_nm_scored_on_its_earlier_test_is_never_worse_than_linear() {
    // Fitted on the second test, scored on the first. Nothing is named; the first test rests
    // reading a load (−0.317 N·m at −8.96 mrad) that its own loading branch passes 0.36 N·m
    // lower later, and the rest rule took 0.445 N·m of it for a zero: 0.310 N·m held out
    // against the linear spring's 0.267 as measured. Read as measured, it is the linear
    // spring's.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-2-2-5-1-27022023-162542.csv")],
        &dir.join("kt-2-1-4-1-27022023-162251.csv"),
        "spring1-2nm-swapped.json",
    );
    let (before, after) = (rmse(&v, "before"), rmse(&v, "after"));
    assert!(
        after <= before * (1.0 + 1e-9),
        "held-out RMSE {before} → {after}"
    );
    let untaken = v["tare"][1]["zero_not_taken_nm"].as_f64();
    assert!(
        untaken.is_some_and(|z| (z - 0.445).abs() < 0.01),
        "{}",
        v["tare"]
    );
    assert_eq!(v["tare"][1]["torque_zero"].as_f64(), Some(0.0));
}

#[test]
fn measured_spring_1_at_1_nm_gets_a_stop_of_its_own_on_each_side_where_one_symmetric_stop_would_not_pay()
 {
    // The deflection meets a stiffer stretch at +6.0 mrad and at −7.4 mrad, 11 and 8 N·m/rad
    // past them. One stop the same on both sides scores −9 against none and is refused; the
    // pair scores +199. With the symmetric stop picked (bf68ece–3eaea6b) nothing was named
    // at 0.052 N·m held out; the pair and the 32 ms torque lag it lets through reach 0.013.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-1-1-1-1-27022023-160414.csv")],
        &dir.join("kt-1-2-2-1-27022023-161500.csv"),
        "spring1-1nm.json",
    );
    assert_eq!(
        names(&v).first().map(String::as_str),
        Some("hard_stop"),
        "{v:#}"
    );
    let (up, down) = (
        param(&v, "hard_stop", "onset_rad"),
        param(&v, "hard_stop", "onset_negative_rad"),
    );
    assert!(
        (up + down).abs() > 1e-3 && up > 0.0 && down < 0.0,
        "onsets {up} and {down}: one on each side, more than 1 mrad apart in size"
    );
    let (tared, after) = (rmse(&v, "tared"), rmse(&v, "after"));
    assert!(after < 0.5 * tared, "held-out RMSE tared {tared} → {after}");
}

#[test]
fn measured_spring_4_at_half_a_nm_keeps_the_torque_lag_its_fit_tests_vetoed_zero_jump_had_unmasked()
{
    // The fit test's torque zero jumps once part-way; the held-out test has no such jump, so
    // the jump is rightly vetoed. Beside it the criterion paid for a 19 ms torque lag that the
    // held-out test confirmed; the reruns without the jump never chose the lag again (searched
    // alone, the jump's misfit swamps it), and nothing was named: 0.019 N·m held out, tared.
    // Judged again beside the last pass's set, the lag is kept: 0.013.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-0.5-1-37-4-27022023-181404.csv")],
        &dir.join("kt-0.5-2-38-4-27022023-181511.csv"),
        "spring4-half-nm.json",
    );
    assert_eq!(names(&v), ["sensor_delay"], "{v:#}");
    // Named, it is no longer among the refused (the last pass had refused it alone).
    never_refused(&v, "sensor_delay");
    // The jump that unmasked it is refused held out.
    refused_because(&v, "offset", "not the held-out error");
    let delay = param(&v, "sensor_delay", "delay_s");
    assert!(
        (0.010..0.030).contains(&delay),
        "the torque lags by {delay} s: the residual follows the rate 26 ms later"
    );
    let (tared, after) = (rmse(&v, "tared"), rmse(&v, "after"));
    assert!(after < 0.8 * tared, "held-out RMSE tared {tared} → {after}");
}

#[test]
fn measured_spring_3_at_2_nm_judges_its_stops_and_torque_lag_again_beside_the_zero_jump_its_held_out_test_needs()
 {
    // The fit rows choose the hysteresis, a pair of stops and a 31 ms torque lag; the held-out
    // check refused the stops and the lag beside the hysteresis alone, where the held-out
    // test's own torque zero jump (named in the next pass) swamped their gains. Judged again
    // beside that jump, both are confirmed: 0.092 → 0.038 N·m held out.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-2-7-31-3-27022023-175356.csv")],
        &dir.join("kt-2-8-32-3-27022023-175449.csv"),
        "spring3-2nm.json",
    );
    let named = names(&v);
    for effect in ["hysteresis", "offset", "hard_stop", "sensor_delay"] {
        assert!(
            named.iter().any(|n| n == effect),
            "{effect} not in {named:?}"
        );
    }
    // Named, neither is among the refused any more.
    never_refused(&v, "hard_stop");
    never_refused(&v, "sensor_delay");
    let delay = param(&v, "sensor_delay", "delay_s");
    assert!(
        (0.020..0.040).contains(&delay),
        "the torque lags by {delay} s (26 ms on the same spring at 1 N·m)"
    );
    // Its stops start where the same spring's at 1 N·m start on the positive side (+9.0 mrad).
    let onset = param(&v, "hard_stop", "onset_rad");
    assert!((0.007..0.012).contains(&onset), "stop from {onset} rad");
    let (tared, after) = (rmse(&v, "tared"), rmse(&v, "after"));
    assert!(after < 0.2 * tared, "held-out RMSE tared {tared} → {after}");
}

#[test]
fn measured_spring_5_at_1_nm_swinging_seventeen_dead_bands_gets_stops_narrow_enough_to_trace_its_loop()
 {
    // A 2500 N·m/rad spring at 1 N·m swings 0.73 mrad: 52 counts of its AS5311, 17 dead bands
    // of three counts. Stops from ten dead bands (0.42 mrad) are wider than half the swing:
    // none was searched, and the loop of ±0.02 N·m its branches show (loading at the line,
    // unloading 0.04 N·m under it, the same in both tests) went unnamed, 0.022 N·m held out.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-1-10-46-5-09032023-141035.csv")],
        &dir.join("kt-1-10-47-5-09032023-141224.csv"),
        "spring5-1nm.json",
    );
    assert!(names(&v).iter().any(|n| n == "hysteresis"), "{v:#}");
    // Its stops slide within the swing: none wider than half of it (0.37 mrad), none narrower
    // than a dead band (3 × 14 µrad).
    let (narrowest, widest) = (
        param(&v, "hysteresis", "narrowest_half_width_rad"),
        param(&v, "hysteresis", "widest_half_width_rad"),
    );
    assert!(
        narrowest >= 4.2e-5 && widest <= 3.7e-4,
        "stops of half-widths {narrowest} to {widest} rad"
    );
    let (tared, after) = (rmse(&v, "tared"), rmse(&v, "after"));
    assert!(after < 0.6 * tared, "held-out RMSE tared {tared} → {after}");
}

#[test]
fn measured_spring_2_at_2_nm_a_stop_that_stiffens_it_by_a_few_per_cent_is_said_to_be_as_likely_the_springs_own()
 {
    // 2620 N·m/rad at 2 N·m: the deflection swings ±0.8 mrad, and a `hard_stop` from −0.16 mrad
    // lowers the held-out error (0.026 → 0.022 N·m) by adding under 4 % of the spring's own
    // stiffness on one side. A contact adds about the spring's stiffness or more; a slope that
    // changes by a few per cent is as likely the spring's own (a progressive or asymmetric
    // spring), and the report says so, with the share computed from its own numbers.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-2-4-16-2-27022023-172136.csv")],
        &dir.join("kt-2-5-17-2-27022023-172319.csv"),
        "spring2-2nm.json",
    );
    assert_eq!(names(&v), ["hard_stop"], "{v:#}");
    let k = v["base"]["after"]["stiffness_nm_per_rad"].as_f64().unwrap();
    let rate = param(&v, "hard_stop", "stop_rate_negative_nm_per_rad");
    let share = 100.0 * rate / k;
    assert!(share > 0.0 && share < 10.0, "{rate} of {k} N·m/rad");
    let note = note_that(&v, |n| n.starts_with("stop:"));
    let onset = param(&v, "hard_stop", "onset_negative_rad");
    assert!(
        note.contains(&format!("beyond {:+.2} mrad", onset * 1e3))
            && note.contains(&format!("({share:.1} %)"))
            && note.contains("progressive or asymmetric spring"),
        "{note}"
    );
}

#[test]
fn measured_spring_2_at_1_nm_smoothed_as_wide_as_its_slow_motion_allows_names_no_lag_at_the_search_bound()
 {
    // 2600 N·m/rad at 1 N·m, sampled at 100 Hz: its encoder's 30 µrad of noise reaches the
    // torque as 0.077 N·m rms. Averaged over the rates' window only (two samples each side,
    // which leave 70 % of it), a first-order filter on the torque "gained" by averaging the
    // rest: 94.1 ms, at the bound of the lags searched, 0.24 of the error before. The test is
    // a slow ramp-and-hold: each sample's quadratic widens to hundreds of milliseconds where the
    // motion is straight.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-1-4-13-2-27022023-171453.csv")],
        &dir.join("kt-1-5-14-2-27022023-171936.csv"),
        "spring2-1nm.json",
    );
    for e in v["effects"].as_array().unwrap() {
        assert!(e["params"]["at_search_bound"].is_null(), "{e:#}");
    }
    for run in v["smoothing"].as_array().unwrap() {
        let h = run["half_window_s"].as_f64().unwrap();
        assert!(h > 0.1, "{run:#}");
    }
    let (before, after) = (rmse(&v, "before"), rmse(&v, "after"));
    assert!(after < 0.2 * before, "held-out RMSE {before} → {after}");
}

#[test]
fn measured_spring_3_at_3_nm_scored_on_its_earlier_test_keeps_the_hysteresis_that_halves_its_error()
{
    // Fitted on the second test, scored on the first. The hysteresis takes the first test's
    // RMSE from 3.33 to 1.17 N·m, but what it leaves there is a few slow swings: 3.1
    // effective samples, a likelihood ratio of 6.55 against χ²₁'s 6.63 at 1 %, and it was
    // refused. A check that short cannot confirm a halving at 1 % (that takes 4.8 samples);
    // it takes one at 5 %.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-3-8-35-3-27022023-175747.csv")],
        &dir.join("kt-3-7-34-3-27022023-175632.csv"),
        "spring3-3nm-swapped.json",
    );
    let (before, after) = (rmse(&v, "before"), rmse(&v, "after"));
    assert!(after < 0.5 * before, "held-out RMSE {before} → {after}");
    assert_eq!(names(&v), ["hysteresis"]);
}

#[test]
fn under_the_restoring_model_rests_that_friction_holds_loaded_are_tared_but_not_named_a_sensor_offset()
 {
    // Paper B's restoring model takes every rest for the zeros (its loop has no state to read
    // from a rest: docs/IDENTIFY.md, Left). Measured spring 2's tests at 4 N·m rest at 0.18 and
    // 0.24 N·m, 10–14 times the torque's noise and the same within a quarter — what a torque
    // sensor's offset looks like at rest, and what a loop held loaded by friction looks like
    // too. A sensor's offset taken out predicts the other test better; this tare predicts it
    // worse, so it is no offset (until 2026-12-02 it was named one, with a held-out "gain" of
    // −0.058 N·m).
    let Some(dir) = springs() else { return };
    let v = report_of(
        spring_command(
            Some("restoring"),
            &[&dir.join("kt-4-4-22-2-27022023-172928.csv")],
            &dir.join("kt-4-5-23-2-27022023-173037.csv"),
        ),
        &scratch("spring2-4nm-restoring.json"),
    );
    // The premise: both rests read well over the noise, and the tare raises the held-out error.
    for t in v["tare"].as_array().unwrap() {
        let (zero, noise) = (
            t["torque_zero"].as_f64().unwrap(),
            t["torque_noise"].as_f64().unwrap(),
        );
        assert!(zero > 5.0 * noise, "{t}");
    }
    let (before, tared) = (rmse(&v, "before"), rmse(&v, "tared"));
    assert!(tared > before, "the tare: held-out RMSE {before} → {tared}");
    assert!(
        !names(&v).contains(&"offset".to_string()),
        "{:?}",
        names(&v)
    );
}

#[test]
fn measured_spring_2_at_4_nm_scored_on_its_earlier_test_is_a_slipping_loop_on_a_spring_that_never_softens()
 {
    // Fitted on the second test, scored on the first. Spring 2's loop at 4 N·m is a
    // parallelogram: branches at about 2100 N·m/rad, and near each torque peak the deflection
    // slides 3–4 mrad at nearly constant torque (a clamp that slips). The first test starts
    // 2.3 mrad from where the second rests, where the slip left it. With the spring's k free
    // beside the stops, the search's fits took k = −7 000 to −21 700 N·m/rad against stops
    // that summed to 2 800 N·m/rad more: within the fit test's range the widest stops act as
    // a stiffness, beyond it the torque falls as the spring is wound further. The first test
    // goes 1.5 mrad further; the loop lowered the validation error by 65 % but not the
    // held-out error, and nothing was named (2.448 N·m held out against 3.505 before).
    // The outside review's baseline (rest tare, 11 play operators:
    // `SWAP=1 python3 scripts/springs_baseline.py`) gets 0.512 N·m.
    let Some(dir) = springs() else { return };
    let v = identify_spring(
        &[&dir.join("kt-4-5-23-2-27022023-173037.csv")],
        &dir.join("kt-4-4-22-2-27022023-172928.csv"),
        "spring2-4nm-swapped.json",
    );
    let (before, after) = (rmse(&v, "before"), rmse(&v, "after"));
    assert!((3.0..4.0).contains(&before), "before {before}");
    assert!(after < 0.512, "held-out RMSE {before} → {after}");
    assert_eq!(names(&v), ["hysteresis"]);
    let k = v["base"]["after"]["stiffness_nm_per_rad"].as_f64().unwrap();
    assert!(k >= 0.0, "k = {k} N·m/rad");
    // The loop holds the first test's rest: its state read there, no torque zero taken.
    let t = &v["tare"][1];
    let lam = t["loop_state"].as_f64().expect("a state of the loop");
    assert!(lam.abs() < 1.0, "{t}");
    let zero = t["torque_zero"].as_f64().unwrap();
    assert!(zero.abs() < 0.05, "{t}");
}

#[test]
fn measured_spring_2_read_in_its_raw_frame_is_fitted_by_the_restoring_loop_beside_a_torque_offset_and_by_default_as_the_linear_spring()
 {
    // Spring 2 at 2 N·m is read −9.6 to −7.2 mrad from its encoder's zero (never re-zeroed
    // between tests). The restoring loop's lines pass through zero: on the data as given its
    // linear start finds a slope of −15 N·m/rad, no spring. Beside a torque constant (as the
    // linear spring has) it finds the spring; and a spring's file (no pivot position) gets the
    // linear spring when no --model is given.
    let Some(dir) = springs() else { return };
    let (fit, held) = (
        dir.join("kt-2-4-16-2-27022023-172136.csv"),
        dir.join("kt-2-5-17-2-27022023-172319.csv"),
    );
    let command = |model| spring_command(model, &[&fit], &held);
    let linear = identify_spring(&[&fit], &held, "spring2-2nm.json");
    let k = linear["base"]["before"]["stiffness_nm_per_rad"]
        .as_f64()
        .unwrap();
    assert!((2000.0..3200.0).contains(&k), "k = {k} N·m/rad");
    assert!(rmse(&linear, "after") <= rmse(&linear, "before"));

    let r = report_of(
        command(Some("restoring")),
        &scratch("spring2-2nm-restoring.json"),
    );
    let before = &r["base"]["before"];
    let k_loop = before["stiffness_nm_per_rad"].as_f64().unwrap();
    assert!((2000.0..3200.0).contains(&k_loop), "k = {k_loop} N·m/rad");
    // The offset is the torque at the deflection's zero, about k × 8.4 mrad.
    let offset = before["offset_nm"].as_f64().unwrap();
    assert!((15.0..30.0).contains(&offset), "offset {offset} N·m");
    // A loop with a torque constant holds the linear spring (a loop of no height), so its
    // "before" is no worse than the linear spring's, and what is added only lowers it.
    assert!(
        rmse(&r, "before") <= 1.05 * rmse(&linear, "before"),
        "loop {} against the linear spring's {}",
        r["before"],
        linear["before"]
    );
    assert!(rmse(&r, "after") <= rmse(&r, "before"), "{}", r["after"]);

    // No --model: the file has no pivot position, so it is a spring, fitted as the linear
    // spring is — the same figures as `--model linear`, and the report says why.
    let d = report_of(command(None), &scratch("spring2-2nm-default.json"));
    assert_eq!(d["model"], "linear", "{}", d["notes"]);
    assert_eq!(d["before"], linear["before"]);
    assert_eq!(d["after"], linear["after"]);
    let notes = d["notes"].to_string();
    assert!(
        notes.contains("no --model") && notes.contains("no pivot position"),
        "{notes}"
    );
}

/// `rig identify --model linear` on measured spring tests (the data README's columns), fitted
/// on `fit` in that order and held out on `held`; the report, written under `report`.
fn identify_spring(fit: &[&Path], held: &Path, report: &str) -> Value {
    report_of(spring_command(Some("linear"), fit, held), &scratch(report))
}

/// `rig identify` with `--model model` (none: the default) on measured spring tests (the data
/// README's columns), fitted on `fit` in that order and held out on `held`.
fn spring_command(model: Option<&str>, fit: &[&Path], held: &Path) -> Command {
    let mut c = Command::new(bin("rig"));
    c.arg("identify");
    if let Some(m) = model {
        c.args(["--model", m]);
    }
    c.args(["--columns", "t=time,phi=displacement:deg,tau=torque_out"]);
    for f in fit {
        c.arg("--data").arg(f);
    }
    c.arg("--holdout").arg(held);
    c
}

/// Where a measured test ends unloaded [rad], as the data README's columns give it: the
/// medians of its last 0.25 s of deflection (deg) and torque, the deflection less the torque
/// over `k` (the upper median of an even count, as the library takes it).
fn end_unloaded(csv: &Path, k: f64) -> f64 {
    let text = std::fs::read_to_string(csv).unwrap();
    let rows: Vec<(f64, f64, f64)> = text
        .lines()
        .skip(1)
        .map(|l| {
            let c: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            (c[1], c[3], c[4].to_radians())
        })
        .collect();
    let t_end = rows.last().unwrap().0;
    let tail: Vec<_> = rows.iter().filter(|r| r.0 >= t_end - 0.25).collect();
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let x = median(tail.iter().map(|r| r.2).collect());
    let tau = median(tail.iter().map(|r| r.1).collect());
    x - tau / k
}

#[test]
fn measured_spring_5_fitted_on_both_tests_reads_each_from_where_the_test_before_it_ended() {
    // On 9 Mar every test's encoder was zeroed at its start, where the test before it had
    // left the spring. Fitted on both tests, the second is read in the first's frame shifted
    // by where the first ends unloaded, and a held-out test after them by where each ended:
    // a third test follows the second, not the first.
    let Some(dir) = springs() else { return };
    let (first, second) = (
        dir.join("kt-9-1-70-5-09032023-143520.csv"),
        dir.join("kt-9-2-71-5-09032023-143611.csv"),
    );
    let v = identify_spring(&[&first, &second], &second, "spring5-9nm-both.json");
    let k = v["base"]["before"]["stiffness_nm_per_rad"]
        .as_f64()
        .unwrap();
    let (e1, e2) = (end_unloaded(&first, k), end_unloaded(&second, k));
    let zero = |i: usize| v["tare"][i]["deflection_zero"].as_f64().unwrap();
    // The first test ends 0.35 mrad on (its loop's remanent deflection): far more than a
    // count (14 µrad), so reading the second in the first's frame would be plainly wrong.
    // (Within a third of a count: the medians are of counts, and a row at the window's edge
    // read otherwise would move one by a count at most.)
    assert!((1e-4..1e-3).contains(&e1.abs()), "first ends at {e1} rad");
    assert!(
        (zero(0) - zero(1) - e1).abs() < 5e-6,
        "second fit file shifted {} rad, the first ends at {e1} rad",
        zero(0) - zero(1)
    );
    // The report says which file each was read after (the first, as measured, none).
    let after = |i: usize| v["tare"][i]["read_after"].as_str().map(str::to_owned);
    let name = |p: &Path| p.file_name().unwrap().to_string_lossy().into_owned();
    assert_eq!(
        (after(0), after(1), after(2)),
        (None, Some(name(&first)), Some(name(&second))),
        "{}",
        v["tare"]
    );
    assert!(
        (zero(0) - zero(2) - (e1 + e2)).abs() < 5e-6,
        "held-out file shifted {} rad, the two end at {e1} + {e2} rad",
        zero(0) - zero(2)
    );
}
