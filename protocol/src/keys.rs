//! Key expressions of the rig (DESIGN.md):
//!
//! ```text
//! rig/<rig>/joint/<j>/sample        joint agent → all      acquisition-stamped sample
//! rig/<rig>/joint/<j>/command       allocator/operator → joint agent
//! rig/<rig>/joint/<j>/status        joint agent → all      limits hit, faults, watchdog
//! rig/<rig>/board/<b>/sample        board agent → all      one tick of a board of several joints
//! rig/<rig>/estimate/joint/<j>      estimator → all        τ̂, k̂, Î, N̂, residual
//! rig/<rig>/estimate/ee             estimator → all        pose, F̂, K_uu, stale joints
//! rig/<rig>/allocate                allocator queryable    request → allocation
//! rig/<rig>/stiffness/goal          operator → allocator   continuous goal
//! rig/<rig>/alive/<role>/<id>       liveliness tokens
//! rig/<rig>/estimate/status         estimator → all        joint stale / resumed (kind 3)
//! rig/<rig>/sim/joint/<j>/truth     simulated agents only  the truth no sensor reads
//! ```
//!
//! `<rig>`, `<j>`, `<role>` and `<id>` are names of 1–64 characters from `[A-Za-z0-9_-]`, so
//! they never contain a separator or a wildcard.

use thiserror::Error;

/// Errors of names and keys.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum KeyError {
    #[error("{what} name {name:?} is invalid: use 1 to 64 characters from A-Z a-z 0-9 _ -")]
    BadName { what: &'static str, name: String },
    #[error("key {0:?} is not a rig key expression")]
    Unknown(String),
}

/// Checks a name used inside a key.
pub fn check_name(what: &'static str, name: &str) -> Result<(), KeyError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok {
        Ok(())
    } else {
        Err(KeyError::BadName {
            what,
            name: name.to_string(),
        })
    }
}

/// The keys of one rig.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    /// Keys for the rig named `rig`.
    pub fn new(rig: &str) -> Result<Self, KeyError> {
        check_name("rig", rig)?;
        Ok(Self {
            prefix: format!("rig/{rig}"),
        })
    }

    /// Everything of this rig: `rig/<rig>/**`.
    pub fn all(&self) -> String {
        format!("{}/**", self.prefix)
    }

    fn joint(&self, j: &str, leaf: &str) -> Result<String, KeyError> {
        check_name("joint", j)?;
        Ok(format!("{}/joint/{j}/{leaf}", self.prefix))
    }

    pub fn joint_sample(&self, j: &str) -> Result<String, KeyError> {
        self.joint(j, "sample")
    }

    pub fn joint_command(&self, j: &str) -> Result<String, KeyError> {
        self.joint(j, "command")
    }

    pub fn joint_status(&self, j: &str) -> Result<String, KeyError> {
        self.joint(j, "status")
    }

    /// Where a board serving several joints publishes each tick's samples as one message
    /// (kind 9). `<b>` is the board's name (`rig_config::board_name`).
    pub fn board_sample(&self, b: &str) -> Result<String, KeyError> {
        check_name("board", b)?;
        Ok(format!("{}/board/{b}/sample", self.prefix))
    }

    /// Every sample, a joint's or a board's: `rig/<rig>/*/*/sample`.
    pub fn all_samples(&self) -> String {
        format!("{}/*/*/sample", self.prefix)
    }

    /// Every board's samples: `rig/<rig>/board/*/sample`.
    pub fn all_board_samples(&self) -> String {
        format!("{}/board/*/sample", self.prefix)
    }

    pub fn joint_estimate(&self, j: &str) -> Result<String, KeyError> {
        check_name("joint", j)?;
        Ok(format!("{}/estimate/joint/{j}", self.prefix))
    }

    pub fn estimator_status(&self) -> String {
        format!("{}/estimate/status", self.prefix)
    }

    pub fn sim_truth(&self, j: &str) -> Result<String, KeyError> {
        check_name("joint", j)?;
        Ok(format!("{}/sim/joint/{j}/truth", self.prefix))
    }

    /// Every joint's samples: `rig/<rig>/joint/*/sample`.
    pub fn all_joint_samples(&self) -> String {
        format!("{}/joint/*/sample", self.prefix)
    }

    /// Every joint's commands: `rig/<rig>/joint/*/command`.
    pub fn all_joint_commands(&self) -> String {
        format!("{}/joint/*/command", self.prefix)
    }

    /// Everything the estimator publishes: `rig/<rig>/estimate/**`.
    pub fn all_estimates(&self) -> String {
        format!("{}/estimate/**", self.prefix)
    }

    /// Every liveliness token of one role: `rig/<rig>/alive/<role>/**`.
    pub fn all_alive(&self, role: &str) -> Result<String, KeyError> {
        check_name("role", role)?;
        Ok(format!("{}/alive/{role}/**", self.prefix))
    }

    /// Every joint's estimate: `rig/<rig>/estimate/joint/*`.
    pub fn all_joint_estimates(&self) -> String {
        format!("{}/estimate/joint/*", self.prefix)
    }

    /// Every simulated joint's truth: `rig/<rig>/sim/joint/*/truth`.
    pub fn all_sim_truths(&self) -> String {
        format!("{}/sim/joint/*/truth", self.prefix)
    }

    /// `rig bench`'s own round-trip keys, under one run's `<id>`: `rig/<rig>/bench/<id>/<leaf>`.
    pub fn bench(&self, id: &str, leaf: &str) -> Result<String, KeyError> {
        check_name("id", id)?;
        check_name("leaf", leaf)?;
        Ok(format!("{}/bench/{id}/{leaf}", self.prefix))
    }

    pub fn ee_estimate(&self) -> String {
        format!("{}/estimate/ee", self.prefix)
    }

    pub fn allocate(&self) -> String {
        format!("{}/allocate", self.prefix)
    }

    pub fn stiffness_goal(&self) -> String {
        format!("{}/stiffness/goal", self.prefix)
    }

    /// Where the allocator publishes every allocation it computes (queries and goals).
    pub fn allocation_result(&self) -> String {
        format!("{}/allocation/result", self.prefix)
    }

    pub fn alive(&self, role: &str, id: &str) -> Result<String, KeyError> {
        check_name("role", role)?;
        check_name("id", id)?;
        Ok(format!("{}/alive/{role}/{id}", self.prefix))
    }
}

/// What a concrete key means.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Topic {
    JointSample {
        rig: String,
        joint: String,
    },
    JointCommand {
        rig: String,
        joint: String,
    },
    BoardSample {
        rig: String,
        board: String,
    },
    JointStatus {
        rig: String,
        joint: String,
    },
    JointEstimate {
        rig: String,
        joint: String,
    },
    EeEstimate {
        rig: String,
    },
    Allocate {
        rig: String,
    },
    StiffnessGoal {
        rig: String,
    },
    AllocationResult {
        rig: String,
    },
    Alive {
        rig: String,
        role: String,
        id: String,
    },
    EstimatorStatus {
        rig: String,
    },
    SimTruth {
        rig: String,
        joint: String,
    },
}

impl Topic {
    /// Parses a concrete key (no wildcards).
    pub fn parse(key: &str) -> Result<Self, KeyError> {
        let unknown = || KeyError::Unknown(key.to_string());
        let parts: Vec<&str> = key.split('/').collect();
        if parts.len() < 3 || parts[0] != "rig" {
            return Err(unknown());
        }
        let rig = parts[1];
        check_name("rig", rig)?;
        let r = rig.to_string();
        let name = |what: &'static str, s: &str| check_name(what, s).map(|_| s.to_string());
        Ok(match &parts[2..] {
            ["joint", j, "sample"] => Topic::JointSample {
                rig: r,
                joint: name("joint", j)?,
            },
            ["board", b, "sample"] => Topic::BoardSample {
                rig: r,
                board: name("board", b)?,
            },
            ["joint", j, "command"] => Topic::JointCommand {
                rig: r,
                joint: name("joint", j)?,
            },
            ["joint", j, "status"] => Topic::JointStatus {
                rig: r,
                joint: name("joint", j)?,
            },
            ["estimate", "joint", j] => Topic::JointEstimate {
                rig: r,
                joint: name("joint", j)?,
            },
            ["estimate", "ee"] => Topic::EeEstimate { rig: r },
            ["estimate", "status"] => Topic::EstimatorStatus { rig: r },
            ["sim", "joint", j, "truth"] => Topic::SimTruth {
                rig: r,
                joint: name("joint", j)?,
            },
            ["allocate"] => Topic::Allocate { rig: r },
            ["stiffness", "goal"] => Topic::StiffnessGoal { rig: r },
            ["allocation", "result"] => Topic::AllocationResult { rig: r },
            ["alive", role, id] => Topic::Alive {
                rig: r,
                role: name("role", role)?,
                id: name("id", id)?,
            },
            _ => return Err(unknown()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcards_and_bench_keys_are_built_under_the_rigs_prefix() {
        let k = Keys::new("lab-1").unwrap();
        assert_eq!(k.all_joint_samples(), "rig/lab-1/joint/*/sample");
        assert_eq!(k.all_board_samples(), "rig/lab-1/board/*/sample");
        assert_eq!(k.all_samples(), "rig/lab-1/*/*/sample");
        assert_eq!(k.all_sim_truths(), "rig/lab-1/sim/joint/*/truth");
        assert_eq!(k.bench("42", "ping").unwrap(), "rig/lab-1/bench/42/ping");
        assert!(k.bench("4/2", "ping").is_err());
    }

    #[test]
    fn builds_and_parses_every_key() {
        let k = Keys::new("lab-1").unwrap();
        let cases = [
            (
                k.joint_sample("j1").unwrap(),
                Topic::JointSample {
                    rig: "lab-1".into(),
                    joint: "j1".into(),
                },
            ),
            (
                k.board_sample("arm").unwrap(),
                Topic::BoardSample {
                    rig: "lab-1".into(),
                    board: "arm".into(),
                },
            ),
            (
                k.joint_command("j1").unwrap(),
                Topic::JointCommand {
                    rig: "lab-1".into(),
                    joint: "j1".into(),
                },
            ),
            (
                k.joint_status("j2").unwrap(),
                Topic::JointStatus {
                    rig: "lab-1".into(),
                    joint: "j2".into(),
                },
            ),
            (
                k.joint_estimate("j3").unwrap(),
                Topic::JointEstimate {
                    rig: "lab-1".into(),
                    joint: "j3".into(),
                },
            ),
            (
                k.ee_estimate(),
                Topic::EeEstimate {
                    rig: "lab-1".into(),
                },
            ),
            (
                k.allocate(),
                Topic::Allocate {
                    rig: "lab-1".into(),
                },
            ),
            (
                k.stiffness_goal(),
                Topic::StiffnessGoal {
                    rig: "lab-1".into(),
                },
            ),
            (
                k.allocation_result(),
                Topic::AllocationResult {
                    rig: "lab-1".into(),
                },
            ),
            (
                k.alive("joint", "j4").unwrap(),
                Topic::Alive {
                    rig: "lab-1".into(),
                    role: "joint".into(),
                    id: "j4".into(),
                },
            ),
        ];
        for (key, topic) in cases {
            assert_eq!(Topic::parse(&key).unwrap(), topic, "{key}");
        }
        assert_eq!(k.joint_sample("j1").unwrap(), "rig/lab-1/joint/j1/sample");
        assert_eq!(
            Topic::parse(&k.estimator_status()).unwrap(),
            Topic::EstimatorStatus {
                rig: "lab-1".into()
            }
        );
        assert_eq!(
            Topic::parse(&k.sim_truth("j2").unwrap()).unwrap(),
            Topic::SimTruth {
                rig: "lab-1".into(),
                joint: "j2".into()
            }
        );
        assert_eq!(k.all(), "rig/lab-1/**");
    }

    #[test]
    fn refuses_wildcards_separators_and_unknown_keys() {
        assert!(Keys::new("a/b").is_err());
        assert!(Keys::new("*").is_err());
        assert!(Keys::new("").is_err());
        assert!(Keys::new(&"x".repeat(65)).is_err());
        let k = Keys::new("r").unwrap();
        assert!(k.joint_sample("**").is_err());
        assert!(k.alive("joint", "a$b").is_err());
        assert!(Topic::parse("rig/r/joint/j1").is_err());
        assert!(Topic::parse("other/r/estimate/ee").is_err());
        assert!(Topic::parse("rig/r/estimate/ee/extra").is_err());
    }
}
