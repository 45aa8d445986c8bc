//! The plan across machines, as this environment allows: three network namespaces joined by
//! veth pairs (made and removed by this test, as root) stand for the host PC and the board
//! computers of the five-bar's two chains. Each runs `rig launch --machine` from the config
//! alone. The chains are linked only to the host, so every sample crosses a veth pair into the
//! host's hub. The host's recorder holds the run; the end-effector force it recorded is scored
//! against the simulated truth it also recorded. An operator on chain 1 asks the host's
//! allocator for a stiffness (`rig allocate --live`): its commands reach all four joints.
//!
//! Where namespaces cannot be made (not root, no `ip`), the test says so; under CI (`CI` set)
//! it fails rather than skipping.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::{bin, config, serial, test_dir};

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use rig_runtime::now_ns;

/// Namespaces this test made; removed (with their veth ends) when dropped.
struct Namespaces(Vec<String>);

impl Drop for Namespaces {
    fn drop(&mut self) {
        for ns in &self.0 {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

fn ip(args: &[&str]) -> Result<(), String> {
    let o = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e}", args.join(" ")))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        ))
    }
}

/// host ↔ chain1 on 10.201.1.0/24, host ↔ chain2 on 10.201.2.0/24; chain1 and chain2 are
/// not linked to each other.
fn make_namespaces(tag: u32) -> Result<(Namespaces, [String; 3]), String> {
    let names = [
        format!("rig-host-{tag}"),
        format!("rig-chain1-{tag}"),
        format!("rig-chain2-{tag}"),
    ];
    let mut made = Namespaces(vec![]);
    for ns in &names {
        ip(&["netns", "add", ns])?;
        made.0.push(ns.clone());
        ip(&["-n", ns, "link", "set", "lo", "up"])?;
    }
    for (k, chain) in [(1, &names[1]), (2, &names[2])] {
        let (h, c) = (format!("rvh{k}-{tag}"), format!("rvc{k}-{tag}"));
        ip(&["link", "add", &h, "type", "veth", "peer", "name", &c])?;
        ip(&["link", "set", &h, "netns", &names[0]])?;
        ip(&["link", "set", &c, "netns", chain])?;
        ip(&[
            "-n",
            &names[0],
            "addr",
            "add",
            &format!("10.201.{k}.1/24"),
            "dev",
            &h,
        ])?;
        ip(&[
            "-n",
            chain,
            "addr",
            "add",
            &format!("10.201.{k}.2/24"),
            "dev",
            &c,
        ])?;
        ip(&["-n", &names[0], "link", "set", &h, "up"])?;
        ip(&["-n", chain, "link", "set", &c, "up"])?;
    }
    Ok((made, names))
}

/// The example parallel robot with this test's plan in place of the example's; `secure`: every
/// link mutual TLS with the lab's certificates from `rig certs`, and access control by role.
fn plan_config(dir: &Path, secure: bool) -> std::path::PathBuf {
    let src = std::fs::read_to_string(config()).unwrap();
    let at = src.find("\n[[machine]]").expect("the example has a plan") + 1;
    let plan = r#"[[machine]]
name = "host"
roles = ["estimator", "allocator", "recorder"]
listen = ["tcp/10.201.1.1:7447", "tcp/10.201.2.1:7447"]

[[machine]]
name = "chain1"
roles = ["j1", "j2"]
connect = ["tcp/10.201.1.1:7447"]

[[machine]]
name = "chain2"
roles = ["j3", "j4"]
connect = ["tcp/10.201.2.1:7447"]
"#;
    let path = dir.join("lab.toml");
    let mut toml = format!("{}{plan}", &src[..at]);
    if secure {
        toml = toml.replace("\"tcp/", "\"tls/")
            + "\n[security]\nca = \"certs/ca.pem\"\ncerts = \"certs\"\n";
    }
    std::fs::write(&path, toml).unwrap();
    if secure {
        let o = Command::new(bin("rig"))
            .args(["certs", "--config"])
            .arg(&path)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    path
}

/// Columns of a CSV written by `rig export`, by header name.
fn csv_columns(path: &Path) -> BTreeMap<String, Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let mut cols: BTreeMap<String, Vec<String>> =
        header.iter().map(|h| (h.clone(), vec![])).collect();
    for l in lines {
        for (h, v) in header.iter().zip(l.split(',')) {
            cols.get_mut(h).unwrap().push(v.to_string());
        }
    }
    cols
}

fn wait_or_kill(child: &mut Child, within: Duration) -> Option<std::process::ExitStatus> {
    let t0 = Instant::now();
    while t0.elapsed() < within {
        if let Ok(Some(s)) = child.try_wait() {
            return Some(s);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

/// The three namespaces, or `None` after saying why they cannot be made here (under CI: a
/// failure, not a skip).
fn namespaces_or_say_why(tag: u32) -> Option<(Namespaces, [String; 3])> {
    match make_namespaces(tag) {
        Ok(made) => Some(made),
        Err(why) => {
            let msg = format!(
                "cannot make network namespaces here ({why}): the test needs root and `ip` (iproute2)"
            );
            assert!(std::env::var_os("CI").is_none(), "{msg}");
            eprintln!("{msg}; not run");
            None
        }
    }
}

/// One `rig launch --machine` per namespace, the host first; one simulated world for all.
fn launch_plan(
    ns: &[String; 3],
    cfg_path: &Path,
    dir: &Path,
    secs: u32,
    start: u64,
    recording: &Path,
) -> Vec<(String, Child, std::path::PathBuf)> {
    let mut launched = Vec::new();
    for (machine, netns) in ["host", "chain1", "chain2"].iter().zip(ns) {
        let log = dir.join(format!("{machine}.log"));
        let child = Command::new("ip")
            .args(["netns", "exec", netns])
            .arg(bin("rig"))
            .args(["launch", "--config"])
            .arg(cfg_path)
            .args(["--machine", machine, "--duration", &secs.to_string()])
            .args(["--start-ns", &start.to_string(), "--out"])
            .arg(recording)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        launched.push((machine.to_string(), child, log));
    }
    launched
}

/// Every machine's launch ends by itself, cleanly.
fn end_cleanly(launched: &mut [(String, Child, std::path::PathBuf)]) {
    for (machine, child, log) in launched {
        let status = wait_or_kill(child, Duration::from_secs(60));
        let text = std::fs::read_to_string(&*log).unwrap_or_default();
        assert!(
            status.is_some_and(|s| s.success()),
            "rig launch --machine {machine}: {status:?}\n{text}"
        );
        assert!(text.contains("ended cleanly"), "{machine}: {text}");
    }
}

/// What the host recorded, as CSV (`rig export`); the directory.
fn export_csv(recording: &Path, dir: &Path) -> std::path::PathBuf {
    let csv = dir.join("csv");
    let o = Command::new(bin("rig"))
        .arg("export")
        .arg(recording)
        .args(["--to", "csv"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    csv
}

#[test]
fn three_machines_in_network_namespaces_run_the_plan_over_mutual_tls_and_estimate_the_force_across_them()
 {
    let _one_at_a_time = serial();
    let Some((_namespaces, ns)) = namespaces_or_say_why(std::process::id() % 100_000) else {
        return;
    };
    let dir = test_dir("deploy");
    // Secured: each machine's hub and roles present the machine's certificate, the operator
    // its own; every hub checks each message against its sender's role.
    let cfg_path = plan_config(&dir, true);
    let rig = bin("rig");

    // The plan as `rig launch --plan` prints it.
    let o = Command::new(&rig)
        .args(["launch", "--config"])
        .arg(&cfg_path)
        .arg("--plan")
        .output()
        .unwrap();
    let plan = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{plan}");
    assert!(
        plan.contains(
            "machine \"chain2\" runs j3, j4; listens on nothing; connects to tls/10.201.2.1:7447"
        ),
        "{plan}"
    );
    assert!(plan.contains("--machine chain1"), "{plan}");

    // One `rig launch` per machine, the host first; one simulated world for all.
    let start = now_ns();
    let recording = dir.join("lab.mcap");
    let mut launched = launch_plan(&ns, &cfg_path, &dir, 14, start, &recording);
    // An operator on the board computer of chain 1 asks the host's allocator for 60 % of the
    // stiffness range: the allocator, on the host, commands all four joints — j3 and j4 across
    // the other veth pair. Retried while the machines come up.
    let t_ask = Instant::now();
    let answer = loop {
        std::thread::sleep(Duration::from_secs(1));
        let o = Command::new("ip")
            .args(["netns", "exec", &ns[1]])
            .arg(&rig)
            .args(["allocate", "--config"])
            .arg(&cfg_path)
            .args(["--live", "--percent", "60", "--json", "--within", "2"])
            .args(["--connect", "tls/10.201.1.1:7447"])
            .output()
            .unwrap();
        if o.status.success() {
            break serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap();
        }
        // Not answered yet (exit 1) is retried; an answer that refuses is not.
        assert!(
            o.status.code() == Some(1) && t_ask.elapsed() < Duration::from_secs(10),
            "rig allocate --live from chain1: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    assert_eq!(answer["feasible"], true, "{answer}");
    let pivots: Vec<f64> = answer["pivot_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(pivots.len(), 4, "{answer}");

    end_cleanly(&mut launched);
    let csv = export_csv(&recording, &dir);
    let mut truth = common::Truths::new();
    for j in ["j1", "j2", "j3", "j4"] {
        let c = csv_columns(&csv.join(format!("rig.parallel.sim.joint.{j}.truth.csv")));
        for ((t, joint), tau) in c["t_acq_ns"].iter().zip(&c["joint"]).zip(&c["torque_nm"]) {
            truth
                .entry(t.parse().unwrap())
                .or_default()
                .insert(joint.parse().unwrap(), tau.parse().unwrap());
        }
    }
    // Every pivot went where the allocator said (the commands crossed the veths), from
    // somewhere else (it was the command that moved it).
    // Each chain's two joints are one board: a board message per tick, one CSV row per joint.
    for (k, want) in pivots.iter().enumerate() {
        let chain = 1 + k / 2;
        let c = csv_columns(&csv.join(format!("rig.parallel.board.chain{chain}.sample.csv")));
        let pivot: Vec<f64> = c["pivot_m"]
            .iter()
            .zip(&c["joint"])
            .filter(|(_, j)| **j == k.to_string())
            .filter_map(|(v, _)| v.parse().ok())
            .collect();
        let (first, last) = (pivot[0], pivot[pivot.len() - 1]);
        eprintln!(
            "j{}: pivot {:.3} mm at the start, {:.3} mm at the end, {:.3} mm allocated",
            k + 1,
            first * 1e3,
            last * 1e3,
            want * 1e3
        );
        assert!(
            (last - want).abs() < 0.1e-3,
            "j{}: {last} m, allocated {want} m",
            k + 1
        );
        assert!(
            (first - want).abs() > 1e-3,
            "j{}: already at {first} m",
            k + 1
        );
    }
    let ee = csv_columns(&csv.join("rig.parallel.estimate.ee.csv"));
    let scored: Vec<(u64, f64, f64)> = ee["t_ns"]
        .iter()
        .zip(&ee["force_n.0"])
        .zip(&ee["force_n.1"])
        .filter_map(|((t, fx), fy)| Some((t.parse().ok()?, fx.parse().ok()?, fy.parse().ok()?)))
        .filter(|(t, _, _)| *t >= start + 2_000_000_000)
        .collect();
    let (rmse, peak, n) = common::force_error(start, &truth, &scored);
    assert!(
        n > 2000,
        "only {n} end-effector estimates matched a complete truth (of {})",
        ee["t_ns"].len()
    );
    eprintln!(
        "across three namespaces: force RMSE {rmse:.4} N against a {peak:.2} N peak over {n} estimates"
    );
    assert!(peak > 0.5, "the hand must load the robot: peak {peak} N");
    // The same bound as on loopback (distributed.rs): the veths add little.
    assert!(
        rmse < 0.05 * peak,
        "force RMSE {rmse} N against a {peak} N peak over {n} estimates"
    );
}

/// The host's end of chain `k`'s veth pair, up or down: a partition of that board computer.
fn link(ns: &[String; 3], k: u32, tag: u32, up: bool) {
    let dev = format!("rvh{k}-{tag}");
    ip(&[
        "-n",
        &ns[0],
        "link",
        "set",
        &dev,
        if up { "up" } else { "down" },
    ])
    .unwrap();
}

#[test]
fn a_board_computer_cut_off_for_3_s_and_for_15_s_is_estimated_again_within_1_s_of_its_link() {
    // Chain 2 (j3, j4) loses its link to the host twice: 3 s (under the 10 s lease: the
    // session survives) and 15 s (over it: the session closes and is made again).
    // Alone: with the other plan's six processes beside it on a 2-core machine the estimator
    // falls behind 1 kHz, which is not what this test is about.
    let _one_at_a_time = serial();
    let tag = std::process::id() % 100_000 + 1;
    let Some((_namespaces, ns)) = namespaces_or_say_why(tag) else {
        return;
    };
    // The board computers as docs/DEPLOY.md sets them up: the kernel asks for a neighbour's
    // address every 0.1 s rather than every 1 s, so a board whose link returns finds the host
    // within 0.1 s (with the kernel's default, this test measured 0.66–0.86 s for the 15 s cut).
    for (k, board) in [(1, &ns[1]), (2, &ns[2])] {
        let key = format!("net.ipv4.neigh.rvc{k}-{tag}.retrans_time_ms=100");
        let ok = Command::new("ip")
            .args(["netns", "exec", board, "sysctl", "-q", "-w", &key])
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "sysctl -w {key} in {board}");
    }
    let dir = test_dir("partition");
    let cfg_path = plan_config(&dir, false);
    let start = now_ns();
    let recording = dir.join("lab.mcap");
    let mut launched = launch_plan(&ns, &cfg_path, &dir, 36, start, &recording);
    let at = |s: u64| {
        let t = start + s * 1_000_000_000;
        std::thread::sleep(Duration::from_nanos(t.saturating_sub(now_ns())));
    };
    let mut returned = Vec::new();
    for (down_s, up_s) in [(8, 11), (15, 30)] {
        at(down_s);
        link(&ns, 2, tag, false);
        at(up_s);
        link(&ns, 2, tag, true);
        returned.push(now_ns());
    }
    // No process exits on a partition: each machine's launch ends cleanly at its duration.
    end_cleanly(&mut launched);
    let csv = export_csv(&recording, &dir);
    let ee = csv_columns(&csv.join("rig.parallel.estimate.ee.csv"));
    let times: Vec<u64> = ee["t_ns"].iter().filter_map(|t| t.parse().ok()).collect();
    // The rate this machine keeps while every link is up (from 0.5 s after the first estimate
    // to 7.5 s, before the first cut): the recovery is held to it, not to a nominal 1 kHz a
    // loaded machine may not keep at all.
    let to = start + 7_500_000_000;
    let from = times.first().map_or(to, |t| t + 500_000_000);
    assert!(
        from + 2_000_000_000 < to,
        "the plan's first estimate came too late to measure"
    );
    let before = times.iter().filter(|&&t| t > from && t < to).count();
    let rate_hz = before as f64 / ((to - from) as f64 * 1e-9);
    eprintln!("before the first cut: {rate_hz:.0} estimates a second");
    assert!(
        rate_hz > 500.0,
        "the plan estimates at {rate_hz} Hz with every link up"
    );
    for (k, back) in returned.iter().enumerate() {
        // The first end-effector estimate after the link returned; none may be missing for
        // long after it.
        let first = times
            .iter()
            .find(|&&t| t > *back)
            .unwrap_or_else(|| panic!("partition {}: no estimate after the link returned", k + 1));
        let recovery_s = (first - back) as f64 * 1e-9;
        let until = back + 4_000_000_000;
        let after = times.iter().filter(|&&t| t > *first && t < until).count();
        eprintln!(
            "partition {}: estimates again {:.3} s after the link returned; {} in the next {:.1} s",
            k + 1,
            recovery_s,
            after,
            (until - first) as f64 * 1e-9
        );
        assert!(recovery_s < 1.0, "partition {}: {recovery_s} s", k + 1);
        // Steady again: at least 90 % of the rate kept before the cut.
        let want = 0.9 * rate_hz * (until - first) as f64 * 1e-9;
        assert!(
            after as f64 > want,
            "partition {}: {after} estimates, under 90 % of the {rate_hz:.0} Hz kept before",
            k + 1
        );
    }
    // Withheld while cut off (never a force from a stale joint).
    let during = times
        .iter()
        .filter(|&&t| t > start + 16_000_000_000 && t < start + 29_000_000_000)
        .count();
    assert_eq!(during, 0, "{during} estimates while j3 and j4 were cut off");
}
