//! `ocm track`: the dissertation's experiments in the virtual lab, with the
//! host controllers (open loop, model feed-forward + PID, and the oracle).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ocm_hilsim::firmware::run_scenario_with_firmware;
use ocm_hilsim::{SCENARIOS, SimConfig, run_scenario};

/// Which controller sits in the loop as the MCU.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum McuMode {
    /// The host's own controllers (open loop, feed-forward + PID).
    Host,
    /// The firmware library linked in process, fed the same protocol
    /// frames a real board gets, in open and closed loop.
    Inproc,
}

/// Arguments of `ocm track`.
#[derive(clap::Args, Debug)]
pub struct TrackArgs {
    /// Scenario name, or `all`.
    #[arg(long, default_value = "all")]
    scenario: String,
    /// Seed of every random process (noise, manufacturing spread, targets).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Shortened runs (a few seconds each) for a quick look.
    #[arg(long)]
    short: bool,
    /// Print one JSON summary per scenario.
    #[arg(long)]
    json: bool,
    /// Write CSV logs and `summary.json` here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// The controller under test; the oracle always runs beside it.
    #[arg(long, value_enum, default_value = "host")]
    mcu: McuMode,
}

/// Runs `ocm track`.
pub fn run(args: TrackArgs) -> Result<()> {
    let names: Vec<&str> = if args.scenario == "all" {
        SCENARIOS.to_vec()
    } else if let Some(n) = SCENARIOS.iter().find(|n| **n == args.scenario) {
        vec![n]
    } else {
        bail!(
            "unknown scenario `{}`; choose one of {} or all",
            args.scenario,
            SCENARIOS.join(", ")
        );
    };
    let cfg = SimConfig {
        seed: args.seed,
        short: args.short,
        ..SimConfig::default()
    };
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    if !args.json {
        println!(
            "{:<12} {:>10} {:>10} {:>10} {:>10}",
            "scenario", "OL mm", "CL mm", "oracle mm", "x realtime"
        );
    }
    let mut all = Vec::new();
    for name in names {
        let report = if args.mcu == McuMode::Inproc && name != "rom" {
            run_scenario_with_firmware(name, &cfg).map_err(anyhow::Error::from)
        } else {
            run_scenario(name, &cfg).map_err(anyhow::Error::from)
        }
        .with_context(|| format!("scenario {name}"))?;
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        } else {
            println!(
                "{:<12} {:>10} {:>10} {:>10} {:>10.0}",
                name,
                fmt(report.ol_rmse_mm),
                fmt(report.cl_rmse_mm),
                fmt(report.oracle_rmse_mm),
                report.realtime_factor
            );
            for (k, v) in &report.figures {
                println!("    {k} = {v:.4}");
            }
        }
        if let Some(dir) = &args.out {
            report
                .write_csv(dir)
                .with_context(|| format!("writing logs of {name}"))?;
        }
        all.push(report);
    }
    if let Some(dir) = &args.out {
        let path = dir.join("summary.json");
        std::fs::write(&path, serde_json::to_string_pretty(&all)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
