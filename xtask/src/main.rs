//! `cargo xtask test [ARGS…]`: the README's test command on a fresh machine.
//!
//! The tests check the rig against tools other people wrote — the Python `eclipse-zenoh`
//! client decoding our wire format, the `rerun` CLI verifying our viewer files, Python's `mcap`
//! and `jsonschema` reading our recordings — and they fail,
//! rightly, when those are missing. This task makes them present: a project-local Python
//! environment (`.venv/`, made with `python3 -m venv --system-site-packages`, so what the
//! machine already has is reused) with the pinned packages installed where they are missing;
//! then `cargo test --workspace --release --no-fail-fast ARGS…` with `RIG_TOOLS_BIN` naming its `bin`, where
//! the tests look for `python3` and `rerun` first. `PATH` stays as it is: build scripts that
//! watch it would otherwise rebuild half the tree for the tests.
//!
//! Needs `python3` with its `venv` module (Debian/Ubuntu: `apt install python3 python3-venv`)
//! and, on the first run, network access to PyPI.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// The Python packages the tests use, pinned to the versions the Rust crates speak:
/// (what to import or run to check it, the pip requirement).
const ZENOH: &str = "eclipse-zenoh==1.10.2";
const RERUN: &str = "rerun-sdk==0.36.3";
const RERUN_VERSION: &str = " 0.36.3";
/// A recording's independent reader: MCAP and JSON Schema (protocol/python/read_recording.py).
const MCAP: &str = "mcap==1.2.2";
const JSONSCHEMA: &str = "jsonschema==4.26.0";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Runs `cmd`, its output shown; an error naming it when it cannot start or fails.
fn run(cmd: &mut Command, what: &str) -> Result<(), String> {
    match cmd.status() {
        Ok(s) if s.success() => Ok(()),
        Ok(s) => Err(format!("{what} failed ({s})")),
        Err(e) => Err(format!("{what}: cannot start: {e}")),
    }
}

/// Whether `cmd` runs and exits 0 (its output hidden).
fn succeeds(cmd: &mut Command) -> bool {
    cmd.stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// `PATH` with `bin` first.
fn path_with(bin: &Path) -> std::ffi::OsString {
    let mut dirs = vec![bin.to_path_buf()];
    if let Some(p) = std::env::var_os("PATH") {
        dirs.extend(std::env::split_paths(&p));
    }
    std::env::join_paths(dirs).unwrap_or_default()
}

/// The project's Python environment, made and completed as needed; its `bin` directory.
fn python_env(root: &Path) -> Result<PathBuf, String> {
    let venv = root.join(".venv");
    let bin = venv.join("bin");
    if !bin.join("python3").exists() {
        eprintln!("xtask: making the Python environment {}", venv.display());
        run(
            Command::new("python3")
                .args(["-m", "venv", "--system-site-packages"])
                .arg(&venv),
            "python3 -m venv (needs python3 with venv: `apt install python3 python3-venv`)",
        )?;
    }
    let python = bin.join("python3");
    let path = path_with(&bin);
    let pip = |req: &str| {
        eprintln!("xtask: installing {req} into {}", venv.display());
        run(
            Command::new(&python).args(["-m", "pip", "install", "-q", req]),
            &format!("pip install {req}"),
        )
    };
    for (module, req) in [("zenoh", ZENOH), ("mcap", MCAP), ("jsonschema", JSONSCHEMA)] {
        if !succeeds(Command::new(&python).args(["-c", &format!("import {module}")])) {
            pip(req)?;
        }
    }
    let rerun_ok = || {
        Command::new("rerun")
            .arg("--version")
            .env("PATH", &path)
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains(RERUN_VERSION))
    };
    if !rerun_ok() {
        pip(RERUN)?;
        if !rerun_ok() {
            return Err(format!(
                "after installing {RERUN}, `rerun --version` does not say{RERUN_VERSION}"
            ));
        }
    }
    // Nothing leaves the machine: the viewer's usage analytics off before its first real use.
    let _ = succeeds(
        Command::new("rerun")
            .args(["analytics", "disable"])
            .env("PATH", &path),
    );
    Ok(bin)
}

fn test(args: &[String]) -> Result<(), String> {
    let root = root();
    let bin = python_env(&root)?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(&root)
        .args(["test", "--workspace", "--release", "--no-fail-fast"])
        .args(args)
        .env("RIG_TOOLS_BIN", &bin);
    // `cargo xtask` is `cargo run -p xtask`, which sets the xtask package's own variables in
    // our environment. Build scripts that watch them (ring's reads CARGO_PKG_NAME and others)
    // would see them changed from the run command's build and rebuild ring, rustls, zenoh,
    // Rerun and all above them for the tests: the inner cargo must see what a shell sees.
    for (key, _) in std::env::vars_os() {
        let k = key.to_string_lossy();
        if k.starts_with("CARGO_PKG_")
            || matches!(
                k.as_ref(),
                "CARGO_MANIFEST_DIR"
                    | "CARGO_MANIFEST_PATH"
                    | "CARGO_MANIFEST_LINKS"
                    | "CARGO_CRATE_NAME"
                    | "CARGO_BIN_NAME"
                    | "CARGO_PRIMARY_PACKAGE"
            )
        {
            cmd.env_remove(&key);
        }
    }
    run(&mut cmd, "cargo test")
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test(&args[1..]),
        _ => {
            eprintln!(
                "usage: cargo xtask test [CARGO TEST ARGS…]\n\n  test  set up the test tools (a project-local Python environment in .venv/ with\n        {ZENOH}, {RERUN}, {MCAP}, {JSONSCHEMA}) and run `cargo test --workspace --release --no-fail-fast` (every failing test binary reported)"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
