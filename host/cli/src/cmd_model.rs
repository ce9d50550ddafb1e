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
        /// Pressures are gauge (below -101.325 kPa is an error); rows outside the
        /// configuration's `[table]` pressure range are written with a warning.
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
            let cfg = Config::load(config.as_deref())?;
            let model = OcmModel::new(cfg.ocm)?;
            let range = (cfg.table.p_min_kpa, cfg.table.p_max_kpa);
            let written = axial(&model, range, &input, &out)?;
            if let Some(w) = &written.outside {
                eprintln!("warning: {w}");
            }
            println!("wrote {} rows to {}", written.rows, out.display());
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

/// Lowest gauge pressure there is: absolute vacuum at standard atmosphere, kPa.
const VACUUM_GAUGE_KPA: f64 = -101.325;

/// What [`axial`] wrote.
#[derive(Debug)]
pub struct AxialWritten {
    /// Data rows written.
    pub rows: usize,
    /// Rows whose pressure lies outside the configured table range, in words (the model is
    /// linear in pressure and extrapolates there); `None` when all lie inside.
    pub outside: Option<String>,
}

/// Reads `input`, evaluates `F_A(strain, pressure)` per row and writes `out`. Pressures are
/// gauge: one below absolute vacuum is an error; rows outside `range_kpa` (the table's
/// pressure range) are counted in the result.
pub fn axial(
    model: &OcmModel,
    range_kpa: (f64, f64),
    input: &Path,
    out: &Path,
) -> Result<AxialWritten> {
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
    // (count, first line, its pressure)
    let mut outside: Option<(usize, usize, f64)> = None;
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
        if p_kpa < VACUUM_GAUGE_KPA {
            bail!(
                "{} line {line}, column `pressure_kpa`: {p_kpa} kPa is below absolute vacuum ({VACUUM_GAUGE_KPA} kPa gauge; pressures are gauge)",
                input.display()
            );
        }
        if !(range_kpa.0..=range_kpa.1).contains(&p_kpa) {
            let o = outside.get_or_insert((0, line, p_kpa));
            o.0 += 1;
        }
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
    Ok(AxialWritten {
        rows: rows.len(),
        outside: outside.map(|(n, line, p)| {
            format!(
                "{}: {n} of {} rows (the first on line {line}: {p} kPa) lie outside the configured pressure range [{}, {}] kPa (`[table] p_min_kpa/p_max_kpa`); the energy model is linear in pressure and extrapolates there",
                input.display(),
                rows.len(),
                range_kpa.0,
                range_kpa.1
            )
        }),
    })
}
