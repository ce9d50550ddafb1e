//! `ocm track`: the dissertation's experiments in the virtual lab, with the
//! host controllers (open loop, model feed-forward + PID, and the oracle).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ocm_hilsim::firmware::{FirmwareMcu, LUT_CAPACITY, lut_image};
use ocm_hilsim::{
    ControllerKind, SCENARIOS, ScenarioReport, SimConfig, run_scenario, run_with_mcu,
};

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

/// Runs a time-domain scenario with the in-process firmware in open and
/// closed loop, and the host oracle as the floor.
fn run_firmware(name: &str, cfg: &SimConfig) -> Result<ScenarioReport> {
    let image = lut_image(&cfg.plant, &cfg.limits)?;
    let mut runs = Vec::new();
    for (closed, label) in [(false, "firmware_ol"), (true, "firmware_cl")] {
        let mut buf = vec![0u8; LUT_CAPACITY];
        let mut fw = FirmwareMcu::new(
            &mut buf,
            &image,
            &cfg.plant,
            &cfg.hall,
            &cfg.gains,
            &cfg.limits,
            closed,
        )?;
        let mut run = run_with_mcu(name, cfg, &mut fw)?;
        run.controller = label.to_string();
        runs.push(run);
    }
    let oracle_cfg = SimConfig {
        controllers: vec![ControllerKind::Oracle],
        ..cfg.clone()
    };
    let mut report = run_scenario(name, &oracle_cfg)?;
    report.ol_rmse_mm = Some(runs[0].rmse_mm);
    report.cl_rmse_mm = Some(runs[1].rmse_mm);
    let (sim, wall) = runs.iter().fold((0.0, 0.0), |(s, w), r| {
        (s + r.sim_s, w + r.sim_s / r.realtime_factor.max(1e-12))
    });
    report.realtime_factor = if wall > 0.0 { sim / wall } else { 0.0 };
    report.runs.extend(runs);
    Ok(report)
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
            run_firmware(name, &cfg)
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
