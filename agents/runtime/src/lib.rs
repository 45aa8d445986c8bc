//! # rig-runtime — the rig's Zenoh edge
//!
//! Opens Zenoh sessions the way every agent of the rig needs them: the mode and endpoints
//! from the rig config, overridden by `--listen` / `--connect`, **multicast scouting off**
//! (peers find each other through the endpoints given and gossip over the links they have,
//! so nothing leaves the machine unless an endpoint says so), timestamping on. Also the one
//! clock every agent stamps with.

use std::time::{SystemTime, UNIX_EPOCH};

use rig_config::{Identity, RigConfig, ZenohConfig, ZenohMode, identities};
use serde_json::json;
use thiserror::Error;

pub use zenoh;

pub mod cli;
pub use cli::{NetArgs, RunFor, tokio_runtime};

/// Errors of the Zenoh edge.
#[derive(Debug, Error)]
pub enum RuntimeError {
    #[error("zenoh configuration, {key}: {source}")]
    Config {
        key: String,
        #[source]
        source: zenoh::Error,
    },
    /// `[security]` cannot be applied (a certificate missing).
    #[error("security: {0}")]
    Security(String),
    #[error("zenoh session: {0}")]
    Session(#[source] zenoh::Error),
    #[error("invalid endpoint {endpoint:?}: {why}")]
    Endpoint { endpoint: String, why: String },
    /// A Zenoh operation (declare, put, reply, close) failed.
    #[error("zenoh: {0}")]
    Zenoh(#[source] zenoh::Error),
    /// A key expression could not be built from the config's names.
    #[error("{0}")]
    Key(#[from] rig_protocol::KeyError),
}

/// Whether the `n`th occurrence of something is worth a line of log: the 1st, 10th, 100th, …
/// A flood (a peer's malformed messages, a sensor failing every tick) cannot fill the log,
/// and the line carries the count, so nothing is hidden.
pub fn worth_a_line(mut n: u64) -> bool {
    while n >= 10 && n.is_multiple_of(10) {
        n /= 10;
    }
    n == 1
}

/// Counts occurrences of one thing; [`LogBudget::count`] gives the count when it is worth a
/// line ([`worth_a_line`]).
#[derive(Debug, Default, Clone, Copy)]
pub struct LogBudget {
    n: u64,
}

impl LogBudget {
    /// Counts one; `Some(count so far)` when this one should be said.
    pub fn count(&mut self) -> Option<u64> {
        self.n += 1;
        worth_a_line(self.n).then_some(self.n)
    }
}

/// Wraps any Zenoh error, for `.map_err(zenoh_err)?` at the edges.
pub fn zenoh_err<E: Into<zenoh::Error>>(e: E) -> RuntimeError {
    RuntimeError::Zenoh(e.into())
}

/// Endpoint overrides from the command line.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NetOverrides {
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    /// Replaces the config's `[zenoh].mode` (`rig launch` runs its roles as clients of the
    /// machine's hub).
    pub mode: Option<ZenohMode>,
    /// The identity to present instead of the role's own (`rig launch`: the machine's).
    pub identity: Option<String>,
}

/// A role's loop clock: a tick every `period` (missed ticks skipped, not bunched) until the
/// shutdown future resolves or the run's duration has passed.
pub struct Ticks<F> {
    ticker: tokio::time::Interval,
    deadline: Option<tokio::time::Instant>,
    shutdown: std::pin::Pin<Box<F>>,
}

impl<F> std::fmt::Debug for Ticks<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ticks")
            .field("period", &self.ticker.period())
            .field("deadline", &self.deadline)
            .finish_non_exhaustive()
    }
}

impl<F: std::future::Future<Output = ()>> Ticks<F> {
    /// Ticks every `period` for `duration` (None: until `shutdown`). Call from a runtime.
    pub fn new(
        period: std::time::Duration,
        duration: Option<std::time::Duration>,
        shutdown: F,
    ) -> Self {
        let mut ticker = tokio::time::interval(period);
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        Self {
            ticker,
            deadline: duration.map(|d| tokio::time::Instant::now() + d),
            shutdown: Box::pin(shutdown),
        }
    }

    /// Waits for the next tick: `true` to go on, `false` once shut down or past the duration
    /// (then stop calling).
    pub async fn next(&mut self) -> bool {
        tokio::select! {
            // A shutdown wins over a tick that is due at the same time.
            biased;
            _ = &mut self.shutdown => return false,
            _ = self.ticker.tick() => {}
        }
        self.deadline
            .is_none_or(|d| tokio::time::Instant::now() < d)
    }
}

/// When `s` was published, from its Zenoh timestamp (set by the publisher's session in its
/// put), on [`now_ns`]'s clock [ns]; None when it carries none. Every host reads a message's
/// age, and the bench its transport time, with this one reading.
pub fn published_ns(s: &zenoh::sample::Sample) -> Option<u64> {
    s.timestamp().map(|t| t.get_time().as_nanos())
}

/// Nanoseconds since the UNIX epoch (the rig's acquisition clock).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(1, |d| d.as_nanos() as u64)
}

/// A TCP port on loopback that is free now and outside the kernel's ephemeral range. A port the
/// kernel hands out for port 0 comes from that range, as do the local ports of every outgoing
/// connection, so between this check and the later bind (Zenoh's) any connection the machine
/// opens may take it — a CI run lost a bench that way ("Address already in use"). Below the
/// range only another listener can, and the pick is random over some sixteen thousand ports.
/// Falls back to a port of the kernel's choosing when none of 64 picks binds.
pub fn free_loopback_port() -> std::io::Result<u16> {
    use std::hash::{BuildHasher, Hasher};
    use std::net::{Ipv4Addr, TcpListener};
    let (lo, hi) = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|s| {
            let mut v = s.split_whitespace().map(|p| p.parse::<u16>().ok());
            Some((v.next()??, v.next()??))
        })
        .unwrap_or((32768, 60999));
    let (from, to) = if lo >= 3024 {
        (lo.saturating_sub(16384).max(1024), lo)
    } else {
        (hi.saturating_add(1), u16::MAX)
    };
    let mut x = std::collections::hash_map::RandomState::new()
        .build_hasher()
        .finish();
    for _ in 0..64 {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let port = from + ((x >> 33) % u64::from((to - from).max(1))) as u16;
        if TcpListener::bind((Ipv4Addr::LOCALHOST, port)).is_ok() {
            return Ok(port);
        }
    }
    Ok(TcpListener::bind((Ipv4Addr::LOCALHOST, 0))?
        .local_addr()?
        .port())
}

/// The Zenoh config of one agent: the rig's mode and endpoints, CLI overrides winning.
/// Without any listen endpoint a peer listens on an ephemeral loopback port. Insecure: for
/// `rig bench`'s own sessions and tests; the rig's roles open with [`session_config`].
pub fn zenoh_config(z: &ZenohConfig, net: &NetOverrides) -> Result<zenoh::Config, RuntimeError> {
    Ok(plain_config(z, net, false)?.0)
}

/// The session config of the process `who` in `cfg`: [`zenoh_config`], and with `[security]`
/// mutual TLS with `who`'s certificate and the rig's access control ([`access_control`]).
pub fn session_config(
    cfg: &RigConfig,
    net: &NetOverrides,
    who: &Identity,
) -> Result<zenoh::Config, RuntimeError> {
    let who = &match &net.identity {
        Some(name) => Identity::parse(cfg, name).map_err(RuntimeError::Security)?,
        None => who.clone(),
    };
    let (mut c, listen, mode) = plain_config(&cfg.zenoh, net, cfg.security.is_some())?;
    let Some(sec) = &cfg.security else {
        let open: Vec<&String> = listen.iter().filter(|e| !on_loopback(e)).collect();
        if !open.is_empty() {
            eprintln!(
                "{}: INSECURE — listening on {} without [security]: anyone who reaches it can command the rig and forge samples (docs/SECURITY.md)",
                who.name(),
                open.iter()
                    .map(|e| e.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        return Ok(c);
    };
    let (cert, key) = (sec.cert(who), sec.key(who));
    for (what, f) in [
        ("the lab CA", &sec.ca),
        ("its certificate", &cert),
        ("its key", &key),
    ] {
        if !f.is_file() {
            return Err(RuntimeError::Security(format!(
                "{}: {what} {} is missing (make the lab's certificates with `rig certs --config {}`)",
                who.name(),
                f.display(),
                cfg.source.display()
            )));
        }
    }
    let path = |p: &std::path::Path| json!(p.to_string_lossy());
    let tls = json!({
        "root_ca_certificate": path(&sec.ca),
        "listen_certificate": path(&cert),
        "listen_private_key": path(&key),
        "connect_certificate": path(&cert),
        "connect_private_key": path(&key),
        "enable_mtls": true,
        // Who a peer is comes from its certificate's common name, checked against the lab
        // CA, not from the host name it was reached at (a lab's addresses change).
        "verify_name_on_connect": false,
    });
    set(&mut c, "transport/link/tls", tls)?;
    let trusted_hub = match (who, mode) {
        (Identity::Machine(_), ZenohMode::Client) => Some(who),
        _ => None,
    };
    set(&mut c, "access_control", access_control(cfg, trusted_hub)?)?;
    Ok(c)
}

/// Sets `k` to `v` (serde_json: an endpoint's characters are escaped, never spliced).
fn set(c: &mut zenoh::Config, k: &str, v: serde_json::Value) -> Result<(), RuntimeError> {
    c.insert_json5(k, &v.to_string())
        .map_err(|source| RuntimeError::Config {
            key: k.to_string(),
            source,
        })
}

/// Whether an endpoint's host is a loopback address.
fn on_loopback(e: &str) -> bool {
    let addr = e.split_once('/').map_or(e, |(_, a)| a);
    let host = addr.rsplit_once(':').map_or(addr, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// The mode and endpoints (`tls/` loopback by default when `secure`), without security.
fn plain_config(
    z: &ZenohConfig,
    net: &NetOverrides,
    secure: bool,
) -> Result<(zenoh::Config, Vec<String>, ZenohMode), RuntimeError> {
    let listen = if net.listen.is_empty() {
        z.listen.clone()
    } else {
        net.listen.clone()
    };
    let connect = if net.connect.is_empty() {
        z.connect.clone()
    } else {
        net.connect.clone()
    };
    for e in listen.iter().chain(&connect) {
        rig_config::check_endpoint(e)
            .and_then(|()| rig_config::endpoint_security(e, secure))
            .map_err(|why| RuntimeError::Endpoint {
                endpoint: e.clone(),
                why,
            })?;
    }
    let mode_of = net.mode.unwrap_or(z.mode);
    let mode = match mode_of {
        ZenohMode::Peer => "peer",
        ZenohMode::Client => "client",
        ZenohMode::Router => "router",
    };
    let listen = if listen.is_empty() && mode_of != ZenohMode::Client {
        let proto = if secure { "tls" } else { "tcp" };
        vec![format!("{proto}/127.0.0.1:0")]
    } else {
        listen
    };
    let mut c = zenoh::Config::default();
    set(&mut c, "mode", json!(mode))?;
    set(&mut c, "listen/endpoints", json!(listen))?;
    set(&mut c, "connect/endpoints", json!(connect))?;
    // A peer whose endpoint is not up yet (a launcher starting roles together, a machine
    // rebooting, a link back after a partition longer than the lease) retries from 100 ms,
    // doubling to 0.2 s, instead of Zenoh's 1 s to 4 s: a board is estimated again 0.14–0.38 s after
    // its link returns (tests/tests/deploy.rs, with docs/DEPLOY.md's neighbour setting).
    set(
        &mut c,
        "connect/retry",
        json!({"period_init_ms": 100, "period_max_ms": 200, "period_increase_factor": 2}),
    )?;
    set(&mut c, "scouting/multicast/enabled", json!(false))?;
    set(&mut c, "timestamping/enabled", json!(true))?;
    // Each link queues up to 16 batches of 64 KiB for data (Zenoh's most; default 2, taken
    // only as needed), so a board message that finds the tx thread a few ms behind waits in
    // the queue instead of being dropped after 1 ms: at 256 joints × 1 kHz (17 KB per tick)
    // two batches are 7 ticks, and two of seven 60 s runs lost whole board messages. A put
    // still never blocks the agent's loop (its watchdog runs there) for more than Zenoh's
    // 1 ms `wait_before_drop`: a link that is down drops, it does not stall the board.
    set(&mut c, "transport/link/tx/queue/size/data", json!(16))?;
    Ok((c, listen, mode_of))
}

/// Zenoh's access control for the rig (`access_control` in Zenoh's config), default deny:
/// a peer presenting identity X's certificate may publish (`put`) and declare liveliness
/// tokens only on X's keys ([`Identity::grants`]); every lab certificate may subscribe and
/// receive. `trusted_hub`: a client of its machine's hub (`rig launch`) accepts everything
/// from it, because the hub has already checked each message against its sender.
pub fn access_control(
    cfg: &RigConfig,
    trusted_hub: Option<&Identity>,
) -> Result<serde_json::Value, rig_protocol::KeyError> {
    let everything = rig_protocol::Keys::new(&cfg.name)?.all();
    let who_all = identities(cfg);
    let everyone: Vec<String> = who_all.iter().map(Identity::name).collect();
    let mut rules = vec![
        json!({
            "id": "listen",
            "messages": ["declare_subscriber", "declare_queryable", "reply",
                         "declare_liveliness_subscriber", "liveliness_query"],
            "flows": ["ingress", "egress"],
            "permission": "allow",
            "key_exprs": ["**"],
        }),
        json!({
            "id": "send",
            "messages": ["put", "delete", "query", "liveliness_token"],
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": ["**"],
        }),
    ];
    let mut subjects = vec![json!({"id": "lab", "cert_common_names": everyone})];
    let mut policies = vec![json!({"rules": ["listen", "send"], "subjects": ["lab"]})];
    for who in who_all {
        let name = who.name();
        let mut mine = Vec::new();
        let (put, query, alive) = if trusted_hub == Some(&who) {
            let all = vec![everything.clone()];
            (all.clone(), all.clone(), all)
        } else {
            let g = who.grants(cfg)?;
            (g.put, g.query, g.alive)
        };
        for (kind, messages, ks) in [
            ("put", json!(["put", "delete"]), put),
            ("query", json!(["query"]), query),
            ("alive", json!(["liveliness_token"]), alive),
        ] {
            if ks.is_empty() {
                continue;
            }
            let id = format!("{kind}-{name}");
            rules.push(json!({
                "id": id,
                "messages": messages,
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": ks,
            }));
            mine.push(id);
        }
        if mine.is_empty() {
            continue;
        }
        subjects.push(json!({"id": name, "cert_common_names": [name]}));
        policies.push(json!({"rules": mine, "subjects": [name]}));
    }
    Ok(json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }))
}

/// Declares a publisher on `key` after declaring the key expression itself, so peers map it
/// to a numeric id and cache its route. Without that, every message on a concrete key that
/// only matches a wildcard subscription is routed by matching the key against every known
/// resource — `rig bench throughput` found that routing to be 30 % of the CPU at 64 joints.
pub async fn publisher(
    session: &zenoh::Session,
    key: String,
) -> Result<zenoh::pubsub::Publisher<'static>, RuntimeError> {
    let declared = session.declare_keyexpr(key).await.map_err(zenoh_err)?;
    session.declare_publisher(declared).await.map_err(zenoh_err)
}

/// Opens the session of the process `who` ([`session_config`]).
pub async fn open(
    cfg: &RigConfig,
    net: &NetOverrides,
    who: &Identity,
) -> Result<zenoh::Session, RuntimeError> {
    let config = session_config(cfg, net, who)?;
    zenoh::open(config).await.map_err(RuntimeError::Session)
}

/// Waits until a liveliness token is up under each of `wanted` (full keys, e.g. from
/// `Keys::alive`: a role declares its token once its subscriptions are in place), or `timeout`
/// passes. Returns the keys still missing, in the order given (empty: every one is up).
/// Launchers wait on this instead of sleeping: a slow machine waits as long as it needs, a
/// fast one not at all.
pub async fn wait_alive(
    session: &zenoh::Session,
    wanted: &[String],
    timeout: std::time::Duration,
) -> Result<Vec<String>, RuntimeError> {
    use zenoh::sample::SampleKind;
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
    let mut subs = Vec::with_capacity(wanted.len());
    for key in wanted {
        let tx = tx.clone();
        subs.push(
            session
                .liveliness()
                .declare_subscriber(key.as_str())
                .history(true)
                .callback(move |s| {
                    let _ = tx.send((s.key_expr().to_string(), s.kind() == SampleKind::Put));
                })
                .await
                .map_err(zenoh_err)?,
        );
    }
    drop(tx);
    let mut up = std::collections::BTreeSet::new();
    let deadline = tokio::time::Instant::now() + timeout;
    while wanted.iter().any(|k| !up.contains(k)) {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Some((key, true))) => {
                up.insert(key);
            }
            Ok(Some((key, false))) => {
                up.remove(&key);
            }
            Ok(None) | Err(_) => break,
        }
    }
    for s in subs {
        s.undeclare().await.map_err(zenoh_err)?;
    }
    Ok(wanted
        .iter()
        .filter(|k| !up.contains(*k))
        .cloned()
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_free_loopback_port_binds_and_lies_outside_the_kernels_ephemeral_range() {
        let range = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
            .map(|s| {
                s.split_whitespace()
                    .map(|p| p.parse::<u16>().unwrap())
                    .collect::<Vec<_>>()
            })
            .unwrap_or_else(|_| vec![32768, 60999]);
        for _ in 0..20 {
            let port = free_loopback_port().unwrap();
            assert!(
                port < range[0] || port > range[1],
                "{port} within {range:?}"
            );
            std::net::TcpListener::bind(("127.0.0.1", port)).unwrap();
        }
    }

    #[test]
    fn a_flood_is_said_at_one_ten_a_hundred_and_so_on() {
        let said: Vec<u64> = (1..=100_000).filter(|&n| worth_a_line(n)).collect();
        assert_eq!(said, [1, 10, 100, 1000, 10_000, 100_000]);
        let mut b = LogBudget::default();
        let lines: Vec<u64> = (0..1000).filter_map(|_| b.count()).collect();
        assert_eq!(lines, [1, 10, 100, 1000]);
        assert!(!worth_a_line(0) && !worth_a_line(20) && !worth_a_line(110));
    }

    #[test]
    fn ticks_go_on_until_the_shutdown_or_the_duration_and_a_shutdown_wins_a_tie() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            let period = std::time::Duration::from_millis(1);
            let mut free = Ticks::new(period, None, std::future::pending());
            for _ in 0..3 {
                assert!(free.next().await);
            }
            // The first tick is due at once, and so is the shutdown: the shutdown wins.
            let mut stopped = Ticks::new(period, None, async {});
            assert!(!stopped.next().await);
            let mut over = Ticks::new(
                period,
                Some(std::time::Duration::ZERO),
                std::future::pending(),
            );
            assert!(!over.next().await);
        });
    }

    #[test]
    fn only_loopback_addresses_count_as_loopback() {
        for e in [
            "tcp/127.0.0.1:7447",
            "tls/[::1]:7447",
            "tcp/localhost:1",
            "tcp/127.9.0.1:2",
        ] {
            assert!(on_loopback(e), "{e}");
        }
        for e in [
            "tcp/0.0.0.0:7447",
            "tls/10.0.0.2:7447",
            "tcp/[::]:7447",
            "tcp/lab-host:1",
        ] {
            assert!(!on_loopback(e), "{e}");
        }
    }

    #[test]
    fn the_access_control_denies_by_default_and_grants_each_identity_its_own_keys() {
        let mut cfg = rig_config::examples::load("parallel").unwrap();
        let acl = access_control(&cfg, None).unwrap();
        assert_eq!(acl["enabled"], true);
        assert_eq!(acl["default_permission"], "deny");
        let rule = |acl: &serde_json::Value, id: &str| {
            acl["rules"]
                .as_array()
                .unwrap()
                .iter()
                .find(|r| r["id"] == id)
                .cloned()
        };
        let j1 = rule(&acl, "put-joint-j1").unwrap();
        assert_eq!(j1["flows"], json!(["ingress"]));
        assert_eq!(
            j1["key_exprs"],
            json!([
                "rig/parallel/joint/j1/sample",
                "rig/parallel/joint/j1/status",
                "rig/parallel/sim/joint/j1/truth"
            ])
        );
        assert_eq!(
            rule(&acl, "query-operator").unwrap()["key_exprs"],
            json!(["rig/parallel/allocate"])
        );
        // Listeners publish nothing: no put rule, and no subject of their own beyond the lab's.
        assert!(rule(&acl, "put-recorder").is_none());
        // A client of its machine's hub takes everything the hub forwards.
        let hub = Identity::Machine(cfg.machines[0].name.clone());
        let trusting = access_control(&cfg, Some(&hub)).unwrap();
        let name = hub.name();
        assert_eq!(
            rule(&trusting, &format!("put-{name}")).unwrap()["key_exprs"],
            json!(["rig/parallel/**"])
        );
        assert_ne!(
            rule(&acl, &format!("put-{name}")).unwrap()["key_exprs"],
            json!(["rig/parallel/**"])
        );
        // Missing certificate files are named with the command that makes them.
        cfg.security = Some(rig_config::SecurityConfig {
            ca: "/nonexistent/ca.pem".into(),
            certs: "/nonexistent".into(),
        });
        let e = session_config(&cfg, &NetOverrides::default(), &Identity::Estimator)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/nonexistent/ca.pem") && e.contains("rig certs"),
            "{e}"
        );
        // With [security], a plain endpoint on the command line is refused too.
        let net = NetOverrides {
            connect: vec!["tcp/127.0.0.1:7447".into()],
            ..Default::default()
        };
        let e = session_config(&cfg, &net, &Identity::Estimator)
            .unwrap_err()
            .to_string();
        assert!(e.contains("mutual TLS"), "{e}");
    }

    #[test]
    fn overrides_win_and_bad_endpoints_are_refused() {
        let z = ZenohConfig {
            mode: ZenohMode::Peer,
            listen: vec!["tcp/127.0.0.1:7000".into()],
            connect: vec![],
        };
        assert!(zenoh_config(&z, &NetOverrides::default()).is_ok());
        let net = NetOverrides {
            listen: vec!["nonsense".into()],
            ..Default::default()
        };
        assert!(matches!(
            zenoh_config(&z, &net),
            Err(RuntimeError::Endpoint { .. })
        ));
    }

    /// Two peers on loopback: the first listens on a port of `base` + (pid mod 1000), the
    /// second connects to it.
    async fn two_peers(base: u16) -> (zenoh::Session, zenoh::Session) {
        let z = ZenohConfig {
            mode: ZenohMode::Peer,
            listen: vec![],
            connect: vec![],
        };
        let hub = format!(
            "tcp/127.0.0.1:{}",
            base + (std::process::id() % 1000) as u16
        );
        let net = |listen: bool| NetOverrides {
            listen: if listen { vec![hub.clone()] } else { vec![] },
            connect: if listen { vec![] } else { vec![hub.clone()] },
            ..Default::default()
        };
        let open = |n: NetOverrides| zenoh::open(zenoh_config(&z, &n).unwrap());
        let a = open(net(true)).await.unwrap();
        let b = open(net(false)).await.unwrap();
        (a, b)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn two_peers_on_loopback_exchange_bytes() {
        let (a, b) = two_peers(17447).await;
        let sub = b.declare_subscriber("rig/test/**").await.unwrap();
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        a.put("rig/test/x", vec![1u8, 2, 3]).await.unwrap();
        let s = tokio::time::timeout(std::time::Duration::from_secs(5), sub.recv_async())
            .await
            .unwrap()
            .unwrap();
        assert_eq!(s.payload().to_bytes().as_ref(), &[1, 2, 3]);
        assert!(s.timestamp().is_some(), "timestamping is on");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn wait_alive_returns_once_a_peers_token_is_up_and_names_the_keys_that_never_came() {
        use std::time::{Duration, Instant};
        let (a, b) = two_peers(18447).await;
        let (up, never) = ("rig/t/alive/joint/j1".to_string(), "rig/t/alive/joint/j9");
        // The token comes 200 ms after the wait starts: the wait sees it arrive.
        let declarer = tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(200)).await;
            let token = b
                .liveliness()
                .declare_token("rig/t/alive/joint/j1")
                .await
                .unwrap();
            (b, token)
        });
        let t0 = Instant::now();
        let missing = wait_alive(&a, std::slice::from_ref(&up), Duration::from_secs(10))
            .await
            .unwrap();
        assert!(missing.is_empty(), "{missing:?}");
        assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
        // The session and its token stay up from here on.
        let _b_and_token = declarer.await.unwrap();
        // Already up: at once (history); one that never comes: named after the timeout.
        let t0 = Instant::now();
        let wanted = [up.clone(), never.to_string()];
        let missing = wait_alive(&a, &wanted, Duration::from_millis(300))
            .await
            .unwrap();
        assert_eq!(missing, [never]);
        assert!(t0.elapsed() >= Duration::from_millis(300));
    }
}
