//! The allocator host's Zenoh edge: a queryable on `rig/<rig>/allocate`, a subscriber for
//! continuous goals on `rig/<rig>/stiffness/goal` and for `rig/<rig>/estimate/ee`; pivot
//! commands out on `rig/<rig>/joint/<j>/command`, re-sent at 10 Hz as the joints' heartbeat.

use std::time::Duration;

use rig_config::RigConfig;
use rig_protocol::{
    AllocationRequest, EeEstimate, JointCommand, JointEstimate, Keys, decode, encode,
};
use rig_runtime::{NetOverrides, now_ns, open, zenoh_err as z};

use crate::core::{AllocatorCore, GoalAge, goal_age, refusal};

/// The allocator host fails only at its Zenoh edge.
pub type AllocatorError = rig_runtime::RuntimeError;

#[derive(Debug, Clone)]
pub struct AllocatorOptions {
    pub cfg: RigConfig,
    pub net: NetOverrides,
    pub duration: Option<Duration>,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AllocatorReport {
    pub requests: u64,
    pub goals: u64,
    pub commands: u64,
    /// Commands sent while no subscriber of the joint's command key was known to this
    /// host: its agent was down, or not linked to this machine (they went nowhere).
    pub unmatched: u64,
    pub malformed: u64,
    /// Goals refused because their stamp was further from this host's clock than the
    /// config's clock bound (held up on the way, replayed, or a publisher whose clock is off).
    pub stale_goals: u64,
    /// Goals from a publisher that does not stamp (obeyed: nothing to check).
    pub unstamped_goals: u64,
}

/// Runs the host until `shutdown` resolves or the duration ends.
pub async fn run(
    opts: AllocatorOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<AllocatorReport, AllocatorError> {
    let cfg = &opts.cfg;
    let keys = Keys::new(&cfg.name)?;
    let mut core = AllocatorCore::new(cfg.clone());
    let session = open(cfg, &opts.net, &rig_config::Identity::Allocator).await?;
    let queries = session
        .declare_queryable(keys.allocate())
        .await
        .map_err(z)?;
    let goals = session
        .declare_subscriber(keys.stiffness_goal())
        .await
        .map_err(z)?;
    let ees = session
        .declare_subscriber(keys.ee_estimate())
        .await
        .map_err(z)?;
    // The joints' stiffness in use, to allocate for it (AllocatorCore::on_joint_estimate).
    let joint_estimates = session
        .declare_subscriber(keys.all_joint_estimates())
        .await
        .map_err(z)?;
    let mut cmd_pubs = Vec::new();
    for j in &cfg.joints {
        cmd_pubs.push(
            session
                .declare_publisher(keys.joint_command(&j.name)?)
                .await
                .map_err(z)?,
        );
    }
    let result_pub = rig_runtime::publisher(&session, keys.allocation_result()).await?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive("allocator", "0")?)
        .await
        .map_err(z)?;
    let mut report = AllocatorReport::default();
    let clock_bound_ns = (cfg.clock.max_offset_s * 1e9).round() as u64;
    // Goals refused for their age: said at the 1st, 10th, 100th…
    let mut stale = rig_runtime::LogBudget::default();
    // Infeasible goals are answered in the result; the log says the 1st, 10th, 100th…
    let mut infeasible = rig_runtime::LogBudget::default();
    // Per joint: commands sent to nobody, said at the 1st, 10th, 100th…
    let mut unmatched = vec![rig_runtime::LogBudget::default(); cfg.joints.len()];
    let mut heartbeat = tokio::time::interval(Duration::from_millis(100));
    heartbeat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    tokio::pin!(shutdown);
    loop {
        let cmds: Vec<JointCommand> = tokio::select! {
            _ = &mut shutdown => break,
            _ = heartbeat.tick() => {
                if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
                    break;
                }
                core.heartbeat(now_ns())
            }
            q = queries.recv_async() => {
                let Ok(q) = q else { break };
                let bytes = q.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
                match decode::<AllocationRequest>(&bytes) {
                    Ok(req) => {
                        report.requests += 1;
                        let (result, cmds) = core.on_request(&req, now_ns());
                        if let Ok(bytes) = encode(&result) {
                            q.reply(keys.allocate(), bytes.clone()).await.map_err(z)?;
                            result_pub.put(bytes).await.map_err(z)?;
                        }
                        cmds
                    }
                    Err(e) => {
                        report.malformed += 1;
                        q.reply_err(format!("malformed allocation request: {e}")).await.map_err(z)?;
                        Vec::new()
                    }
                }
            }
            g = goals.recv_async() => {
                let Ok(g) = g else { break };
                let stamp_ns = rig_runtime::published_ns(&g);
                match decode::<AllocationRequest>(&g.payload().to_bytes()) {
                    Ok(req) => {
                        report.goals += 1;
                        let late = match goal_age(stamp_ns, now_ns(), clock_bound_ns) {
                            GoalAge::Fresh => None,
                            GoalAge::Unstamped => {
                                report.unstamped_goals += 1;
                                if report.unstamped_goals == 1 {
                                    eprintln!(
                                        "rig allocator: goal {} carries no Zenoh timestamp (its publisher runs with timestamping off), so its age cannot be checked; obeyed",
                                        req.id
                                    );
                                }
                                None
                            }
                            GoalAge::Stale { age_ns } => Some(format!(
                                "goal stamped {:.3} s ago",
                                age_ns as f64 * 1e-9
                            )),
                            GoalAge::Ahead { ahead_ns } => Some(format!(
                                "goal stamped {:.3} s ahead of this host's clock",
                                ahead_ns as f64 * 1e-9
                            )),
                        };
                        if let Some(late) = late {
                            report.stale_goals += 1;
                            let why = format!(
                                "{late}, beyond the clock bound of {:.3} s ([clock] max_offset_ms): refused (held up on the way, replayed, or a publisher whose clock is off)",
                                cfg.clock.max_offset_s
                            );
                            if let Some(n) = stale.count() {
                                eprintln!(
                                    "rig allocator: goal {} not applied: {why} ({n} refused so far)",
                                    req.id
                                );
                            }
                            if let Ok(bytes) = encode(&refusal(req.id, &why)) {
                                result_pub.put(bytes).await.map_err(z)?;
                            }
                            continue;
                        }
                        let (result, cmds) = core.on_goal(&req, now_ns());
                        if !result.feasible
                            && let Some(n) = infeasible.count()
                        {
                            eprintln!(
                                "rig allocator: goal {} not applied: {} ({n} goals not applied so far)",
                                req.id, result.error
                            );
                        }
                        if let Ok(bytes) = encode(&result) {
                            result_pub.put(bytes).await.map_err(z)?;
                        }
                        cmds
                    }
                    Err(e) => {
                        report.malformed += 1;
                        if rig_runtime::worth_a_line(report.malformed) {
                            eprintln!(
                                "rig allocator: dropped a malformed goal: {e} ({} malformed so far)",
                                report.malformed
                            );
                        }
                        Vec::new()
                    }
                }
            }
            e = joint_estimates.recv_async() => {
                let Ok(e) = e else { break };
                match decode::<JointEstimate>(&e.payload().to_bytes()) {
                    Ok(je) => core.on_joint_estimate(&je),
                    Err(_) => report.malformed += 1,
                }
                Vec::new()
            }
            e = ees.recv_async() => {
                let Ok(e) = e else { break };
                match decode::<EeEstimate>(&e.payload().to_bytes()) {
                    Ok(ee) => match core.on_ee(&ee, now_ns()) {
                        Some((result, cmds)) => {
                            if let Ok(bytes) = encode(&result) {
                                result_pub.put(bytes).await.map_err(z)?;
                            }
                            cmds
                        }
                        None => Vec::new(),
                    },
                    Err(_) => {
                        report.malformed += 1;
                        Vec::new()
                    }
                }
            }
        };
        for c in cmds {
            let j = c.joint as usize;
            if let (Some(p), Ok(bytes)) = (cmd_pubs.get(j), encode(&c)) {
                // Zenoh knows whether any subscriber matches: a command with none goes
                // nowhere, and a lab must hear so rather than see a pivot that never moves.
                let matched = p.matching_status().await.is_ok_and(|m| m.matching());
                p.put(bytes).await.map_err(z)?;
                report.commands += 1;
                if !matched {
                    report.unmatched += 1;
                    if let (Some(n), Some(joint)) = (
                        unmatched.get_mut(j).and_then(|b| b.count()),
                        cfg.joints.get(j),
                    ) {
                        eprintln!(
                            "rig allocator: no subscriber for {}'s commands ({}): its agent is down or not linked to this machine, so the command went nowhere ({n} so far). Peers forward only to peers they are linked to: give the joint's machine a --connect to this one, or run a router (README, \"The rig over Zenoh\")",
                            joint.name,
                            p.key_expr()
                        );
                    }
                }
            }
        }
    }
    session.close().await.map_err(z)?;
    Ok(report)
}
