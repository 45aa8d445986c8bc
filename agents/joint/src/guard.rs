//! Safety at the joint, sans I/O: every command is checked against this joint's own limits,
//! whoever sent it, and the joint holds its last safe position when commands stop.
//!
//! - **Range**: a motor goal outside `[motor_min, motor_max]` or a stiffness-actuator goal
//!   (pivot position of a lever VSA, stiffness-motor angle of AWAS) outside its travel is
//!   rejected, naming the limit.
//! - **Rate of change**: the actuator moves towards an accepted goal at most at the
//!   configured rate (the servo's profile). A new goal that changes the current one faster
//!   than that rate, while the actuator is still on its way, is rejected: a sender can retarget
//!   once the last goal is reached, or slowly, not flip goals faster than the joint can follow.
//! - **Freshness**: a command stamped further than the rig's clock bound (`[clock]
//!   max_offset_ms`, 100 ms by default) from the joint's clock is rejected — a command
//!   captured and sent again later, held up in a queue, or from a machine whose clock is off;
//!   within the bound, a command identical in `seq` and stamp to one already accepted is a
//!   replay and is rejected too.
//! - **Watchdog**: when no valid command arrives for `watchdog_s`, the goal becomes the
//!   actuator's present position (it stops where it is) and the state becomes safe-hold until
//!   the next valid command.

use rig_protocol::{JointCommand, JointState};

/// What the guard needs of the joint's limits, in SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardLimits {
    pub motor_min_rad: f64,
    pub motor_max_rad: f64,
    /// Stiffness actuator travel [m] (pivot) or [rad] (AWAS stiffness motor).
    pub actuator_min: f64,
    pub actuator_max: f64,
    /// Fastest actuator motion [m/s] or [rad/s].
    pub actuator_rate: f64,
    pub watchdog_s: f64,
    /// How far a command's stamp may be from the joint's clock [s] (`[clock] max_offset_ms`).
    pub max_clock_offset_s: f64,
    /// Name and unit of the actuator for messages, e.g. ("pivot", "mm", 1e3).
    pub actuator_name: &'static str,
    pub actuator_unit: &'static str,
    pub actuator_scale: f64,
}

/// The guard's answer to a command.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Goals to apply (None: unchanged).
    Accepted {
        motor_goal: Option<f64>,
        actuator_goal: Option<f64>,
        torque_enable: bool,
    },
    /// Refused; the text names the limit.
    Rejected(String),
}

/// The guard of one joint.
#[derive(Debug, Clone)]
pub struct JointGuard {
    joint: u16,
    limits: GuardLimits,
    goal: f64,
    last_valid_ns: Option<u64>,
    last_goal_ns: Option<u64>,
    state: JointState,
    /// (seq, stamp) of the commands accepted within the clock bound, oldest first.
    recent: std::collections::VecDeque<(u64, u64)>,
}

/// The most accepted commands remembered for replay detection (a sender at 1 kHz fills the
/// 100 ms bound with 100).
const RECENT: usize = 512;

impl JointGuard {
    /// A guard for joint `joint`, its actuator at `actuator_now`.
    pub fn new(joint: u16, limits: GuardLimits, actuator_now: f64) -> Self {
        Self {
            joint,
            limits,
            goal: actuator_now,
            last_valid_ns: None,
            last_goal_ns: None,
            state: JointState::Ok,
            recent: std::collections::VecDeque::new(),
        }
    }

    /// The current actuator goal.
    pub fn goal(&self) -> f64 {
        self.goal
    }

    /// The guard's state (Ok, SafeHold).
    pub fn state(&self) -> JointState {
        self.state
    }

    fn fmt(&self, v: f64) -> String {
        format!(
            "{:.3} {}",
            v * self.limits.actuator_scale,
            self.limits.actuator_unit
        )
    }

    /// Checks a command received at `now_ns` with the actuator at `actuator_now`.
    pub fn on_command(&mut self, cmd: &JointCommand, now_ns: u64, actuator_now: f64) -> Verdict {
        let l = self.limits;
        if cmd.joint != self.joint {
            return Verdict::Rejected(format!(
                "command for joint {} reached joint {}",
                cmd.joint, self.joint
            ));
        }
        let offset_s = (cmd.t_ns as f64 - now_ns as f64) * 1e-9;
        if offset_s.abs() > l.max_clock_offset_s {
            return Verdict::Rejected(format!(
                "command seq {} stamped {:+.1} ms from this joint's clock (bound ±{:.0} ms, [clock] max_offset_ms): a late or replayed command, or a clock that is off (run chrony or PTP on every machine)",
                cmd.seq,
                offset_s * 1e3,
                l.max_clock_offset_s * 1e3
            ));
        }
        if self.recent.contains(&(cmd.seq, cmd.t_ns)) {
            return Verdict::Rejected(format!(
                "command seq {} stamped {} was already accepted: a replay",
                cmd.seq, cmd.t_ns
            ));
        }
        if let Some(m) = cmd.motor_goal_rad
            && !(l.motor_min_rad..=l.motor_max_rad).contains(&m)
        {
            return Verdict::Rejected(format!(
                "motor_goal_rad {m:.4} is outside limits.motor_min_deg..motor_max_deg = [{:.4}, {:.4}] rad",
                l.motor_min_rad, l.motor_max_rad
            ));
        }
        let goal = cmd.pivot_goal_m.or(cmd.stiffness_motor_goal_rad);
        if let Some(g) = goal {
            if !(l.actuator_min..=l.actuator_max).contains(&g) {
                return Verdict::Rejected(format!(
                    "{} goal {} is outside its travel [{}, {}]",
                    l.actuator_name,
                    self.fmt(g),
                    self.fmt(l.actuator_min),
                    self.fmt(l.actuator_max)
                ));
            }
            let on_its_way =
                (actuator_now - self.goal).abs() > 1e-6 * (l.actuator_max - l.actuator_min);
            if let (true, Some(t0)) = (on_its_way, self.last_goal_ns) {
                let dt = (now_ns.saturating_sub(t0) as f64 * 1e-9).max(1e-9);
                let rate = (g - self.goal).abs() / dt;
                if rate > l.actuator_rate {
                    return Verdict::Rejected(format!(
                        "{} goal changes at {}/s, faster than the rate limit {}/s while the last goal is not reached",
                        l.actuator_name,
                        self.fmt(rate),
                        self.fmt(l.actuator_rate)
                    ));
                }
            }
            if (g - self.goal).abs() > 0.0 {
                self.last_goal_ns = Some(now_ns);
            }
            self.goal = g;
        }
        self.last_valid_ns = Some(now_ns);
        self.state = JointState::Ok;
        self.remember(cmd, now_ns);
        Verdict::Accepted {
            motor_goal: cmd.motor_goal_rad,
            actuator_goal: goal,
            torque_enable: cmd.torque_enable,
        }
    }

    /// Keeps an accepted command's (seq, stamp) while a copy of it could still pass the
    /// clock check.
    fn remember(&mut self, cmd: &JointCommand, now_ns: u64) {
        let bound_ns = self.limits.max_clock_offset_s * 1e9;
        while let Some(&(_, t)) = self.recent.front() {
            let expired = (now_ns as f64 - t as f64) > bound_ns;
            if expired || self.recent.len() >= RECENT {
                self.recent.pop_front();
            } else {
                break;
            }
        }
        self.recent.push_back((cmd.seq, cmd.t_ns));
    }

    /// Periodic check. Returns the new state when the watchdog fires (goal := present
    /// position). Before the first command there is nothing to watch.
    pub fn on_tick(&mut self, now_ns: u64, actuator_now: f64) -> Option<JointState> {
        let last = self.last_valid_ns?;
        let silent = now_ns.saturating_sub(last) as f64 * 1e-9;
        if self.state == JointState::Ok && silent > self.limits.watchdog_s {
            self.goal = actuator_now;
            self.state = JointState::SafeHold;
            return Some(self.state);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> GuardLimits {
        GuardLimits {
            motor_min_rad: -1.0,
            motor_max_rad: 1.0,
            actuator_min: 0.0,
            actuator_max: 0.018,
            actuator_rate: 0.02,
            watchdog_s: 0.5,
            // These tests stamp every command at 1 ns; the clock check has its own test.
            max_clock_offset_s: f64::INFINITY,
            actuator_name: "pivot",
            actuator_unit: "mm",
            actuator_scale: 1e3,
        }
    }

    /// A command with a fresh sequence number (a repeated one would be a replay).
    fn cmd(pivot: Option<f64>, motor: Option<f64>) -> JointCommand {
        static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        JointCommand {
            joint: 0,
            seq: SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            t_ns: 1,
            motor_goal_rad: motor,
            pivot_goal_m: pivot,
            stiffness_motor_goal_rad: None,
            torque_enable: true,
        }
    }

    const S: u64 = 1_000_000_000;

    #[test]
    fn range_violations_are_rejected_naming_the_limit() {
        let mut g = JointGuard::new(0, limits(), 0.009);
        match g.on_command(&cmd(Some(0.03), None), S, 0.009) {
            Verdict::Rejected(t) => assert!(
                t.contains("pivot goal 30.000 mm") && t.contains("[0.000 mm, 18.000 mm]"),
                "{t}"
            ),
            v => panic!("{v:?}"),
        }
        match g.on_command(&cmd(None, Some(2.0)), S, 0.009) {
            Verdict::Rejected(t) => assert!(t.contains("motor_goal_rad"), "{t}"),
            v => panic!("{v:?}"),
        }
        assert_eq!(g.goal(), 0.009, "a rejected command changes nothing");
        let mut other = cmd(Some(0.01), None);
        other.joint = 3;
        assert!(matches!(
            g.on_command(&other, S, 0.009),
            Verdict::Rejected(_)
        ));
    }

    #[test]
    fn fast_retargeting_while_moving_is_rejected_slow_is_accepted() {
        let mut g = JointGuard::new(0, limits(), 0.009);
        assert!(matches!(
            g.on_command(&cmd(Some(0.015), None), S, 0.009),
            Verdict::Accepted { .. }
        ));
        // 0.1 s later, still moving (at 0.011), a flip to 0.001: 140 mm/s > 20 mm/s.
        match g.on_command(&cmd(Some(0.001), None), S + S / 10, 0.011) {
            Verdict::Rejected(t) => assert!(t.contains("rate limit 20.000 mm/s"), "{t}"),
            v => panic!("{v:?}"),
        }
        // A small change at the rate is fine.
        assert!(matches!(
            g.on_command(&cmd(Some(0.0151), None), S + S / 5, 0.013),
            Verdict::Accepted { .. }
        ));
        // Once the goal is reached, any goal in range is accepted (the servo ramps to it).
        assert!(matches!(
            g.on_command(&cmd(Some(0.0), None), 2 * S, 0.0151),
            Verdict::Accepted { .. }
        ));
    }

    #[test]
    fn a_command_stamped_off_the_clock_bound_or_seen_before_is_rejected() {
        let mut g = JointGuard::new(
            0,
            GuardLimits {
                max_clock_offset_s: 0.1,
                ..limits()
            },
            0.009,
        );
        let at = |seq: u64, t_ns: u64| JointCommand {
            seq,
            t_ns,
            ..cmd(Some(0.009), None)
        };
        assert!(matches!(
            g.on_command(&at(1, 10 * S - S / 20), 10 * S, 0.009),
            Verdict::Accepted { .. }
        ));
        // The same command again, 50 ms later: within the bound, but seen before.
        match g.on_command(&at(1, 10 * S - S / 20), 10 * S + S / 20, 0.009) {
            Verdict::Rejected(t) => assert!(t.contains("replay"), "{t}"),
            v => panic!("{v:?}"),
        }
        // Later still it is off the bound: stamped 150 ms in the past.
        match g.on_command(&at(1, 10 * S - S / 20), 10 * S + S / 10, 0.009) {
            Verdict::Rejected(t) => {
                assert!(t.contains("-150.0 ms") && t.contains("±100 ms"), "{t}")
            }
            v => panic!("{v:?}"),
        }
        // From the future (a clock ahead) is refused as well; a fresh one passes.
        assert!(matches!(
            g.on_command(&at(2, 12 * S), 11 * S, 0.009),
            Verdict::Rejected(_)
        ));
        assert!(matches!(
            g.on_command(&at(2, 11 * S), 11 * S, 0.009),
            Verdict::Accepted { .. }
        ));
        // What is remembered stays within the bound's worth of commands.
        for k in 0..5000u64 {
            let t = 20 * S + k * S / 1000;
            assert!(matches!(
                g.on_command(&at(100 + k, t), t, 0.009),
                Verdict::Accepted { .. }
            ));
        }
        assert!(g.recent.len() <= 102, "{}", g.recent.len());
    }

    #[test]
    fn watchdog_holds_the_present_position_until_the_next_command() {
        let mut g = JointGuard::new(0, limits(), 0.009);
        assert_eq!(
            g.on_tick(10 * S, 0.009),
            None,
            "nothing to watch before the first command"
        );
        g.on_command(&cmd(Some(0.015), None), S, 0.009);
        assert_eq!(g.on_tick(S + S / 4, 0.010), None);
        assert_eq!(g.on_tick(S + 6 * S / 10, 0.011), Some(JointState::SafeHold));
        assert_eq!(g.goal(), 0.011);
        assert_eq!(g.on_tick(S + 7 * S / 10, 0.011), None, "fires once");
        g.on_command(&cmd(Some(0.012), None), 2 * S, 0.011);
        assert_eq!(g.state(), JointState::Ok);
    }
}
