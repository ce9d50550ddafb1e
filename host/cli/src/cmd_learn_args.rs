//! The arguments of `ocm learn`, shared by the dynamics commands and the mapping commands.

use std::path::PathBuf;

use ocm_dynamics::pipeline::{DEFAULT_BETA, DEFAULT_LAMBDA};

/// Arguments of `ocm learn bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Forward checkpoint.
    #[arg(long)]
    pub forward: PathBuf,
    /// Batch size of the throughput run.
    #[arg(long, default_value_t = 1024)]
    pub batch: usize,
    /// Print the timings as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Which model to train.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// Forward dynamics f_S: window of [X_S, P_S, tau] to dX_S/dt(t+1).
    Forward,
    /// Inverse dynamics: [X_S, tau, dX_S/dt(t+1)] to P_S, cycle loss through a forward model.
    Inverse,
    /// The mapping MLPs of App. D: f_SP (pressures to surrogate joints) and its inverse, from the
    /// folder of `ocm surrogate map` (--data DIR: surrogate.json, fem_samples.json); with --rom
    /// also f_RS (full-FEM pressures to the reduced model's pressures with the same TCP).
    Map,
}

/// Where the trajectories come from and how they are split.
#[derive(clap::Args, Debug, Clone)]
pub struct DataArgs {
    /// Reduced-FEM data set written by `ocm mor` (manifest.json + shards); for the mapping
    /// networks, the folder of `ocm surrogate map` (surrogate.json, fem_samples.json).
    #[arg(long, value_name = "DIR", conflicts_with = "demo")]
    pub data: Option<PathBuf>,
    /// Use trajectories of a seeded lumped system (8 components like X_S) instead of a data set.
    #[arg(long)]
    pub demo: bool,
    /// Sequences of the demo data.
    #[arg(long, default_value_t = 40)]
    pub demo_sequences: usize,
    /// Steps (10 ms) per demo sequence.
    #[arg(long, default_value_t = 600)]
    pub demo_steps: usize,
    /// Fraction of the sequences (the last ones) held out for evaluation.
    #[arg(long, default_value_t = 0.2)]
    pub test_fraction: f64,
    /// Fraction of the training sequences actually used (data-size ablations).
    #[arg(long, default_value_t = 1.0)]
    pub fraction: f64,
    /// Leave out (and name on stderr) the sequences of --data that hold non-finite values
    /// instead of refusing the data set.
    #[arg(long)]
    pub drop_nonfinite: bool,
}

/// Arguments of `ocm learn train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Model to train.
    #[arg(value_enum)]
    pub kind: ModelKind,
    #[command(flatten)]
    pub data: DataArgs,
    /// Output folder: checkpoint, loss curve (CSV, PNG), summary.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Forward checkpoint for the inverse model's cycle loss.
    #[arg(long, required_if_eq("kind", "inverse"))]
    pub forward: Option<PathBuf>,
    /// Maximum epochs (the dissertation: 300 forward, 200 inverse).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Batch size (default: 64; 32 for the mapping networks, as App. D).
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// Adam learning rate (default: 5e-4 forward, 1e-3 inverse, as in the dissertation).
    #[arg(long)]
    pub lr: Option<f64>,
    /// Lower the step size along half a cosine, step by step, from --lr down to this
    /// fraction of it at the end of the last planned epoch (absent: --lr throughout).
    #[arg(long, value_parser = crate::arg_check::fraction)]
    pub lr_final: Option<f64>,
    /// Physics weight lambda of the forward loss.
    #[arg(long, default_value_t = DEFAULT_LAMBDA)]
    pub lambda: f64,
    /// Cycle weight beta of the inverse loss.
    #[arg(long, default_value_t = DEFAULT_BETA)]
    pub beta: f64,
    /// Leave the current velocity dX_S/dt(t) out of the inverse model's input (eq 4.17's
    /// input list read literally: [X_S(t), tau(t), dX_S/dt(t+1)]).
    #[arg(long)]
    pub no_current_velocity: bool,
    /// Early-stopping patience in epochs, 0: never (default: 30; 20 for the mapping networks).
    #[arg(long)]
    pub patience: Option<usize>,
    /// Reduced-model folder (`ocm mor reduce`) for f_RS (train map only).
    #[arg(long)]
    pub rom: Option<PathBuf>,
    /// Bellows mesh for f_RS (default: the data directory's ManipulatorWhole25.vtk).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Seed of weights, split and shuffling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Continue training this forward checkpoint (its shape and scalings) instead of starting
    /// from random weights: a second stage at a lower --lr.
    #[arg(long, conflicts_with = "small")]
    pub init_from: Option<PathBuf>,
    /// A smaller forward model (d_model 64, one block) for quick runs.
    #[arg(long)]
    pub small: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `ocm learn eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Forward checkpoint.
    #[arg(long, required_unless_present = "map")]
    pub forward: Option<PathBuf>,
    /// Folder of the mapping networks (`ocm learn train map`): scores f_SP against the
    /// interpolant on the held-out samples of --data (an `ocm surrogate map` folder), and f_RS
    /// when --rom is given and the folder holds it.
    #[arg(long, conflicts_with = "forward")]
    pub map: Option<PathBuf>,
    /// Reduced-model folder for scoring f_RS.
    #[arg(long)]
    pub rom: Option<PathBuf>,
    /// Bellows mesh for f_RS (default: the data directory's ManipulatorWhole25.vtk).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Inverse checkpoint (optional).
    #[arg(long)]
    pub inverse: Option<PathBuf>,
    #[command(flatten)]
    pub data: DataArgs,
    /// Length of the free-running rollouts, s.
    #[arg(long, value_parser = crate::arg_check::positive, default_value_t = 1.0)]
    pub horizon_s: f64,
    /// Write prediction-against-truth plots (CSV, PNG, SVG) into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the scores as JSON.
    #[arg(long)]
    pub json: bool,
}
