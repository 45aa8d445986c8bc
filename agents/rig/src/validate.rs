//! `rig validate FILE…`

use std::path::PathBuf;

use rig_config::{JointKind, RigConfig};

use crate::error::CliError;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rig config files (TOML), e.g. rig-config/examples/parallel.toml
    #[arg(required = true, value_name = "FILE")]
    files: Vec<PathBuf>,
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let mut failed = 0usize;
    for f in &args.files {
        match rig_config::load(f) {
            Ok(cfg) => {
                // The files [security] names: there, made out to each identity, signed by
                // the lab's CA, valid now.
                let problems = crate::certs::check(&cfg);
                if problems.is_empty() {
                    println!("ok: {}: {}", f.display(), summary(&cfg));
                    print!("{}", plan(&cfg));
                } else {
                    for p in &problems {
                        eprintln!("{}: {p}", f.display());
                    }
                    failed += 1;
                }
            }
            Err(e) => {
                eprintln!("{e}");
                failed += 1;
            }
        }
    }
    match failed {
        0 => Ok(()),
        n => Err(CliError::Invalid(format!(
            "{n} of {} config files invalid",
            args.files.len()
        ))),
    }
}

fn summary(cfg: &RigConfig) -> String {
    let kinds: Vec<String> = cfg
        .joints
        .iter()
        .map(|j| {
            let kind = match &j.kind {
                JointKind::Lever { .. } => "lever",
                JointKind::Awas { .. } => "awas",
            };
            format!(
                "{} ({kind}, k {:.4}..{:.4} N·m/rad)",
                j.name, j.limits.k_min, j.limits.k_max
            )
        })
        .collect();
    format!(
        "rig \"{}\", {} topology at {} Hz; joints: {}; {}",
        cfg.name,
        cfg.topology.name(),
        cfg.rate_hz,
        kinds.join(", "),
        if cfg.security.is_some() {
            "secured: mutual TLS, access control by role"
        } else {
            "insecure (no [security]): for loopback and trusted networks"
        }
    )
}

/// The plan (`[[machine]]`), one line per machine: what it runs, how it joins the others.
/// Empty without a plan.
pub fn plan(cfg: &RigConfig) -> String {
    let mut out = String::new();
    for (i, m) in cfg.machines.iter().enumerate() {
        let roles: Vec<&str> = m.roles.iter().map(|r| r.name()).collect();
        out += &format!(
            "{} machine \"{}\" runs {}; listens on {}; connects to {}\n",
            if i == 0 { "  plan:" } else { "       " },
            m.name,
            or_nothing(&roles),
            or_nothing(&m.listen),
            or_nothing(&m.connect)
        );
    }
    out
}

/// A list joined with commas, or "nothing" when it is empty.
pub fn or_nothing<S: AsRef<str>>(v: &[S]) -> String {
    if v.is_empty() {
        "nothing".to_string()
    } else {
        v.iter().map(AsRef::as_ref).collect::<Vec<_>>().join(", ")
    }
}
