//! # rig-runtime — the rig's Zenoh edge
//!
//! Opens Zenoh sessions the way every agent of the rig needs them: the mode and endpoints
//! from the rig config, overridden by `--listen` / `--connect`, **multicast scouting off**
//! (peers find each other through the endpoints given and gossip over the links they have,
//! so nothing leaves the machine unless an endpoint says so), timestamping on. Also the one
//! clock every agent stamps with.

use std::time::{SystemTime, UNIX_EPOCH};

use rig_config::{ZenohConfig, ZenohMode};
use thiserror::Error;

pub use zenoh;

/// Errors of the Zenoh edge.
#[derive(Debug, Error)]
pub enum RuntimeError {
    #[error("zenoh configuration: {0}")]
    Config(String),
    #[error("zenoh session: {0}")]
    Session(String),
    #[error("invalid endpoint {endpoint:?}: {why}")]
    Endpoint { endpoint: String, why: String },
    /// A Zenoh operation (declare, put, reply, close) failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A key expression could not be built from the config's names.
    #[error("{0}")]
    Key(#[from] rig_protocol::KeyError),
}

/// Wraps any Zenoh error, for `.map_err(zenoh_err)?` at the edges.
pub fn zenoh_err<E: std::fmt::Display>(e: E) -> RuntimeError {
    RuntimeError::Zenoh(e.to_string())
}

/// Endpoint overrides from the command line.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NetOverrides {
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

/// Nanoseconds since the UNIX epoch (the rig's acquisition clock).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(1, |d| d.as_nanos() as u64)
}

fn json_list(v: &[String]) -> String {
    let quoted: Vec<String> = v
        .iter()
        .map(|e| format!("\"{}\"", e.replace('"', "")))
        .collect();
    format!("[{}]", quoted.join(","))
}

/// The Zenoh config of one agent: the rig's mode and endpoints, CLI overrides winning.
/// Without any listen endpoint a peer listens on an ephemeral loopback port.
pub fn zenoh_config(z: &ZenohConfig, net: &NetOverrides) -> Result<zenoh::Config, RuntimeError> {
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
        rig_config::check_endpoint(e).map_err(|why| RuntimeError::Endpoint {
            endpoint: e.clone(),
            why,
        })?;
    }
    let mode = match z.mode {
        ZenohMode::Peer => "peer",
        ZenohMode::Client => "client",
        ZenohMode::Router => "router",
    };
    let listen = if listen.is_empty() && z.mode != ZenohMode::Client {
        vec!["tcp/127.0.0.1:0".to_string()]
    } else {
        listen
    };
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| RuntimeError::Config(format!("{k}: {e}")))
    };
    set(&mut c, "mode", &format!("\"{mode}\""))?;
    set(&mut c, "listen/endpoints", &json_list(&listen))?;
    set(&mut c, "connect/endpoints", &json_list(&connect))?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    set(&mut c, "timestamping/enabled", "true")?;
    Ok(c)
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

/// Opens a session.
pub async fn open(z: &ZenohConfig, net: &NetOverrides) -> Result<zenoh::Session, RuntimeError> {
    let config = zenoh_config(z, net)?;
    zenoh::open(config)
        .await
        .map_err(|e| RuntimeError::Session(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

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
            connect: vec![],
        };
        assert!(matches!(
            zenoh_config(&z, &net),
            Err(RuntimeError::Endpoint { .. })
        ));
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn two_peers_on_loopback_exchange_bytes() {
        let z = ZenohConfig {
            mode: ZenohMode::Peer,
            listen: vec![],
            connect: vec![],
        };
        let port = 17447 + (std::process::id() % 1000) as u16;
        let a = open(
            &z,
            &NetOverrides {
                listen: vec![format!("tcp/127.0.0.1:{port}")],
                connect: vec![],
            },
        )
        .await
        .unwrap();
        let b = open(
            &z,
            &NetOverrides {
                listen: vec![],
                connect: vec![format!("tcp/127.0.0.1:{port}")],
            },
        )
        .await
        .unwrap();
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
}
