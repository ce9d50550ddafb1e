//! `ocm track`: the dissertation's experiments in the virtual lab. The
//! firmware runs in open and closed loop, in process, under QEMU or on a
//! real board, beside the oracle; `--mcu host` runs the host controllers.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use ocm_hilsim::firmware::{lut_image, run_scenario_over, run_scenario_with_image};
use ocm_hilsim::qemu::{QemuLink, build_board};
use ocm_hilsim::serial::SerialLink;
use ocm_hilsim::{SCENARIOS, ScenarioReport, SimConfig, run_scenario, working_limits};

use crate::plot_track;

/// Which controller sits in the loop as the MCU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum McuMode {
    /// The host's own controllers (open loop, feed-forward + PID).
    Host,
    /// The firmware library linked in process, fed the same protocol
    /// messages a real board gets.
    Inproc,
    /// The firmware binary in qemu-system-arm over its UART pty (PIL).
    Qemu,
    /// A real board on a serial port.
    Port(String),
}

impl McuMode {
    /// Report label.
    fn label(&self) -> String {
        match self {
            Self::Host => "host".into(),
            Self::Inproc => "inproc".into(),
            Self::Qemu => "qemu".into(),
            Self::Port(p) => format!("port:{p}"),
        }
    }
}

fn parse_mcu(s: &str) -> Result<McuMode, String> {
    match s {
        "host" => Ok(McuMode::Host),
        "inproc" => Ok(McuMode::Inproc),
        "qemu" => Ok(McuMode::Qemu),
        _ => match s.strip_prefix("port:") {
            Some(p) if !p.is_empty() => Ok(McuMode::Port(p.to_string())),
            _ => Err(format!(
                "`{s}`: expected host, inproc, qemu or port:PATH (e.g. port:/dev/ttyACM0)"
            )),
        },
    }
}

/// A lab scenario (the dissertation's experiments), or all of them.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scenario {
    /// Every scenario below, in this order.
    All,
    /// Range of motion: the model's reachable tip positions against the plant's (no controller).
    Rom,
    /// A triangle traced with the tip at constant speed.
    Triangle,
    /// A circle traced with the tip at constant speed.
    Circle,
    /// Random target points held 10 s each, with an announced 250 g payload.
    Points,
    /// A held tilted pose while an announced tip force ramps up.
    Orientation,
    /// The circle with one chamber's supply cut for 5 s and restored.
    Disconnect,
    /// A held pose when an unannounced 250 g load is hung on the tip.
    #[value(name = "step_load")]
    StepLoad,
}

impl Scenario {
    /// The scenarios this choice runs, by their lab names.
    fn names(self) -> Vec<&'static str> {
        use clap::ValueEnum;
        match self {
            Self::All => SCENARIOS.to_vec(),
            one => {
                let v = one.to_possible_value().expect("every scenario has a name");
                SCENARIOS
                    .iter()
                    .copied()
                    .filter(|n| *n == v.get_name())
                    .collect()
            }
        }
    }
}

/// Arguments of `ocm track`.
#[derive(clap::Args, Debug)]
pub struct TrackArgs {
    /// Which experiment to run.
    #[arg(long, value_enum, default_value_t = Scenario::All)]
    scenario: Scenario,
    /// Seed of every random process (noise, manufacturing spread, targets);
    /// default 1.
    #[arg(long)]
    seed: Option<u64>,
    /// Shortened runs (a few seconds each) for a quick look.
    #[arg(long)]
    short: bool,
    /// Print one JSON summary per scenario.
    #[arg(long)]
    json: bool,
    /// Write CSV logs, `summary.json` and plots (PNG and SVG) here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// The MCU under test: inproc, qemu, port:PATH, or host (the host's
    /// own controllers). The oracle always runs beside it.
    #[arg(long, default_value = "inproc", value_parser = parse_mcu)]
    mcu: McuMode,
    /// Cut every time-domain scenario after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
    /// Firmware ELF for `--mcu qemu` (default: build firmware/boards/qemu).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Baud rate for `--mcu port:PATH`.
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// LUT image to load into the firmware (default: build one from the
    /// energy model for the lab's working pressure range).
    #[arg(long)]
    lut: Option<PathBuf>,
    /// Lab settings (TOML: plant, effects, sensors, gains, limits; see
    /// hil-sim/lab.toml); --seed, --short and --duration override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// OCM parameter set of the plant and the LUT, in place of a config
    /// file: `calibrated` (default) or `table-3.1` (with a vacuum-capable
    /// regulator, -20..35 kPa, which its softness needs).
    #[arg(long, value_enum, conflicts_with = "config")]
    params: Option<crate::cmd_lut::Params>,
}

/// Reads the lab settings from TOML. Command limits the file leaves out
/// are derived from its plant, not the default one.
fn read_config(path: &std::path::Path) -> Result<SimConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut cfg: SimConfig =
        toml::from_str(&text).with_context(|| format!("in {}", path.display()))?;
    let table: toml::Table =
        toml::from_str(&text).with_context(|| format!("in {}", path.display()))?;
    if !table.contains_key("limits") {
        cfg.limits = working_limits(&cfg.plant);
    }
    cfg.validate()
        .with_context(|| format!("in {}", path.display()))?;
    Ok(cfg)
}

/// Where the firmware runs and what it is given.
struct Mcu<'a> {
    mode: &'a McuMode,
    elf: Option<PathBuf>,
    baud: u32,
    image: Vec<u8>,
}

/// Runs one scenario with the chosen MCU.
fn run_one(name: &str, cfg: &SimConfig, mcu: &Mcu) -> Result<ScenarioReport> {
    // `rom` is a static comparison of model and plant: no controller.
    if name == "rom" || *mcu.mode == McuMode::Host {
        return Ok(run_scenario(name, cfg)?);
    }
    let image = &mcu.image;
    Ok(match mcu.mode {
        McuMode::Qemu => {
            let elf = mcu.elf.as_ref().context("no firmware ELF")?;
            run_scenario_over(name, cfg, image, false, || QemuLink::boot(elf))?
        }
        McuMode::Port(path) => run_scenario_over(name, cfg, image, false, || {
            SerialLink::open(path, mcu.baud, Duration::from_secs(5))
        })?,
        _ => run_scenario_with_image(name, cfg, image)?,
    })
}

/// Runs `ocm track`.
pub fn run(args: TrackArgs) -> Result<()> {
    let names = args.scenario.names();
    let base = match (&args.config, args.params) {
        (Some(path), _) => read_config(path)?,
        (None, Some(p)) => SimConfig::with_preset(p.into()),
        (None, None) => SimConfig::default(),
    };
    let cfg = SimConfig {
        seed: args.seed.unwrap_or(base.seed),
        short: args.short || base.short,
        duration_cap_s: args.duration.or(base.duration_cap_s),
        ..base
    };
    let elf = match (&args.mcu, &args.elf) {
        (McuMode::Qemu, Some(e)) => Some(e.clone()),
        (McuMode::Qemu, None) => {
            if !args.json {
                eprintln!("building the QEMU board (firmware/boards/qemu) ...");
            }
            Some(build_board()?)
        }
        _ => None,
    };
    // The host's own controllers need no LUT image.
    let image = match (&args.lut, &args.mcu) {
        (_, McuMode::Host) => Vec::new(),
        (Some(path), _) => {
            let bytes = std::fs::read(path)
                .with_context(|| format!("reading the LUT {}", path.display()))?;
            // checked here, where the file's name is known: the firmware's refusal names
            // neither the file nor the reason
            let image = ocm_shared::lut::LutImage::parse(&bytes).map_err(|e| {
                anyhow::anyhow!(
                    "{}: invalid LUT image: {e:?} (`ocm lut check` says more)",
                    path.display()
                )
            })?;
            let want = cfg.plant.ocm.hash();
            if image.param_hash() != want {
                anyhow::bail!(
                    "{}: built for other OCM parameters (hash {:#018x}) than the lab's plant ({want:#018x}): build the LUT with the same --params or --config as this run",
                    path.display(),
                    image.param_hash()
                );
            }
            bytes
        }
        (None, _) => lut_image(&cfg.plant, &cfg.limits)?,
    };
    if !args.json && args.mcu != McuMode::Host {
        println!(
            "LUT: {} B {}; command limits {:.0} .. {:.0} Pa; firmware: {}",
            image.len(),
            args.lut.as_ref().map_or_else(
                || "built from the energy model for the lab's working range".to_string(),
                |p| format!("from {}", p.display())
            ),
            cfg.limits.min_pa,
            cfg.limits.max_pa,
            args.mcu.label()
        );
    }
    let mcu = Mcu {
        mode: &args.mcu,
        elf,
        baud: args.baud,
        image,
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
        let report = run_one(name, &cfg, &mcu)
            .with_context(|| format!("scenario {name} with --mcu {}", args.mcu.label()))?;
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        } else {
            let rt = report.realtime_factor;
            println!(
                "{:<12} {:>10} {:>10} {:>10} {:>10}",
                name,
                fmt(report.ol_rmse_mm),
                fmt(report.cl_rmse_mm),
                fmt(report.oracle_rmse_mm),
                if rt == 0.0 {
                    "-".to_string()
                } else if rt < 10.0 {
                    format!("{rt:.2}")
                } else {
                    format!("{rt:.0}")
                }
            );
            for (k, v) in &report.figures {
                println!("    {k} = {v:.4}");
            }
        }
        if let Some(dir) = &args.out {
            report
                .write_csv(dir)
                .with_context(|| format!("writing logs of {name}"))?;
            plot_track::write(&report, dir).with_context(|| format!("plotting {name}"))?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    /// The command line offers exactly the lab's scenarios, each running itself alone.
    #[test]
    fn scenario_choices_are_the_labs_scenarios() {
        let offered: Vec<&str> = Scenario::value_variants()
            .iter()
            .filter(|s| **s != Scenario::All)
            .flat_map(|s| s.names())
            .collect();
        assert_eq!(offered, SCENARIOS.to_vec());
        for s in Scenario::value_variants()
            .iter()
            .filter(|s| **s != Scenario::All)
        {
            assert_eq!(s.names().len(), 1, "{s:?}");
        }
        assert_eq!(Scenario::All.names(), SCENARIOS.to_vec());
    }
}
