//! Runs every scenario at full length with the host controllers and prints
//! one JSON summary per scenario; `--short` runs the shortened versions,
//! `--seed N` picks the seed, `--csv DIR` writes the logs.

use ocm_hilsim::{SCENARIOS, SimConfig, run_scenario};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut cfg = SimConfig::default();
    let mut csv_dir = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--short" => cfg.short = true,
            "--seed" => cfg.seed = args.next().ok_or("--seed needs a value")?.parse()?,
            "--csv" => {
                csv_dir = Some(std::path::PathBuf::from(
                    args.next().ok_or("--csv needs a directory")?,
                ))
            }
            other => return Err(format!("unknown argument {other:?}").into()),
        }
    }
    for name in SCENARIOS {
        let report = run_scenario(name, &cfg)?;
        if let Some(dir) = &csv_dir {
            report.write_csv(dir)?;
        }
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
}
