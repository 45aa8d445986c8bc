//! `[security]`: who may say what on the rig's network.
//!
//! With a `[security]` section every link is TLS with client certificates (mutual TLS), all
//! signed by the lab's CA, and every process drops what a peer's certificate does not allow
//! it to publish (Zenoh's access control, default deny). Each process presents one
//! certificate, its **identity**; its common name (CN) is the identity's name:
//!
//! | identity | CN | may publish (under `rig/<rig>/`) |
//! |---|---|---|
//! | a joint's board agent | `joint-<joint>` | `joint/<joint>/sample`, `…/status`, `sim/joint/<joint>/truth` |
//! | estimator | `estimator` | `estimate/**` |
//! | allocator | `allocator` | `joint/*/command`, `allocation/result` |
//! | operator (`rig up`, `rig pivot`, `rig allocate`) | `operator` | `joint/*/command`, `stiffness/goal`; asks `allocate` |
//! | recorder, viz | `recorder`, `viz` | nothing (they listen) |
//! | a machine of the plan (`rig launch`) | `machine-<name>` | what its roles may, and `board/<name>/sample` when it runs two joints or more |
//!
//! Each identity may also declare its own liveliness token (`alive/<role>/…`); anyone with
//! a lab certificate may subscribe. This module is the table; `rig-runtime` turns it into
//! Zenoh's TLS and access-control settings, `rig certs` makes the certificates, and
//! `rig validate` checks the files. docs/SECURITY.md says what this protects and from whom.

use std::path::PathBuf;

use rig_protocol::{KeyError, Keys};

use crate::{RigConfig, Role};

/// Where the lab's CA and the identities' certificates are (`[security]`), resolved against
/// the config file's directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SecurityConfig {
    /// The lab CA's certificate (PEM): every peer's certificate must be signed by it.
    pub ca: PathBuf,
    /// The directory holding `<identity>.pem` and `<identity>.key` for each identity.
    pub certs: PathBuf,
}

impl SecurityConfig {
    /// The certificate (PEM) of `who`.
    pub fn cert(&self, who: &Identity) -> PathBuf {
        self.certs.join(format!("{}.pem", who.name()))
    }

    /// The private key (PEM) of `who`.
    pub fn key(&self, who: &Identity) -> PathBuf {
        self.certs.join(format!("{}.key", who.name()))
    }
}

/// Who a process is on the rig's network: the certificate it presents.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Identity {
    /// The board agent serving this one joint.
    Joint(String),
    Estimator,
    Allocator,
    /// A person's tools: `rig up`'s goal, `rig pivot`, `rig allocate`.
    Operator,
    Recorder,
    Viz,
    /// Every process of one machine of the plan (`rig launch`), its hub included.
    Machine(String),
}

/// What one identity may publish, as key expressions (`rig/<rig>/…`): data (`put`), queries
/// and liveliness tokens.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Grants {
    pub put: Vec<String>,
    /// Queries it may send (`rig allocate` asks the allocator).
    pub query: Vec<String>,
    pub alive: Vec<String>,
}

impl Identity {
    /// The certificate's common name, and the stem of its files.
    pub fn name(&self) -> String {
        match self {
            Identity::Joint(j) => format!("joint-{j}"),
            Identity::Estimator => "estimator".into(),
            Identity::Allocator => "allocator".into(),
            Identity::Operator => "operator".into(),
            Identity::Recorder => "recorder".into(),
            Identity::Viz => "viz".into(),
            Identity::Machine(m) => format!("machine-{m}"),
        }
    }

    /// The identity whose name is `name` in `cfg` (a joint or machine must exist).
    pub fn parse(cfg: &RigConfig, name: &str) -> Result<Identity, String> {
        let known = identities(cfg);
        known
            .iter()
            .find(|i| i.name() == name)
            .cloned()
            .ok_or_else(|| {
                let names: Vec<String> = known.iter().map(Identity::name).collect();
                format!(
                    "{name:?} is no identity of rig \"{}\"; it has {}",
                    cfg.name,
                    names.join(", ")
                )
            })
    }

    /// The identity of the process playing `role` (a joint: its board agent).
    pub fn of_role(role: &Role) -> Identity {
        match role {
            Role::Joint(j) => Identity::Joint(j.clone()),
            Role::Estimator => Identity::Estimator,
            Role::Allocator => Identity::Allocator,
            Role::Recorder => Identity::Recorder,
            Role::Viz => Identity::Viz,
        }
    }

    /// What this identity may publish in `cfg`, as full key expressions from [`Keys`].
    /// Fails only on a name `Keys` refuses, which a validated config does not hold.
    pub fn grants(&self, cfg: &RigConfig) -> Result<Grants, KeyError> {
        let k = Keys::new(&cfg.name)?;
        Ok(match self {
            Identity::Joint(j) => Grants {
                put: vec![k.joint_sample(j)?, k.joint_status(j)?, k.sim_truth(j)?],
                alive: vec![k.alive("joint", j)?],
                ..Grants::default()
            },
            Identity::Estimator => Grants {
                put: vec![k.all_estimates()],
                alive: vec![k.all_alive("estimator")?],
                ..Grants::default()
            },
            Identity::Allocator => Grants {
                put: vec![k.all_joint_commands(), k.allocation_result()],
                alive: vec![k.all_alive("allocator")?],
                ..Grants::default()
            },
            Identity::Operator => Grants {
                put: vec![k.all_joint_commands(), k.stiffness_goal()],
                query: vec![k.allocate()],
                alive: vec![k.all_alive("operator")?],
            },
            Identity::Recorder => Grants {
                alive: vec![k.all_alive("recorder")?],
                ..Grants::default()
            },
            Identity::Viz => Grants {
                alive: vec![k.all_alive("viz")?],
                ..Grants::default()
            },
            Identity::Machine(m) => {
                let mut g = Grants::default();
                let roles = cfg.machine(m).map_or(&[][..], |m| &m.roles[..]);
                // A board agent serving several of its joints sends each tick as one message.
                if roles.iter().filter(|r| matches!(r, Role::Joint(_))).count() > 1 {
                    g.put.push(k.board_sample(m)?);
                }
                for r in roles {
                    let r = Identity::of_role(r).grants(cfg)?;
                    for k in r.put {
                        if !g.put.contains(&k) {
                            g.put.push(k);
                        }
                    }
                    g.query.extend(r.query);
                    g.alive.extend(r.alive);
                }
                g
            }
        })
    }
}

/// The identity of a board agent serving `joints`: the joint's own for one joint; for several,
/// the machine of the plan that runs them all (its certificate may publish for each). `None`
/// when no one certificate may publish for all of them.
pub fn board_identity(cfg: &RigConfig, joints: &[String]) -> Option<Identity> {
    match joints {
        [one] => Some(Identity::Joint(one.clone())),
        _ => cfg
            .machines
            .iter()
            .find(|m| {
                joints
                    .iter()
                    .all(|j| m.roles.contains(&Role::Joint(j.clone())))
            })
            .map(|m| Identity::Machine(m.name.clone())),
    }
}

/// The name in the board key (`rig/<rig>/board/<name>/sample`) of an agent serving several
/// `joints`: the plan's machine that runs them all (its certificate may publish there), else
/// the first joint's name (possible only without `[security]`).
pub fn board_name(cfg: &RigConfig, joints: &[String]) -> String {
    match board_identity(cfg, joints) {
        Some(Identity::Machine(m)) => m,
        _ => joints.first().cloned().unwrap_or_default(),
    }
}

/// Whether a message on board `board`'s key may carry joint `joint`'s sample: a machine of
/// the plan carries the joints it runs; a board that is no machine of the plan carries any
/// joint without `[security]` (where anyone may say anything) and none under it (no
/// certificate may publish there).
pub fn board_may_carry(cfg: &RigConfig, board: &str, joint: &str) -> bool {
    match cfg.machine(board) {
        Some(m) => m.roles.contains(&Role::Joint(joint.to_string())),
        None => cfg.security.is_none(),
    }
}

/// Every identity of `cfg`, one certificate each: each joint's board, the hosts, the operator,
/// the recorder and the view, and each machine of the plan.
pub fn identities(cfg: &RigConfig) -> Vec<Identity> {
    cfg.joints
        .iter()
        .map(|j| Identity::Joint(j.name.clone()))
        .chain([
            Identity::Estimator,
            Identity::Allocator,
            Identity::Operator,
            Identity::Recorder,
            Identity::Viz,
        ])
        .chain(
            cfg.machines
                .iter()
                .map(|m| Identity::Machine(m.name.clone())),
        )
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_identity_may_publish_only_its_own_keys_and_a_machine_what_its_roles_may() {
        let mut cfg = crate::examples::load("parallel").unwrap();
        let j1 = Identity::Joint("j1".into()).grants(&cfg).unwrap();
        assert_eq!(
            j1.put,
            [
                "rig/parallel/joint/j1/sample",
                "rig/parallel/joint/j1/status",
                "rig/parallel/sim/joint/j1/truth"
            ]
        );
        assert_eq!(j1.alive, ["rig/parallel/alive/joint/j1"]);
        assert!(!j1.put.iter().any(|k| k.contains("command")));
        assert!(
            Identity::Estimator
                .grants(&cfg)
                .unwrap()
                .put
                .iter()
                .all(|k| k.starts_with("rig/parallel/estimate/"))
        );
        assert!(Identity::Recorder.grants(&cfg).unwrap().put.is_empty());
        let op = Identity::Operator.grants(&cfg).unwrap().put;
        assert!(op.contains(&"rig/parallel/stiffness/goal".to_string()));
        assert!(
            !Identity::Allocator
                .grants(&cfg)
                .unwrap()
                .put
                .contains(&"rig/parallel/stiffness/goal".to_string())
        );
        cfg.machines = vec![crate::Machine {
            name: "board1".into(),
            roles: vec![Role::Joint("j1".into()), Role::Allocator],
            listen: vec![],
            connect: vec![],
        }];
        let m = Identity::Machine("board1".into()).grants(&cfg).unwrap();
        assert!(m.put.contains(&"rig/parallel/joint/j1/sample".to_string()));
        assert!(m.put.contains(&"rig/parallel/joint/*/command".to_string()));
        assert!(!m.put.contains(&"rig/parallel/joint/j2/sample".to_string()));
        assert!(!m.put.iter().any(|k| k.starts_with("rig/parallel/estimate")));
        assert!(
            !m.put.iter().any(|k| k.contains("/board/")),
            "one joint: no board key"
        );
        let served = |v: &[&str]| v.iter().map(|j| j.to_string()).collect::<Vec<_>>();
        assert_eq!(
            board_identity(&cfg, &served(&["j3"])),
            Some(Identity::Joint("j3".into()))
        );
        assert_eq!(
            board_identity(&cfg, &served(&["j1"])),
            Some(Identity::Joint("j1".into()))
        );
        assert_eq!(board_identity(&cfg, &served(&["j1", "j2"])), None);
        cfg.machines[0].roles.push(Role::Joint("j2".into()));
        assert_eq!(
            board_identity(&cfg, &served(&["j1", "j2"])),
            Some(Identity::Machine("board1".into()))
        );
        // Two joints on the machine: its board key, which carries only its joints.
        let m = Identity::Machine("board1".into()).grants(&cfg).unwrap();
        assert!(
            m.put
                .contains(&"rig/parallel/board/board1/sample".to_string())
        );
        assert_eq!(board_name(&cfg, &served(&["j1", "j2"])), "board1");
        assert_eq!(board_name(&cfg, &served(&["j3", "j4"])), "j3");
        assert!(board_may_carry(&cfg, "board1", "j2"));
        assert!(!board_may_carry(&cfg, "board1", "j3"));
        assert!(
            board_may_carry(&cfg, "j3", "j4"),
            "no [security]: any joint"
        );
        cfg.security = Some(SecurityConfig {
            ca: "ca.pem".into(),
            certs: "certs".into(),
        });
        assert!(
            !board_may_carry(&cfg, "j3", "j4"),
            "[security]: machines only"
        );
        assert!(board_may_carry(&cfg, "board1", "j1"));
        let names: Vec<String> = identities(&cfg).iter().map(Identity::name).collect();
        assert!(names.contains(&"machine-board1".to_string()));
        assert_eq!(
            Identity::parse(&cfg, "joint-j2"),
            Ok(Identity::Joint("j2".into()))
        );
        let e = Identity::parse(&cfg, "joint-j9").unwrap_err();
        assert!(e.contains("joint-j9") && e.contains("estimator"), "{e}");
    }
}
