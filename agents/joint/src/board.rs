//! What the agent needs of a joint board, whatever it is made of: the [`JointBoard`] trait,
//! and [`BoardRunner`], which runs a board inline (a simulation never blocks) or on a thread
//! of its own that owns it (serial I/O blocks: it never runs on the async workers).
//!
//! Two boards implement the trait: [`crate::sim_board::SimBoard`] (feature `sim`, the
//! default) and [`crate::hardware::DynamixelBoard`] (paper B's servos and encoder bridge).
//! The agent knows neither: it reads, applies the commands its guard accepted, reports what
//! the board did on the watchdog, and asks for the safe state on every way out.
//!
//! Call contract: `read` once per tick with the rig time `t` [s] and the time `dt` [s] since
//! the previous read; `set_actuator_goal` and `apply` only with what the guard accepted;
//! `on_watchdog` when the guard's watchdog fires; `safe_state` last (and on any fault).
//! Joints are the board's own indices `k`, in the order the board was given them.

use rig_config::RigConfig;
use thiserror::Error;

/// What the simulator knows and a real joint cannot: the true deflection [rad], torque
/// [N·m], link angle [rad] and stiffness [N·m/rad].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    pub deflection_rad: f64,
    pub torque_nm: f64,
    pub link_rad: f64,
    pub stiffness_nm_per_rad: f64,
}

/// One reading of a joint, and (simulated boards only) the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    pub motor_rad: f64,
    pub deflection_rad: f64,
    pub pivot_m: Option<f64>,
    pub torque_nm: Option<f64>,
    /// The joint motor's torque [N·m], where the servo reports its current.
    pub motor_torque_nm: Option<f64>,
    pub stiffness_motor_rad: Option<f64>,
    /// Where the stiffness actuator is, in the guard's unit (pivot [m], stiffness motor
    /// [rad]): what the guard checks the next commands against.
    pub actuator: f64,
    pub truth: Option<Truth>,
}

/// What a board did with a command's motor goal and torque switch.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Applied {
    Done,
    /// The hardware cannot do it; the text says why (the joint goes on as before).
    Refused(String),
}

/// What a board did when the watchdog fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WatchdogAction {
    /// The stiffness actuator is held where it is (a simulation).
    Held,
    /// The joint's servos went limp (hardware).
    TorqueOff,
}

/// What the safe state came to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SafeState {
    /// Nothing holds torque (a simulation).
    NothingToSwitch,
    /// Torque is off on every servo.
    TorqueOff,
    /// Torque-off failed on some servos; each failure names its servo and bus.
    TorqueOffFailed(Vec<String>),
}

/// Errors of a board. Bad commands are not errors (the guard refuses them); these end the
/// agent, after the safe state.
#[derive(Debug, Error)]
pub enum BoardError {
    #[error("joint {name:?} is not in the config (joints: {known})")]
    UnknownJoint { name: String, known: String },
    #[error("the simulated world: {0}")]
    Sim(#[source] Box<dyn std::error::Error + Send + Sync>),
    #[error(
        "this build has no simulator: rebuild rig-joint with the `sim` feature (on by default)"
    )]
    NoSimulator,
    /// The board's devices failed, or the config cannot drive them; the source is the
    /// device's own error (`hardware::PlanError`, `hardware::HardwareError`).
    #[error("{0}")]
    Device(#[source] Box<dyn std::error::Error + Send + Sync>),
    #[error("virtual board: {0}")]
    VirtualBoard(#[source] std::io::Error),
    #[error("the board's I/O thread stopped")]
    ThreadGone,
}

/// A joint board: one or more joints read together.
pub trait JointBoard: Send {
    /// The board's name, for statuses (`sim`, `dynamixel`).
    fn name(&self) -> &'static str;
    /// Whether ticks missed by a late wake-up can still be read (a simulation can evaluate
    /// the past; hardware reads only now).
    fn reads_the_past(&self) -> bool;
    /// Every joint's reading at rig time `t` [s], `dt` [s] after the previous reading.
    fn read(&mut self, t: f64, dt: f64) -> Result<Vec<Reading>, BoardError>;
    /// Before the first tick: `Some` when the board's read cycle cannot keep `rate_hz`
    /// (hardware times a few cycles; a simulation always can).
    fn pace(
        &mut self,
        _rate_hz: f64,
    ) -> Result<Option<crate::hardware::pace::TooFast>, BoardError> {
        Ok(None)
    }
    /// Joint `k`'s stiffness actuator position now (pivot [m], stiffness motor [rad]).
    fn actuator(&self, k: usize) -> f64;
    /// Joint `k`'s stiffness actuator goal (the guard has checked it).
    fn set_actuator_goal(&mut self, k: usize, goal: f64);
    /// Applies an accepted command's motor goal [rad] and torque switch to joint `k`.
    fn apply(
        &mut self,
        k: usize,
        motor_goal_rad: Option<f64>,
        torque_enable: bool,
    ) -> Result<Applied, BoardError>;
    /// The watchdog fired on joint `k` (`hold_at`: the guard's goal); what the board did.
    fn on_watchdog(&mut self, k: usize, hold_at: f64) -> Result<WatchdogAction, BoardError>;
    /// Torque off everywhere, each servo tried even when another fails.
    fn safe_state(&mut self) -> SafeState;
}

/// The joint's index in the config.
pub fn joint_index(cfg: &RigConfig, name: &str) -> Result<usize, BoardError> {
    cfg.joints
        .iter()
        .position(|j| j.name == name)
        .ok_or_else(|| unknown_joint(cfg, name))
}

/// `name` is no joint of `cfg`: the error lists the joints there are.
pub fn unknown_joint(cfg: &RigConfig, name: &str) -> BoardError {
    BoardError::UnknownJoint {
        name: name.to_string(),
        known: cfg
            .joints
            .iter()
            .map(|j| j.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
    }
}

type Job = Box<dyn FnOnce(&mut dyn JointBoard) + Send>;

/// Runs a board: inline, or on a thread that owns it.
pub struct BoardRunner {
    how: How,
    name: &'static str,
    reads_the_past: bool,
}

enum How {
    Inline(Box<dyn JointBoard>),
    Thread {
        jobs: std::sync::mpsc::Sender<Job>,
        thread: Option<std::thread::JoinHandle<()>>,
    },
}

impl std::fmt::Debug for BoardRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BoardRunner")
            .field("board", &self.name)
            .field("thread", &matches!(self.how, How::Thread { .. }))
            .finish()
    }
}

impl BoardRunner {
    /// A board whose calls return at once (a simulation): called on the caller's task.
    pub fn inline(board: Box<dyn JointBoard>) -> Self {
        Self {
            name: board.name(),
            reads_the_past: board.reads_the_past(),
            how: How::Inline(board),
        }
    }

    /// A board whose calls block on I/O: `open` runs on a new thread, which then owns the
    /// board (its ports are opened, read and closed there) and runs every call in turn. The
    /// board is dropped, and its `Drop` leaves the servos limp, when the runner is.
    pub async fn on_thread(
        open: impl FnOnce() -> Result<Box<dyn JointBoard>, BoardError> + Send + 'static,
    ) -> Result<Self, BoardError> {
        let (jobs, rx) = std::sync::mpsc::channel::<Job>();
        let (opened, opened_rx) = tokio::sync::oneshot::channel();
        let thread = std::thread::Builder::new()
            .name("joint-board".into())
            .spawn(move || {
                let mut board = match open() {
                    Ok(b) => {
                        let _ = opened.send(Ok((b.name(), b.reads_the_past())));
                        b
                    }
                    Err(e) => {
                        let _ = opened.send(Err(e));
                        return;
                    }
                };
                while let Ok(job) = rx.recv() {
                    job(board.as_mut());
                }
            })
            .map_err(|_| BoardError::ThreadGone)?;
        let (name, reads_the_past) = opened_rx.await.map_err(|_| BoardError::ThreadGone)??;
        Ok(Self {
            how: How::Thread {
                jobs,
                thread: Some(thread),
            },
            name,
            reads_the_past,
        })
    }

    /// The board's name.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Whether the board can read missed ticks ([`JointBoard::reads_the_past`]).
    pub fn reads_the_past(&self) -> bool {
        self.reads_the_past
    }

    /// Runs `f` on the board: inline, or on its thread while this task waits without
    /// blocking the runtime.
    pub async fn call<T: Send + 'static>(
        &mut self,
        f: impl FnOnce(&mut dyn JointBoard) -> T + Send + 'static,
    ) -> Result<T, BoardError> {
        match &mut self.how {
            How::Inline(b) => Ok(f(b.as_mut())),
            How::Thread { jobs, .. } => {
                let (tx, rx) = tokio::sync::oneshot::channel();
                jobs.send(Box::new(move |b: &mut dyn JointBoard| {
                    let _ = tx.send(f(b));
                }))
                .map_err(|_| BoardError::ThreadGone)?;
                rx.await.map_err(|_| BoardError::ThreadGone)
            }
        }
    }
}

impl Drop for BoardRunner {
    /// The board's thread ends when its queue closes; waiting for it means the board (and
    /// its ports) is gone when the runner is.
    fn drop(&mut self) {
        if let How::Thread { jobs, thread } = &mut self.how {
            let (closed, _) = std::sync::mpsc::channel();
            *jobs = closed;
            if let Some(t) = thread.take() {
                let _ = t.join();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    /// A board that counts its reads.
    struct Counting {
        reads: usize,
    }

    impl JointBoard for Counting {
        fn name(&self) -> &'static str {
            "counting"
        }
        fn reads_the_past(&self) -> bool {
            false
        }
        fn read(&mut self, t: f64, _dt: f64) -> Result<Vec<Reading>, BoardError> {
            self.reads += 1;
            Ok(vec![Reading {
                motor_rad: t,
                deflection_rad: 0.0,
                pivot_m: None,
                torque_nm: None,
                motor_torque_nm: None,
                stiffness_motor_rad: None,
                actuator: self.reads as f64,
                truth: None,
            }])
        }
        fn actuator(&self, _k: usize) -> f64 {
            self.reads as f64
        }
        fn set_actuator_goal(&mut self, _k: usize, _goal: f64) {}
        fn apply(&mut self, _: usize, _: Option<f64>, _: bool) -> Result<Applied, BoardError> {
            Ok(Applied::Done)
        }
        fn on_watchdog(&mut self, _: usize, _: f64) -> Result<WatchdogAction, BoardError> {
            Ok(WatchdogAction::Held)
        }
        fn safe_state(&mut self) -> SafeState {
            SafeState::NothingToSwitch
        }
    }

    fn counting() -> Box<dyn JointBoard> {
        Box::new(Counting { reads: 0 })
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_threaded_board_runs_every_call_in_order_on_its_own_thread() {
        let mut r = BoardRunner::on_thread(|| Ok(counting())).await.unwrap();
        assert_eq!((r.name(), r.reads_the_past()), ("counting", false));
        for i in 1..=5 {
            let x = r.call(|b| b.read(0.1, 1e-3)).await.unwrap().unwrap();
            assert_eq!(x[0].actuator, i as f64);
        }
        let here = std::thread::current().id();
        let seen = r
            .call(|b| {
                b.read(0.0, 0.0).unwrap();
                std::thread::current().id()
            })
            .await
            .unwrap();
        assert_ne!(seen, here);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_board_that_fails_to_open_says_why_and_an_inline_board_runs_on_the_caller() {
        let e = BoardRunner::on_thread(|| Err(BoardError::NoSimulator))
            .await
            .unwrap_err();
        assert!(matches!(e, BoardError::NoSimulator), "{e}");
        let mut r = BoardRunner::inline(counting());
        let seen = r.call(|_| std::thread::current().id()).await.unwrap();
        assert_eq!(seen, std::thread::current().id());
    }
}
