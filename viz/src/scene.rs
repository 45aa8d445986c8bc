//! What is drawn, from which message, at what rate; and the blueprint that lays it out.

use std::collections::{BTreeMap, VecDeque};

use rerun::blueprint::{
    Blueprint, ContainerLike, Grid, Horizontal, Spatial2DView, Tabs, TextLogView, TimeSeriesView,
    Vertical,
};
use rerun::{
    Arrows2D, Color, LineStrips2D, Points2D, RecordingStream, RecordingStreamResult, Scalars,
    SeriesLines, TextLog,
};
use rig_config::{JointKind, RigConfig};
use rig_model::planar::{PlanarRobot, end_effector_force};
use rig_protocol::{AnyMessage, JointSample, JointState, StiffnessTriple, Topic};

use crate::paths;
use crate::trail::{self, Gate, Trail};

/// Time series rate, loop trail (window, spacing, redraw), robot redraw [ns].
const SERIES_NS: u64 = 10_000_000;
const LOOP_WINDOW_NS: u64 = 2_000_000_000;
const LOOP_SPACING_NS: u64 = 10_000_000;
const LOOP_REDRAW_NS: u64 = 200_000_000;
const ROBOT_NS: u64 = 50_000_000;
/// Arrow length per newton on the robot view [mm/N].
const MM_PER_N: f32 = 5.0;
/// The timeline every entity is logged on: the rig's acquisition clock.
pub const TIMELINE: &str = "rig_time";

const ESTIMATE: [u8; 3] = [255, 140, 0];
const TRUTH: [u8; 3] = [30, 120, 220];
const WANTED: [u8; 3] = [40, 170, 60];
const LINK: [u8; 3] = [200, 200, 200];

/// What the view did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VizStats {
    pub messages: u64,
    /// Log calls made (after decimation).
    pub logged: u64,
    pub skipped: u64,
    pub errors: u64,
}

struct JointView {
    name: String,
    /// Recent samples' deflection [rad] and measured torque, by sequence number: the modelled
    /// torque of an estimate is drawn against the deflection of its sample.
    recent: VecDeque<(u64, f64)>,
    measured: Trail,
    model: Trail,
    series: Gate,
    truth_series: Gate,
    estimate_series: Gate,
    redraw: Gate,
    awas: Option<(f64, f64)>,
}

pub(crate) struct Scene {
    robot: Option<PlanarRobot>,
    joints: Vec<JointView>,
    /// True torque and link angle per joint, by tick time, until every joint has reported.
    truths: BTreeMap<u64, Vec<Option<(f64, f64)>>>,
    ee_series: Gate,
    ee_robot: Gate,
    truth_series: Gate,
    truth_robot: Gate,
    pub(crate) stats: VizStats,
}

fn rgb(c: [u8; 3]) -> Color {
    Color::from_rgb(c[0], c[1], c[2])
}

fn strip(points: &[(f64, f64)]) -> Vec<[f32; 2]> {
    points
        .iter()
        .map(|&(x, y)| [(x * 1e3) as f32, -(y * 1e3) as f32])
        .collect()
}

/// The stiffness ellipse of K [N/m] drawn as K·u for unit displacements u, in N/mm (y up).
fn ellipse(k: &StiffnessTriple) -> Vec<[f32; 2]> {
    (0..=72)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / 72.0;
            let (c, s) = (a.cos(), a.sin());
            let fx = (k.xx * c + k.xy * s) * 1e-3;
            let fy = (k.xy * c + k.yy * s) * 1e-3;
            [fx as f32, -fy as f32]
        })
        .collect()
}

impl Scene {
    pub(crate) fn new(cfg: &RigConfig) -> Self {
        let joints = cfg
            .joints
            .iter()
            .map(|j| JointView {
                name: j.name.clone(),
                recent: VecDeque::new(),
                measured: Trail::new(LOOP_WINDOW_NS, LOOP_SPACING_NS),
                model: Trail::new(LOOP_WINDOW_NS, LOOP_SPACING_NS),
                series: Gate::every(SERIES_NS),
                truth_series: Gate::every(SERIES_NS),
                estimate_series: Gate::every(SERIES_NS),
                redraw: Gate::every(LOOP_REDRAW_NS),
                awas: match &j.kind {
                    JointKind::Awas { dynamics, .. } => {
                        Some((dynamics.link_inertia, dynamics.link_damping))
                    }
                    JointKind::Lever { .. } => None,
                },
            })
            .collect();
        Self {
            robot: cfg.robot(),
            joints,
            truths: BTreeMap::new(),
            ee_series: Gate::every(SERIES_NS),
            ee_robot: Gate::every(ROBOT_NS),
            truth_series: Gate::every(SERIES_NS),
            truth_robot: Gate::every(ROBOT_NS),
            stats: VizStats::default(),
        }
    }

    /// Series styles (names, colours) and the true AWAS parameters, once.
    pub(crate) fn log_static(&self, rec: &RecordingStream) -> RecordingStreamResult<()> {
        let line = |rec: &RecordingStream, path: String, name: &str, color: [u8; 3]| {
            rec.log_static(
                path,
                &SeriesLines::new().with_names([name]).with_colors([color]),
            )
        };
        for j in &self.joints {
            let p = paths::joint(&j.name);
            line(rec, format!("{p}/pivot_mm"), "pivot [mm]", ESTIMATE)?;
            line(
                rec,
                format!("{p}/stiffness/estimate"),
                "k̂ [N·m/rad]",
                ESTIMATE,
            )?;
            line(
                rec,
                format!("{p}/stiffness/truth"),
                "k true [N·m/rad]",
                TRUTH,
            )?;
            if j.awas.is_some() {
                for (q, unit) in [("inertia", "kg·m²"), ("damping", "N·m·s/rad")] {
                    line(
                        rec,
                        format!("{p}/{q}/estimate"),
                        &format!("{q} [{unit}]"),
                        ESTIMATE,
                    )?;
                    line(rec, format!("{p}/{q}/plus_2sigma"), "+2σ", ESTIMATE)?;
                    line(rec, format!("{p}/{q}/minus_2sigma"), "−2σ", ESTIMATE)?;
                    line(rec, format!("{p}/{q}/config"), "config", TRUTH)?;
                }
            }
        }
        for axis in ["x", "y"] {
            line(
                rec,
                paths::force("estimate", axis),
                &format!("F̂{axis} [N]"),
                ESTIMATE,
            )?;
            line(
                rec,
                paths::force("truth", axis),
                &format!("F{axis} true [N]"),
                TRUTH,
            )?;
        }
        for c in ["xx", "xy", "yy"] {
            line(
                rec,
                paths::stiffness("wanted", c),
                &format!("wanted K{c} [N/m]"),
                WANTED,
            )?;
            line(
                rec,
                paths::stiffness("achieved", c),
                &format!("allocated K{c} [N/m]"),
                TRUTH,
            )?;
            line(
                rec,
                paths::stiffness("estimated", c),
                &format!("estimated K{c} [N/m]"),
                ESTIMATE,
            )?;
        }
        if let Some(robot) = &self.robot {
            let bases: Vec<[f32; 2]> = match robot {
                PlanarRobot::Serial(_) => vec![[0.0, 0.0]],
                PlanarRobot::FiveBar(r) => vec![[0.0, 0.0], [(r.geometry.lb * 1e3) as f32, 0.0]],
            };
            rec.log_static(
                paths::ROBOT_BASES,
                &Points2D::new(bases)
                    .with_radii([4.0])
                    .with_colors([rgb(LINK)]),
            )?;
        }
        Ok(())
    }

    fn scalar(&mut self, rec: &RecordingStream, path: String, v: f64) -> RecordingStreamResult<()> {
        if v.is_finite() {
            self.stats.logged += 1;
            rec.log(path, &Scalars::single(v))?;
        }
        Ok(())
    }

    fn joint_sample(
        &mut self,
        rec: &RecordingStream,
        s: &JointSample,
    ) -> RecordingStreamResult<()> {
        let Some(j) = self.joints.get_mut(s.joint as usize) else {
            return Ok(());
        };
        rec.set_timestamp_nanos_since_epoch(TIMELINE, s.t_acq_ns as i64);
        j.recent.push_back((s.seq, s.deflection_rad));
        if j.recent.len() > 256 {
            j.recent.pop_front();
        }
        if let Some(tau) = s.torque_nm {
            j.measured
                .push(s.t_acq_ns, s.deflection_rad.to_degrees(), -tau);
        }
        if j.series.pass(s.t_acq_ns)
            && let Some(p) = s.pivot_m
        {
            let path = format!("{}/pivot_mm", paths::joint(&j.name));
            self.scalar(rec, path, p * 1e3)?;
        }
        self.redraw_loop(rec, s.joint as usize, s.t_acq_ns)?;
        Ok(())
    }

    pub(crate) fn on(
        &mut self,
        rec: &RecordingStream,
        topic: &Topic,
        msg: &AnyMessage,
    ) -> RecordingStreamResult<()> {
        self.stats.messages += 1;
        match msg {
            AnyMessage::JointSample(s) => self.joint_sample(rec, s)?,
            // A board's tick: each of its joints' samples, as if each had come on its own key.
            AnyMessage::BoardSample(b) => {
                for s in &b.samples {
                    self.joint_sample(rec, s)?;
                }
            }
            AnyMessage::SimTruth(t) => {
                let n = self.joints.len();
                let Some(j) = self.joints.get_mut(t.joint as usize) else {
                    return Ok(());
                };
                rec.set_timestamp_nanos_since_epoch(TIMELINE, t.t_acq_ns as i64);
                // With a torque sensor the loop shows the sensor; without, the truth.
                if j.awas.is_none() {
                    j.measured
                        .push(t.t_acq_ns, t.deflection_rad.to_degrees(), -t.torque_nm);
                }
                if j.truth_series.pass(t.t_acq_ns) {
                    let path = format!("{}/stiffness/truth", paths::joint(&j.name));
                    self.scalar(rec, path, t.stiffness_nm_per_rad)?;
                }
                if self.robot.is_some() {
                    let slot = self
                        .truths
                        .entry(t.t_acq_ns)
                        .or_insert_with(|| vec![None; n]);
                    slot[t.joint as usize] = Some((t.torque_nm, t.link_rad));
                    if slot.iter().all(Option::is_some) {
                        self.true_force(rec, t.t_acq_ns)?;
                    }
                    while self.truths.len() > 64 {
                        self.truths.pop_first();
                    }
                }
            }
            AnyMessage::JointEstimate(e) => {
                let Some(j) = self.joints.get_mut(e.joint as usize) else {
                    return Ok(());
                };
                rec.set_timestamp_nanos_since_epoch(TIMELINE, e.t_acq_ns as i64);
                if let Some(&(_, defl)) = j.recent.iter().rev().find(|(seq, _)| *seq == e.seq) {
                    j.model.push(e.t_acq_ns, defl.to_degrees(), -e.torque_nm);
                }
                if j.estimate_series.pass(e.t_acq_ns) {
                    let p = paths::joint(&j.name);
                    let awas = j.awas;
                    if let Some(k) = e.stiffness_nm_per_rad {
                        self.scalar(rec, format!("{p}/stiffness/estimate"), k)?;
                    }
                    if let Some(r) = e.residual_nm {
                        self.scalar(rec, format!("{p}/residual"), r)?;
                    }
                    if let Some((inertia, damping)) = awas {
                        for (q, v, var, truth) in [
                            ("inertia", e.inertia_kg_m2, e.inertia_var, inertia),
                            ("damping", e.damping_nms_per_rad, e.damping_var, damping),
                        ] {
                            self.scalar(rec, format!("{p}/{q}/config"), truth)?;
                            let Some(v) = v else { continue };
                            self.scalar(rec, format!("{p}/{q}/estimate"), v)?;
                            if let Some(sd) = var.filter(|v| *v >= 0.0).map(f64::sqrt) {
                                self.scalar(rec, format!("{p}/{q}/plus_2sigma"), v + 2.0 * sd)?;
                                self.scalar(rec, format!("{p}/{q}/minus_2sigma"), v - 2.0 * sd)?;
                            }
                        }
                    }
                }
            }
            AnyMessage::EeEstimate(e) => {
                rec.set_timestamp_nanos_since_epoch(TIMELINE, e.t_ns as i64);
                if self.ee_series.pass(e.t_ns) {
                    if let Some((fx, fy)) = e.force_n {
                        self.scalar(rec, paths::force("estimate", "x"), fx)?;
                        self.scalar(rec, paths::force("estimate", "y"), fy)?;
                    }
                    if let Some(k) = e.stiffness_n_per_m {
                        for (c, v) in [("xx", k.xx), ("xy", k.xy), ("yy", k.yy)] {
                            self.scalar(rec, paths::stiffness("estimated", c), v)?;
                        }
                    }
                }
                if self.ee_robot.pass(e.t_ns) {
                    self.draw_robot(rec, e.x_m, e.y_m, e.force_n)?;
                    if let Some(k) = e.stiffness_n_per_m {
                        self.stats.logged += 1;
                        rec.log(
                            paths::ellipse("estimated"),
                            &LineStrips2D::new([ellipse(&k)]).with_colors([rgb(ESTIMATE)]),
                        )?;
                    }
                }
            }
            AnyMessage::AllocationResult(r) => {
                if r.feasible {
                    for (c, w, a) in [
                        ("xx", r.target.xx, r.achieved.xx),
                        ("xy", r.target.xy, r.achieved.xy),
                        ("yy", r.target.yy, r.achieved.yy),
                    ] {
                        self.scalar(rec, paths::stiffness("wanted", c), w)?;
                        self.scalar(rec, paths::stiffness("achieved", c), a)?;
                    }
                    self.stats.logged += 2;
                    rec.log(
                        paths::ellipse("wanted"),
                        &LineStrips2D::new([ellipse(&r.target)]).with_colors([rgb(WANTED)]),
                    )?;
                    rec.log(
                        paths::ellipse("achieved"),
                        &LineStrips2D::new([ellipse(&r.achieved)]).with_colors([rgb(TRUTH)]),
                    )?;
                } else {
                    self.stats.logged += 1;
                    rec.log(
                        paths::STATUS,
                        &TextLog::new(format!("allocation {} refused: {}", r.id, r.error))
                            .with_level(rerun::TextLogLevel::WARN),
                    )?;
                }
            }
            AnyMessage::JointStatus(s) => {
                rec.set_timestamp_nanos_since_epoch(TIMELINE, s.t_ns as i64);
                let level = match s.state {
                    JointState::Ok | JointState::Stopped => rerun::TextLogLevel::INFO,
                    JointState::Rejected | JointState::SafeHold | JointState::Stale => {
                        rerun::TextLogLevel::WARN
                    }
                    JointState::Fault => rerun::TextLogLevel::ERROR,
                };
                let who = match topic {
                    Topic::EstimatorStatus { .. } => "estimator".to_string(),
                    Topic::JointStatus { joint, .. } => format!("joint {joint}"),
                    _ => "rig".to_string(),
                };
                self.stats.logged += 1;
                rec.log(
                    paths::STATUS,
                    &TextLog::new(format!("{who}: {}", s.text)).with_level(level),
                )?;
                // The estimator's residual monitor gets a view of its own.
                if let (Topic::EstimatorStatus { .. }, Some(text)) =
                    (&topic, s.text.strip_prefix("diagnosis: "))
                {
                    let name = self
                        .joints
                        .get(s.joint as usize)
                        .map_or_else(|| format!("joint {}", s.joint), |j| j.name.clone());
                    let level = if text.starts_with("residual structure —") {
                        rerun::TextLogLevel::WARN
                    } else {
                        rerun::TextLogLevel::INFO
                    };
                    self.stats.logged += 1;
                    rec.log(
                        paths::DIAGNOSIS,
                        &TextLog::new(format!("{name}: {text}")).with_level(level),
                    )?;
                }
            }
            AnyMessage::JointCommand(_) | AnyMessage::AllocationRequest(_) => {}
        }
        Ok(())
    }

    fn redraw_loop(
        &mut self,
        rec: &RecordingStream,
        j: usize,
        t_ns: u64,
    ) -> RecordingStreamResult<()> {
        let Some(view) = self.joints.get_mut(j) else {
            return Ok(());
        };
        if !view.redraw.pass(t_ns) {
            return Ok(());
        }
        let p = paths::joint_loop(&view.name);
        // Both curves minus the measured curve's best line (the model's where nothing is
        // measured): the loop is a few per cent of the torque, invisible on the raw line.
        // Then both into ±1 by the measured curve's box: Rerun's 2D view has equal axes, and a
        // loop of a few mN·m against degrees of deflection is flat at any zoom.
        let (measured, model) = trail::loop_view(&view.measured.points(), &view.model.points());
        if !measured.is_empty() {
            rec.log(
                format!("{p}/measured"),
                &LineStrips2D::new([measured])
                    .with_colors([rgb(TRUTH)])
                    .with_radii([rerun::Radius::new_ui_points(2.5)]),
            )?;
        }
        if !model.is_empty() {
            rec.log(
                format!("{p}/model"),
                &LineStrips2D::new([model])
                    .with_colors([rgb(ESTIMATE)])
                    .with_radii([rerun::Radius::new_ui_points(1.0)]),
            )?;
        }
        self.stats.logged += 2;
        Ok(())
    }

    fn draw_robot(
        &mut self,
        rec: &RecordingStream,
        x: f64,
        y: f64,
        force: Option<(f64, f64)>,
    ) -> RecordingStreamResult<()> {
        let Some(robot) = &self.robot else {
            return Ok(());
        };
        let Ok(c) = robot.at_position(x, y) else {
            return Ok(());
        };
        let chains: Vec<Vec<[f32; 2]>> = robot.chains(&c).iter().map(|ch| strip(ch)).collect();
        let joints: Vec<[f32; 2]> = chains
            .iter()
            .flat_map(|ch| ch[1..ch.len() - 1].iter().copied())
            .collect();
        let ee = [(x * 1e3) as f32, -(y * 1e3) as f32];
        rec.log(
            paths::ROBOT_LINKS,
            &LineStrips2D::new(chains)
                .with_colors([rgb(LINK)])
                .with_radii([1.5]),
        )?;
        rec.log(
            paths::ROBOT_JOINTS,
            &Points2D::new(joints)
                .with_radii([3.0])
                .with_colors([rgb(LINK)]),
        )?;
        rec.log(
            paths::ROBOT_END_EFFECTOR,
            &Points2D::new([ee])
                .with_radii([4.0])
                .with_colors([rgb(ESTIMATE)]),
        )?;
        self.stats.logged += 3;
        if let Some((fx, fy)) = force {
            self.stats.logged += 1;
            rec.log(
                paths::robot_force("estimate"),
                &Arrows2D::from_vectors([[fx as f32 * MM_PER_N, -fy as f32 * MM_PER_N]])
                    .with_origins([ee])
                    .with_colors([rgb(ESTIMATE)]),
            )?;
        }
        Ok(())
    }

    /// The true end-effector force at the true configuration, from every joint's true torque.
    fn true_force(&mut self, rec: &RecordingStream, t_ns: u64) -> RecordingStreamResult<()> {
        let Some(slot) = self.truths.remove(&t_ns) else {
            return Ok(());
        };
        let Some(robot) = &self.robot else {
            return Ok(());
        };
        let truth: Vec<(f64, f64)> = slot.into_iter().flatten().collect();
        let (series, draw) = (self.truth_series.pass(t_ns), self.truth_robot.pass(t_ns));
        if !(series || draw) || truth.len() < 2 {
            return Ok(());
        }
        let Ok(c) = robot.from_independent(truth[0].1, truth[1].1) else {
            return Ok(());
        };
        let torques: Vec<f64> = truth.iter().map(|t| t.0).collect();
        let Ok(f) = end_effector_force(&c.g_u_a, &torques) else {
            return Ok(());
        };
        if series {
            self.scalar(rec, paths::force("truth", "x"), f[0])?;
            self.scalar(rec, paths::force("truth", "y"), f[1])?;
        }
        if draw {
            self.stats.logged += 1;
            let at = [(c.pose.x * 1e3) as f32, -(c.pose.y * 1e3) as f32];
            rec.log(
                paths::robot_force("truth"),
                &Arrows2D::from_vectors([[f[0] as f32 * MM_PER_N, -f[1] as f32 * MM_PER_N]])
                    .with_origins([at])
                    .with_colors([rgb(TRUTH)]),
            )?;
        }
        Ok(())
    }
}

/// The layout: the robot and its force on the left; per joint the loops and the time series
/// in the middle; allocations and statuses on the right.
pub fn blueprint(cfg: &RigConfig) -> Blueprint {
    let loops: Vec<ContainerLike> = cfg
        .joints
        .iter()
        .map(|j| {
            Spatial2DView::new(format!(
                "{} loop: torque minus its best line vs deflection, last 2 s, each scaled to ±1",
                j.name
            ))
            .with_origin(paths::origin(&paths::joint_loop(&j.name)))
            .into()
        })
        .collect();
    let series: Vec<ContainerLike> = cfg
        .joints
        .iter()
        .map(|j| {
            TimeSeriesView::new(format!("{}: pivot, stiffness, residual", j.name))
                .with_origin(paths::origin(&paths::joint(&j.name)))
                .with_contents([
                    "$origin/pivot_mm",
                    "$origin/stiffness/**",
                    "$origin/residual",
                ])
                .into()
        })
        .chain(
            cfg.joints
                .iter()
                .filter(|j| matches!(j.kind, JointKind::Awas { .. }))
                .map(|j| {
                    TimeSeriesView::new(format!("{}: inertia, damping (±2σ)", j.name))
                        .with_origin(paths::origin(&paths::joint(&j.name)))
                        .with_contents(["$origin/inertia/**", "$origin/damping/**"])
                        .into()
                }),
        )
        .collect();
    let left = Vertical::new([
        Spatial2DView::new("robot [mm], force arrows 5 mm/N")
            .with_origin(paths::origin(paths::ROBOT))
            .into(),
        TimeSeriesView::new("end-effector force [N]")
            .with_origin(paths::origin(paths::FORCE))
            .into(),
    ]);
    let middle = Vertical::new([Grid::new(loops).into(), Tabs::new(series).into()]);
    let right = Vertical::new([
        Spatial2DView::new("stiffness ellipse K·u [N/mm]")
            .with_origin(paths::origin(paths::ELLIPSE))
            .into(),
        TimeSeriesView::new("operational stiffness [N/m]")
            .with_origin(paths::origin(paths::STIFFNESS))
            .into(),
        TextLogView::new("status")
            .with_origin(paths::origin(paths::STATUS))
            .into(),
        TextLogView::new("residual diagnosis")
            .with_origin(paths::origin(paths::DIAGNOSIS))
            .into(),
    ]);
    let root: ContainerLike = if cfg.topology.is_robot() {
        Horizontal::new([left.into(), middle.into(), right.into()]).into()
    } else {
        Horizontal::new([
            middle.into(),
            Vertical::new([
                TextLogView::new("status")
                    .with_origin(paths::origin(paths::STATUS))
                    .into(),
                TextLogView::new("residual diagnosis")
                    .with_origin(paths::origin(paths::DIAGNOSIS))
                    .into(),
            ])
            .into(),
        ])
        .into()
    };
    Blueprint::new(root)
}
