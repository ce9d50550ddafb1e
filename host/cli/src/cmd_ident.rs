//! `ocm ident`: find what the model gets wrong in measured data, name the cause, extend the
//! model and measure the held-out gain.

use std::path::PathBuf;

use anyhow::{Context, bail};
use ocm_ident::baseline::SeriesModel;
use ocm_ident::synth::{Spec, generate};
use ocm_ident::{Cause, Config, Kind, report, softarm};

/// Baseline of `series` records without `sim_` columns.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeriesBaseline {
    /// Linear state-space model (subspace identification refined on free-run simulation
    /// error, order by BIC): for dynamic systems; the static map is reported beside it.
    StateSpace,
    /// Static affine map y = A u + b: for quasi-static systems; the state-space model is
    /// reported beside it.
    Static,
}

/// Arguments of `ocm ident`.
#[derive(clap::Args, Debug)]
pub struct IdentArgs {
    /// Measured data: a CSV in the kind's schema, or the soft-arm MATLAB file (`.mat`).
    ///
    /// Schema conventions: axial force_n tension positive; pose x_mm, y_mm, z_mm in the base
    /// frame of a standing segment with z from base to tip (rotate a hanging mount's log
    /// first), load_n axial tension; series u_<name> inputs, y_<name> measured outputs, and
    /// optionally sim_<name> (another simulator's prediction of y_<name>: then ident explains
    /// measured minus simulated) and x_<name> (its states, e.g. a position whose velocity
    /// friction follows). Units come from the name's suffix (_n, _m, _mm, _kpa, _pa, _rad, _s).
    /// A record that contradicts the conventions gets a warning in the report.
    pub file: PathBuf,
    /// Record kind: axial, bending, pose or series (a `.mat` file is always series).
    #[arg(long, default_value = "series")]
    pub kind: String,
    /// Baseline of a `series` record without sim_ columns (a .mat soft-arm file is static).
    #[arg(long, value_enum, default_value_t = SeriesBaseline::StateSpace)]
    pub baseline: SeriesBaseline,
    /// Print the JSON report instead of the text summary.
    #[arg(long)]
    pub json: bool,
    /// Write report.md, report.json and plots into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Family-wise significance of the false-discovery guard.
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Smallest held-out RMSE gain (percent) for a cause to be named.
    #[arg(long, default_value_t = 2.0)]
    pub min_gain: f64,
    /// Instead of identifying, write a synthetic record to FILE with this hidden effect
    /// (a cause name, or `none` for a clean control), then exit.
    #[arg(long, value_name = "CAUSE")]
    pub synthesize: Option<String>,
    /// Rows of the synthetic record.
    #[arg(long, default_value_t = 4000)]
    pub rows: usize,
    /// Seed of the synthetic record.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs `ocm ident`.
pub fn run(args: IdentArgs) -> anyhow::Result<()> {
    let is_mat = args
        .file
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mat"));
    let kind = if is_mat {
        Kind::Series
    } else {
        Kind::parse(&args.kind).with_context(|| {
            format!(
                "unknown kind `{}` (axial, bending, pose, series)",
                args.kind
            )
        })?
    };
    if let Some(name) = &args.synthesize {
        let cause = Cause::from_name(name).with_context(|| format!("unknown cause `{name}`"))?;
        let effects = if cause == Cause::None {
            vec![]
        } else {
            vec![cause]
        };
        let g = generate(&Spec {
            kind,
            effects,
            seed: args.seed,
            rows: args.rows,
            ratio: (3.0, 6.0),
        });
        ocm_ident::data::write_csv(&g.record, &args.file)?;
        eprintln!(
            "wrote {} ({} rows, hidden {:?}, visible effect / noise {:?}, {:?})",
            args.file.display(),
            g.record.len(),
            g.effects.iter().map(|c| c.name()).collect::<Vec<_>>(),
            g.ratios,
            g.details
        );
        return Ok(());
    }
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        bail!("--alpha must be in (0, 1), got {}", args.alpha);
    }
    if !args.min_gain.is_finite() || args.min_gain < 0.0 {
        bail!(
            "--min-gain must be a non-negative percentage, got {}",
            args.min_gain
        );
    }
    let record = if is_mat {
        softarm::load(&args.file)?
    } else {
        ocm_ident::data::read_csv(&args.file, kind)?
    };
    let series_model = match args.baseline {
        // the soft arm is read as quasi-static, its published figures are on that baseline
        _ if is_mat => SeriesModel::Static,
        SeriesBaseline::StateSpace => SeriesModel::StateSpace,
        SeriesBaseline::Static => SeriesModel::Static,
    };
    let cfg = Config {
        alpha: args.alpha,
        min_gain_pct: args.min_gain,
        series_model,
        ..Config::default()
    };
    let id = ocm_ident::identify(&record, &cfg)?;
    if args.json {
        println!("{}", report::json(&id.report));
    } else {
        print!("{}", report::text(&id.report));
    }
    if let Some(dir) = &args.out {
        let files = report::write_all(&id, dir)?;
        eprintln!(
            "wrote {}",
            files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}
