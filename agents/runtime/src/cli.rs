//! The command-line pieces every role shares, flattened into its arguments the way Rerun's
//! `RerunArgs` is: the Zenoh endpoints ([`NetArgs`]), how long to run ([`RunFor`]), and the
//! async runtime the role runs on ([`tokio_runtime`]).

use std::time::Duration;

use rig_config::ZenohMode;

use crate::NetOverrides;

/// Zenoh endpoints from the command line; each list, when given, replaces the config's.
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct NetArgs {
    /// Zenoh endpoints to listen on, e.g. tcp/0.0.0.0:7447 (replace the config's `[zenoh].listen`)
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to, e.g. tcp/10.0.0.2:7447 (replace the config's `[zenoh].connect`)
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Zenoh mode instead of the config's `[zenoh].mode`: peer, client (joins through the
    /// endpoints it connects to; what `rig launch` gives a machine's roles) or router
    #[arg(long, value_name = "MODE", value_parser = mode)]
    pub mode: Option<ZenohMode>,
    /// With [security]: present this identity's certificate instead of the role's own, e.g.
    /// machine-board1 (what `rig launch` gives a machine's roles; docs/SECURITY.md)
    #[arg(long, value_name = "NAME")]
    pub identity: Option<String>,
}

fn mode(s: &str) -> Result<ZenohMode, String> {
    match s {
        "peer" => Ok(ZenohMode::Peer),
        "client" => Ok(ZenohMode::Client),
        "router" => Ok(ZenohMode::Router),
        _ => Err(format!(
            "{s:?} is no Zenoh mode: write peer, client or router"
        )),
    }
}

impl NetArgs {
    /// The overrides [`crate::open`] and [`crate::zenoh_config`] take.
    pub fn overrides(&self) -> NetOverrides {
        NetOverrides {
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            mode: self.mode,
            identity: self.identity.clone(),
        }
    }
}

/// How long a role runs: `--duration SECONDS`, or until Ctrl-C when left out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::Args)]
pub struct RunFor {
    /// Stop after this many seconds (a positive number, at most a year; default: until Ctrl-C)
    #[arg(long, value_name = "SECONDS", value_parser = positive_seconds, allow_negative_numbers = true)]
    pub duration: Option<Duration>,
}

/// The longest run `--duration` accepts: a year. Longer is a typo (or `1e20`), and left out
/// the role runs until stopped anyway.
pub const LONGEST_RUN: Duration = Duration::from_secs(366 * 24 * 3600);

/// Parses a positive, finite number of seconds up to [`LONGEST_RUN`]; the error says what was
/// given and what to write instead.
pub fn positive_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds (e.g. 10 or 2.5)"))?;
    if !v.is_finite() || v <= 0.0 {
        return Err(format!(
            "{s} is not a positive number of seconds; leave --duration out to run until Ctrl-C"
        ));
    }
    if v > LONGEST_RUN.as_secs_f64() {
        return Err(format!(
            "{s} s is longer than a year; leave --duration out to run until Ctrl-C"
        ));
    }
    Ok(Duration::from_secs_f64(v))
}

/// The multi-threaded Tokio runtime a role runs on (`worker_threads`: `None` for Tokio's
/// default of one per core), with I/O and timers.
pub fn tokio_runtime(worker_threads: Option<usize>) -> std::io::Result<tokio::runtime::Runtime> {
    let mut b = tokio::runtime::Builder::new_multi_thread();
    if let Some(n) = worker_threads {
        b.worker_threads(n.max(1));
    }
    b.enable_all().build()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        net: NetArgs,
        #[command(flatten)]
        run: RunFor,
    }

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("role").chain(args.iter().copied()))
    }

    #[test]
    fn a_positive_duration_parses_to_seconds_and_none_runs_until_stopped() {
        let c = parse(&["--duration", "2.5", "--connect", "tcp/127.0.0.1:7447"]).unwrap();
        assert_eq!(c.run.duration, Some(Duration::from_millis(2500)));
        assert_eq!(c.net.overrides().connect, ["tcp/127.0.0.1:7447"]);
        assert!(c.net.overrides().listen.is_empty());
        assert_eq!(parse(&[]).unwrap().run.duration, None);
    }

    #[test]
    fn zero_negative_nan_infinite_and_absurd_durations_are_refused_with_the_flag_named() {
        for bad in ["0", "-1", "nan", "inf", "1e20", "ten"] {
            let e = parse(&["--duration", bad]).unwrap_err().to_string();
            assert!(e.contains("--duration"), "{bad}: {e}");
            assert!(e.contains(bad), "{bad}: {e}");
        }
        assert!(positive_seconds("31622400").is_ok());
        assert!(positive_seconds("31622401").is_err());
    }
}
