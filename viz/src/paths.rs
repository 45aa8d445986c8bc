//! Every entity path of the view, in one place: the logging code (`scene`) writes to them and
//! the blueprint shows them, so a path renamed here moves both. The table in viz/README.md
//! lists them for users.

/// The robot drawn in the plane [mm]: links, joints, bases, end effector, force arrows.
pub const ROBOT: &str = "robot";
pub const ROBOT_LINKS: &str = "robot/links";
pub const ROBOT_JOINTS: &str = "robot/joints";
pub const ROBOT_BASES: &str = "robot/bases";
pub const ROBOT_END_EFFECTOR: &str = "robot/end_effector";

/// The force arrow at the end effector: `robot/force/{estimate,truth}`.
pub fn robot_force(which: &str) -> String {
    format!("{ROBOT}/force/{which}")
}

/// End-effector force series [N].
pub const FORCE: &str = "force";

/// One force component: `force/{estimate,truth}/{x,y}`.
pub fn force(which: &str, axis: &str) -> String {
    format!("{FORCE}/{which}/{axis}")
}

/// The stiffness ellipses K·u [N/mm].
pub const ELLIPSE: &str = "allocation/ellipse";

/// One ellipse: `allocation/ellipse/{wanted,achieved,estimated}`.
pub fn ellipse(which: &str) -> String {
    format!("{ELLIPSE}/{which}")
}

/// Operational stiffness series [N/m].
pub const STIFFNESS: &str = "allocation/k";

/// One component: `allocation/k/{wanted,achieved,estimated}/{xx,xy,yy}`.
pub fn stiffness(which: &str, component: &str) -> String {
    format!("{STIFFNESS}/{which}/{component}")
}

/// Joint and estimator statuses, refused allocations (text log).
pub const STATUS: &str = "status";
/// The residual monitor's diagnoses (text log).
pub const DIAGNOSIS: &str = "diagnosis";

/// A joint's series: `joints/<j>` (its `pivot_mm`, `stiffness/…`, `residual`, `inertia/…`, …
/// below it).
pub fn joint(name: &str) -> String {
    format!("joints/{name}")
}

/// A joint's hysteresis loop: `joints/<j>/loop` (`measured`, `model` below it).
pub fn joint_loop(name: &str) -> String {
    format!("{}/loop", joint(name))
}

/// A blueprint origin: the path from the root.
pub fn origin(path: &str) -> String {
    format!("/{path}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_the_ones_the_readme_lists() {
        assert_eq!(robot_force("truth"), "robot/force/truth");
        assert_eq!(force("estimate", "x"), "force/estimate/x");
        assert_eq!(ellipse("wanted"), "allocation/ellipse/wanted");
        assert_eq!(stiffness("achieved", "xy"), "allocation/k/achieved/xy");
        assert_eq!(joint("j1"), "joints/j1");
        assert_eq!(joint_loop("j2"), "joints/j2/loop");
        assert_eq!(origin(STATUS), "/status");
    }
}
