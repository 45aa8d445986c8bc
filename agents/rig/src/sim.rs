//! `rig sim --scenario FILE --out data.csv`: run a scenario into a sensor stream.

use std::path::PathBuf;

use rig_sim::scenario::{self, Scenario};

use crate::error::CliError;
use crate::progress;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario file (TOML), e.g. agents/sim/scenarios/lever-bench.toml
    #[arg(long, value_name = "FILE")]
    scenario: PathBuf,
    /// Output file; .csv (columns documented in agents/sim/SCENARIOS.md)
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let s = Scenario::load(&args.scenario)?;
    match args.out.extension().and_then(|e| e.to_str()) {
        Some("csv") => {}
        _ => {
            return Err(CliError::Unsupported(format!(
                "{}: only .csv output exists today (MCAP arrives with the runtime)",
                args.out.display()
            )));
        }
    }
    let w = std::cell::RefCell::new(
        csv::Writer::from_path(&args.out).map_err(|e| CliError::Io(std::io::Error::other(e)))?,
    );
    let pb = progress::bar(
        s.samples(),
        &format!("simulating {} ({} s)", s.kind, s.duration_s),
    );
    let mut rows = 0u64;
    scenario::run(
        &s,
        &mut |h| w.borrow_mut().write_record(h).map_err(|e| e.to_string()),
        &mut |r| {
            rows += 1;
            w.borrow_mut()
                .write_record(r.iter().map(|v| format!("{v}")))
                .map_err(|e| e.to_string())
        },
        &mut |done| pb.set_position(done),
    )?;
    w.borrow_mut().flush()?;
    pb.finish_and_clear();
    eprintln!("wrote {rows} samples to {}", args.out.display());
    Ok(())
}
