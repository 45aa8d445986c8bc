//! Helpers shared by the end-to-end tests (each test binary uses some of them).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// A binary of the workspace, next to this test's own executable's directory.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().and_then(Path::parent).unwrap();
    let p = dir.join(name);
    assert!(
        p.exists(),
        "{} is not built: run `cargo build --workspace` (cargo test --workspace builds it)",
        p.display()
    );
    p
}

/// A free TCP port on loopback, outside the kernel's ephemeral range (see
/// [`rig_runtime::free_loopback_port`]).
pub fn free_port() -> u16 {
    rig_runtime::free_loopback_port().unwrap()
}

/// A child process killed when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A workspace binary started with `args`, its output discarded.
pub fn spawn(name: &str, args: &[String]) -> Proc {
    Proc(
        Command::new(bin(name))
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    )
}

/// [`spawn`] with the process's stderr kept in `log` (read it into a failure's message).
pub fn spawn_logged(name: &str, args: &[String], log: &std::path::Path) -> Proc {
    Proc(
        Command::new(bin(name))
            .args(args)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(log).unwrap())
            .spawn()
            .unwrap(),
    )
}

/// An external tool the tests check against (`python3`, `rerun`): from `RIG_TOOLS_BIN` when
/// `cargo xtask test` set it (its project-local Python environment), else from `PATH`. The
/// environment is passed this way, not on `PATH`, so that cargo's build scripts see the same
/// `PATH` as the run command's build and nothing is rebuilt for the tests.
pub fn tool(name: &str) -> Command {
    match std::env::var_os("RIG_TOOLS_BIN") {
        Some(dir) if Path::new(&dir).join(name).exists() => {
            Command::new(Path::new(&dir).join(name))
        }
        _ => Command::new(name),
    }
}

pub fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// One rig test at a time within a test binary: each runs a whole rig of processes on this
/// 2-core machine.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

pub fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

pub fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// The example parallel robot's config file.
pub fn config() -> PathBuf {
    example("parallel")
}

/// The example config `rig-config/examples/<name>.toml`.
pub fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../rig-config/examples/{name}.toml"))
}

/// A Zenoh session of the example rig that listens on or connects to these endpoints.
pub async fn session(listen: &[&str], connect: &[&str]) -> rig_runtime::zenoh::Session {
    let cfg = rig_config::load(&config()).unwrap();
    let own = |v: &[&str]| v.iter().map(|e| e.to_string()).collect();
    rig_runtime::open(
        &cfg,
        &rig_runtime::NetOverrides {
            listen: own(listen),
            connect: own(connect),
            ..Default::default()
        },
        &rig_config::Identity::Operator,
    )
    .await
    .unwrap()
}

/// The liveliness key of a role of the example rig (`rig/parallel/alive/<role>/<id>`).
pub fn alive(role: &str, id: &str) -> String {
    alive_in("parallel", role, id)
}

/// The liveliness key of a role of rig `rig` (`rig/<rig>/alive/<role>/<id>`), from `Keys`.
pub fn alive_in(rig: &str, role: &str, id: &str) -> String {
    rig_protocol::Keys::new(rig)
        .and_then(|k| k.alive(role, id))
        .unwrap()
}

/// Waits, on a session of its own connected to `hub`, until each role's liveliness token is up
/// (a role declares it once its subscriptions are in place); panics naming those that did not
/// come within 20 s. Tests start what depends on a role after this, instead of sleeping.
pub fn wait_alive(hub: &str, keys: &[String]) {
    rt().block_on(async {
        let z = session(&[], &[hub]).await;
        wait_alive_on(&z, keys).await;
        let _ = z.close().await;
    });
}

/// [`wait_alive`] on a session the test already has.
pub async fn wait_alive_on(z: &rig_runtime::zenoh::Session, keys: &[String]) {
    let missing = rig_runtime::wait_alive(z, keys, std::time::Duration::from_secs(20))
        .await
        .unwrap();
    assert!(missing.is_empty(), "not up within 20 s: {missing:?}");
}

/// A directory for one test's files, `rig-<what>-<pid>` under the temp dir, made if missing.
pub fn test_dir(what: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rig-{what}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Ends a process as Ctrl-C would (SIGINT), without waiting for it.
pub fn interrupt(p: &Proc) {
    let sent = Command::new("kill")
        .args(["-INT", &p.0.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill -INT {}", p.0.id());
}

/// [`interrupt`], then asserts the process ends cleanly (exit status 0).
pub fn interrupt_and_wait(p: &mut Proc, what: &str) {
    interrupt(p);
    assert!(
        p.0.wait().unwrap().success(),
        "{what} ends cleanly on Ctrl-C"
    );
}

/// Each simulated joint's true torque by acquisition time: `t_acq_ns → (joint index → N·m)`.
pub type Truths = std::collections::BTreeMap<u64, std::collections::BTreeMap<u16, f64>>;

/// Every simulated joint truth of the example rig that reaches `z`, gathered in a callback
/// (4 kHz of them must never queue): the map they go into, and the subscriber that feeds it
/// while it lives.
pub async fn collect_truths(
    z: &rig_runtime::zenoh::Session,
) -> (
    std::sync::Arc<std::sync::Mutex<Truths>>,
    rig_runtime::zenoh::pubsub::Subscriber<()>,
) {
    let truths = std::sync::Arc::new(std::sync::Mutex::new(Truths::new()));
    let tm = truths.clone();
    let sub = z
        .declare_subscriber("rig/parallel/sim/joint/*/truth")
        .callback(move |t| {
            if let Ok(m) = rig_protocol::decode::<rig_protocol::SimTruth>(&t.payload().to_bytes()) {
                tm.lock()
                    .unwrap()
                    .entry(m.t_acq_ns)
                    .or_default()
                    .insert(m.joint, m.torque_nm);
            }
        })
        .await
        .unwrap();
    (truths, sub)
}

/// The end-effector force estimates `(t_ns, fx, fy)` of the example parallel robot scored
/// against the force its simulated hand pushed with (the stroke world started at `start`
/// [ns]), at the ticks where all four joints' truths are known: (RMSE [N], peak [N], count).
pub fn force_error(start: u64, truth: &Truths, ee: &[(u64, f64, f64)]) -> (f64, f64, usize) {
    use rig_sim::world::{HAND_STROKE_M, HAND_STROKE_S, StrokeWorld};
    let cfg = rig_config::load(&config()).unwrap();
    let world = StrokeWorld::new(
        cfg.robot().unwrap(),
        cfg.geometry.unwrap().home,
        HAND_STROKE_M,
        HAND_STROKE_S,
    )
    .unwrap();
    let (mut sq, mut n, mut peak) = (0.0, 0usize, 0.0_f64);
    for &(t, fx, fy) in ee {
        let Some(tj) = truth.get(&t).filter(|m| m.len() == 4) else {
            continue;
        };
        let f = world
            .force(
                (t - start) as f64 * 1e-9,
                &tj.values().copied().collect::<Vec<_>>(),
            )
            .unwrap();
        sq += (fx - f[0]).powi(2) + (fy - f[1]).powi(2);
        peak = peak.max(f.norm());
        n += 1;
    }
    ((sq / n.max(1) as f64).sqrt(), peak, n)
}

/// The number before `label` in the last line of the log `log` that starts with `report` (a
/// role's closing report, e.g. "rig estimator: …, 3 malformed; refused: 2 replayed, …"; any
/// "dropped …" lines of the run start alike and come before it).
pub fn report_count(log: &Path, report: &str, label: &str) -> u64 {
    let text = std::fs::read_to_string(log).unwrap();
    text.lines()
        .rev()
        .filter(|l| l.starts_with(report))
        .find_map(|l| {
            l.split([',', ';', ':', '('])
                .map(str::trim)
                .find_map(|p| p.strip_suffix(label)?.trim().parse().ok())
        })
        .unwrap_or_else(|| panic!("no \"{label}\" count after \"{report}\" in:\n{text}"))
}

/// A command holding joint 0 (of its key) at `pivot_m`, torque on, stamped now.
pub fn pivot_command(seq: u64, pivot_m: f64) -> Vec<u8> {
    rig_protocol::encode(&rig_protocol::JointCommand {
        joint: 0,
        seq,
        t_ns: rig_runtime::now_ns(),
        motor_goal_rad: None,
        pivot_goal_m: Some(pivot_m),
        stiffness_motor_goal_rad: None,
        torque_enable: true,
    })
    .unwrap()
}
