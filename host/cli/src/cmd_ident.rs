//! `ocm ident`: find what the model gets wrong in measured data, name the cause, extend the
//! model and measure the held-out gain.

use std::path::PathBuf;

use anyhow::bail;
use ocm_ident::baseline::SeriesModel;
use ocm_ident::synth::{Spec, generate};
use ocm_ident::{Cause, Config, Kind, report, softarm};

/// Most rows `ocm ident synth` writes: ten times the benchmark's record, a few hundred MB of
/// CSV (a larger count is more likely a typo than a record anyone identifies).
const MAX_SYNTH_ROWS: usize = 1_000_000;

/// Record kinds (the column schema of the CSV).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum KindArg {
    /// An actuator pulled or pushed along its axis: time_s, pressure_kpa, strain, force_n.
    Axial,
    /// An actuator bent at a fixed axial strain: time_s, strain0, bend_angle_rad, moment_nm.
    Bending,
    /// A segment's tip pose from three chamber pressures and an axial load: time_s,
    /// p1_kpa..p3_kpa, load_n, x_mm, y_mm, z_mm.
    Pose,
    /// Any system: time_s, u_<name> inputs, y_<name> measured outputs, optional sim_<name>
    /// (a simulator's prediction) and x_<name> (its states).
    Series,
}

impl KindArg {
    fn kind(self) -> Kind {
        match self {
            KindArg::Axial => Kind::Axial,
            KindArg::Bending => Kind::Bending,
            KindArg::Pose => Kind::Pose,
            KindArg::Series => Kind::Series,
        }
    }
}

/// Baseline of `series` records without `sim_` columns.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeriesBaseline {
    /// The state-space model, or the static map where the static map with the causes it
    /// names fits better (training BIC counting each baseline's parameters, no held-out
    /// accuracy lost): a static system's loops are otherwise taken for dynamics.
    Auto,
    /// Linear state-space model (subspace identification refined on free-run simulation
    /// error, order by BIC; once a cause is named, up to two lower orders are tried with the
    /// extensions): for dynamic systems; the static map is reported beside it.
    StateSpace,
    /// Static affine map y = A u + b: for quasi-static systems; the state-space model is
    /// reported beside it.
    Static,
}

/// Effects a synthetic record can hide.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum EffectArg {
    /// A clean control: the model plus noise.
    None,
    /// Rate-independent memory: loading and unloading follow different paths.
    Hysteresis,
    /// Viscoelastic creep and relaxation: the response depends on how fast it is driven.
    #[value(name = "rate_dependence")]
    RateDependence,
    /// Stiffness lost with cycles or with the largest deformation so far.
    Softening,
    /// The measurement lags the input (dead time and a first-order lag).
    Latency,
    /// A constant bias in an output or an input.
    Offset,
    /// A scale error of an actuator.
    Gain,
    /// A static mismatch that none of the others explains (stiffening).
    Nonlinearity,
}

impl EffectArg {
    fn cause(self) -> Cause {
        match self {
            EffectArg::None => Cause::None,
            EffectArg::Hysteresis => Cause::Hysteresis,
            EffectArg::RateDependence => Cause::RateDependence,
            EffectArg::Softening => Cause::Softening,
            EffectArg::Latency => Cause::Latency,
            EffectArg::Offset => Cause::Offset,
            EffectArg::Gain => Cause::Gain,
            EffectArg::Nonlinearity => Cause::Nonlinearity,
        }
    }
}

/// Subcommands of `ocm ident`.
#[derive(clap::Subcommand, Debug)]
pub enum IdentCommand {
    /// Write a synthetic record with a hidden effect (a test input for `ocm ident`); refuses
    /// to overwrite an existing file.
    Synth(SynthArgs),
}

/// Arguments of `ocm ident synth`.
#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// The CSV to write (in the kind's schema, units in the column names); must not exist.
    pub out: PathBuf,
    /// Record kind.
    #[arg(long, value_enum, default_value_t = KindArg::Axial)]
    pub kind: KindArg,
    /// The hidden effect (`none` for a clean control). Not every kind can hide every effect:
    /// the baseline's free parameters absorb some (an offset or a gain of a series map).
    #[arg(long, value_enum, default_value_t = EffectArg::None)]
    pub effect: EffectArg,
    /// Rows of the record (100 to 1,000,000).
    #[arg(long, default_value_t = 4000)]
    pub rows: usize,
    /// Seed: the same seed writes the same record.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Arguments of `ocm ident`.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct IdentArgs {
    /// Write a synthetic record instead of identifying one.
    #[command(subcommand)]
    pub command: Option<IdentCommand>,
    /// Measured data: a CSV in the kind's schema, or the soft-arm MATLAB file (`.mat`).
    ///
    /// Schema conventions: axial force_n tension positive, strain extension positive, gauge
    /// pressures inflation positive; pose x_mm, y_mm, z_mm in the base frame of a standing
    /// segment with z from base to tip (rotate a hanging mount's log first), load_n axial
    /// tension; series u_<name> inputs, y_<name> measured outputs, and optionally sim_<name>
    /// (another simulator's prediction of y_<name>: then ident explains measured minus
    /// simulated) and x_<name> (its states, e.g. a position whose velocity friction follows;
    /// where the states determine the simulated output, memory, offsets and gains act on them
    /// too, a gain about the state's zero: log elongations rather than lengths), and
    /// dsim_<output>__<state> (the simulator's own sensitivity d sim_<output> / d x_<state>,
    /// one per state for an output or none: taken as exact, and offsets and gains of inputs
    /// and states are then one parameter for all outputs). Units come from the name's suffix (_n, _nm, _m, _mm, _kpa, _pa, _bar, _rad, _deg, _s,
    /// _v). A record that contradicts the conventions gets a warning in the report.
    #[arg(required = true)]
    pub file: Option<PathBuf>,
    /// Record kind (a `.mat` file is always series).
    #[arg(long, value_enum, default_value_t = KindArg::Series)]
    pub kind: KindArg,
    /// Baseline of a `series` record without sim_ columns [default: auto; static for the
    /// soft-arm .mat file, whose published figures are quasi-static: pass `state-space` to
    /// judge it against the linear-dynamic baseline].
    #[arg(long, value_enum)]
    pub baseline: Option<SeriesBaseline>,
    /// Print the JSON report instead of the text summary.
    #[arg(long)]
    pub json: bool,
    /// Write report.md, report.json and plots into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Family-wise significance of the false-discovery guard: the chance of naming a cause
    /// in a record that has none, shared among the candidates.
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Smallest held-out RMSE gain (percent) for a cause to be named.
    #[arg(long, default_value_t = 2.0)]
    pub min_gain: f64,
    /// State-space baselines: search the baseline's lower orders and where the extensions'
    /// forces enter only when the named causes leave more than this many times the noise
    /// (held out); 0 searches always (slower, sometimes a closer fit, same names so far).
    #[arg(long, default_value_t = 2.0)]
    pub structure_search_ratio: f64,
    /// OCM parameter set of the axial, bending and pose baselines: `table-3.1` (default, the
    /// dissertation's table) or `calibrated` (the virtual lab's plant and the LUT).
    #[arg(long, value_enum, default_value_t = crate::cmd_lut::Params::Table31)]
    pub params: crate::cmd_lut::Params,
}

/// Runs `ocm ident synth`.
fn synth(args: SynthArgs) -> anyhow::Result<()> {
    if args.out.exists() {
        bail!(
            "{} exists: ocm ident synth does not overwrite files (remove it or choose another name)",
            args.out.display()
        );
    }
    if !(100..=MAX_SYNTH_ROWS).contains(&args.rows) {
        bail!(
            "--rows must be between 100 and {MAX_SYNTH_ROWS}, got {}",
            args.rows
        );
    }
    let kind = args.kind.kind();
    let cause = args.effect.cause();
    let effects = if cause == Cause::None {
        vec![]
    } else {
        if !ocm_ident::synth::hideable(kind).contains(&cause) {
            bail!(
                "a {} record cannot hide `{}` (its baseline's free parameters absorb it); effects it can hide: {}",
                kind.name(),
                cause.name(),
                ocm_ident::synth::hideable(kind)
                    .iter()
                    .map(|c| c.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        vec![cause]
    };
    let g = generate(&Spec {
        kind,
        effects,
        seed: args.seed,
        rows: args.rows,
        ratio: (3.0, 6.0),
    });
    ocm_ident::data::write_csv(&g.record, &args.out)?;
    eprintln!(
        "wrote {} ({} rows, hidden {:?}, visible effect / noise {:?}, {:?})",
        args.out.display(),
        g.record.len(),
        g.effects.iter().map(|c| c.name()).collect::<Vec<_>>(),
        g.ratios,
        g.details
    );
    Ok(())
}

/// Runs `ocm ident`.
pub fn run(args: IdentArgs) -> anyhow::Result<()> {
    if let Some(IdentCommand::Synth(s)) = args.command {
        return synth(s);
    }
    let Some(file) = args.file else {
        bail!("ocm ident needs a FILE to identify (or the `synth` subcommand)");
    };
    let is_mat = file
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mat"));
    let kind = if is_mat {
        Kind::Series
    } else {
        args.kind.kind()
    };
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        bail!("--alpha must be in (0, 1), got {}", args.alpha);
    }
    if !args.structure_search_ratio.is_finite() || args.structure_search_ratio < 0.0 {
        bail!(
            "--structure-search-ratio must be a non-negative number, got {}",
            args.structure_search_ratio
        );
    }
    if !args.min_gain.is_finite() || args.min_gain < 0.0 {
        bail!(
            "--min-gain must be a non-negative percentage, got {}",
            args.min_gain
        );
    }
    let record = if is_mat {
        softarm::load(&file)?
    } else {
        ocm_ident::data::read_csv(&file, kind)?
    };
    let series_model = match args.baseline {
        Some(SeriesBaseline::StateSpace) => SeriesModel::StateSpace,
        Some(SeriesBaseline::Static) => SeriesModel::Static,
        Some(SeriesBaseline::Auto) => SeriesModel::Auto,
        // the soft arm is read as quasi-static unless asked, its published figures are on
        // that baseline
        None if is_mat => SeriesModel::Static,
        None => SeriesModel::Auto,
    };
    let cfg = Config {
        alpha: args.alpha,
        min_gain_pct: args.min_gain,
        structure_search_ratio: args.structure_search_ratio,
        series_model,
        ocm: args.params.into(),
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
