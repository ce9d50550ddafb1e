//! `ocm model`: evaluate the f64 energy model on user data.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use ocm_lutgen::OcmModel;
use ocm_lutgen::config::Config;
use ocm_lutgen::stack::{AssumptionConfig, AssumptionReport, measure_assumptions};

/// Model subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum ModelCommand {
    /// Add the axial force one OCM exerts at each row's pressure and strain, as `force_n`
    /// (tension positive; eq 3.9), to a CSV with columns `time_s,pressure_kpa,strain`.
    Axial {
        /// Input CSV with the columns `time_s,pressure_kpa,strain`; other columns are kept.
        input: PathBuf,
        /// Output CSV: the input columns plus `force_n`.
        #[arg(long)]
        out: PathBuf,
        /// TOML configuration of the OCM (a `preset` and overrides); the calibrated
        /// parameter set if absent.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Measure the uniform-layer assumptions against the full N-layer
    /// bar-and-hinge equilibrium (all nodes free): force, moment and
    /// neutral-axis deviations, and the pressure stability limit.
    Assumptions {
        /// TOML configuration of the OCM (a `preset` and overrides); the calibrated
        /// parameter set if absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the whole report as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Runs an `ocm model` subcommand.
pub fn run(cmd: ModelCommand) -> Result<()> {
    match cmd {
        ModelCommand::Axial { input, out, config } => {
            let model = OcmModel::new(Config::load(config.as_deref())?.ocm)?;
            let rows = axial(&model, &input, &out)?;
            println!("wrote {} rows to {}", rows, out.display());
            Ok(())
        }
        ModelCommand::Assumptions { config, json } => {
            let model = OcmModel::new(Config::load(config.as_deref())?.ocm)?;
            let report = measure_assumptions(&model, &AssumptionConfig::default())?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print_assumptions(&report);
            }
            Ok(())
        }
    }
}

fn print_assumptions(r: &AssumptionReport) {
    println!(
        "Full {}-layer bar-and-hinge equilibrium vs the uniform single-layer model",
        r.layers
    );
    println!(
        "pressure stability: plate free up to {:.1} Pa, plate held at l0 up to {:.1} Pa",
        r.pressure_stability_free.last_stable_pa, r.pressure_stability_held.last_stable_pa
    );
    println!(
        "force at equal strain: max |dF| {:.4} N, mean {:.4} N",
        r.force_deviation_n.max_abs, r.force_deviation_n.mean_abs
    );
    println!(
        "strain at equal force: max |d eps| {:.4}, mean {:.4}",
        r.strain_deviation.max_abs, r.strain_deviation.mean_abs
    );
    println!(
        "moment at equal angle (plate on the uniform arc): max |dM| {:.5} N m, mean {:.5} N m",
        r.moment_arc_deviation_nm.max_abs, r.moment_arc_deviation_nm.mean_abs
    );
    println!(
        "neutral-axis length change under pure moment: max {:.3} mm (dissertation: 0.183 mm)",
        r.neutral_axis_max_deviation_mm
    );
    println!(
        "layer height spread (axial): {:.4} mm; layer angle spread (bending): {:.4} rad",
        r.max_layer_height_spread_mm, r.max_layer_angle_spread_rad
    );
    println!(
        "{} sweep points had no equilibrium (see --json)",
        r.failures.len()
    );
}

/// Reads `input`, evaluates `F_A(strain, pressure)` per row and writes `out`.
/// Returns the number of data rows.
pub fn axial(model: &OcmModel, input: &Path, out: &Path) -> Result<usize> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(input)
        .with_context(|| format!("reading {}", input.display()))?;
    let headers = reader
        .headers()
        .with_context(|| format!("{}: reading the header line", input.display()))?
        .clone();
    let column = |name: &str| -> Result<usize> {
        headers.iter().position(|h| h == name).with_context(|| {
            format!(
                "{} line 1: missing column `{name}` (need time_s,pressure_kpa,strain; found {})",
                input.display(),
                headers.iter().collect::<Vec<_>>().join(",")
            )
        })
    };
    let (c_t, c_p, c_e) = (
        column("time_s")?,
        column("pressure_kpa")?,
        column("strain")?,
    );
    if headers.iter().any(|h| h == "force_n") {
        bail!(
            "{} line 1: column `force_n` already present; refusing to overwrite it",
            input.display()
        );
    }
    let (lo, hi) = model.strain_limits();
    let mut rows = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record
            .with_context(|| format!("{} line {line}: malformed CSV record", input.display()))?;
        let field = |c: usize| -> Result<f64> {
            let text = record.get(c).unwrap_or("");
            let v: f64 = text.parse().map_err(|_| {
                anyhow::anyhow!(
                    "{} line {line}, column `{}`: `{text}` is not a number",
                    input.display(),
                    &headers[c]
                )
            })?;
            if !v.is_finite() {
                bail!(
                    "{} line {line}, column `{}`: value must be finite",
                    input.display(),
                    &headers[c]
                );
            }
            Ok(v)
        };
        field(c_t)?;
        let p_kpa = field(c_p)?;
        let eps = field(c_e)?;
        if !(eps > lo && eps < hi) {
            bail!(
                "{} line {line}, column `strain`: {eps} is outside the model's range ({lo}, {hi:.4})",
                input.display()
            );
        }
        let mut out_rec: Vec<String> = record.iter().map(str::to_owned).collect();
        out_rec.push(format!("{:.9}", model.axial_force_n(eps, p_kpa * 1e3)));
        rows.push(out_rec);
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut w =
        csv::Writer::from_path(out).with_context(|| format!("writing {}", out.display()))?;
    let mut h: Vec<&str> = headers.iter().collect();
    h.push("force_n");
    w.write_record(&h)?;
    for r in &rows {
        w.write_record(r)?;
    }
    w.flush()?;
    Ok(rows.len())
}
