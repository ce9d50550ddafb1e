//! `ocm`: the command line of the ocm toolkit.

use clap::{Parser, Subcommand};

mod arg_check;
mod cmd_fem;
mod cmd_ident;
mod cmd_learn;
mod cmd_learn_args;
mod cmd_learn_map;
mod cmd_lut;
mod cmd_model;
mod cmd_mor;
mod cmd_npe;
mod cmd_peg;
mod cmd_rl;
mod cmd_surrogate;
mod cmd_tactile;
mod cmd_tactile_net;
mod cmd_track;
mod heap;
mod pipe;
mod plot;
mod plot_track;
mod progress;

/// Soft and origami robotics toolkit: physics, LUTs, firmware, simulation.
#[derive(Parser, Debug)]
#[command(name = "ocm", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Build, check, plot and export the OCM lookup tables (LUT images).
    #[command(subcommand)]
    Lut(cmd_lut::LutCommand),
    /// Evaluate the OCM energy model on data.
    #[command(subcommand)]
    Model(cmd_model::ModelCommand),
    /// Run the dissertation's experiments in the virtual lab (plant + controllers).
    Track(cmd_track::TrackArgs),
    /// Finite-element simulation of soft bodies (bellows manipulator, DIGIT gel).
    #[command(subcommand)]
    Fem(cmd_fem::FemCommand),
    /// Find what the model gets wrong in measured data, name the cause, extend the model.
    Ident(cmd_ident::IdentArgs),
    /// Model-order reduction of the bellows FEM: snapshots, POD, reduced model, X_S datasets.
    #[command(subcommand)]
    Mor(cmd_mor::MorCommand),
    /// Rigid-link surrogate of the bellows: geometry from FEM nodes, URDF, actuation map, bench.
    #[command(subcommand)]
    Surrogate(cmd_surrogate::SurrogateCommand),
    /// Learned dynamics of the bellows manipulator: forward Transformer-PINN and inverse model.
    #[command(subcommand)]
    Learn(cmd_learn::LearnCommand),
    /// Reinforcement learning on the surrogate: train (BC, PPO), evaluate, benchmark.
    #[command(subcommand)]
    Rl(cmd_rl::RlCommand),
    /// Neural physics engine of the DIGIT gel: train, evaluate against the FEM, time.
    #[command(subcommand)]
    Npe(cmd_npe::NpeCommand),
    /// DIGIT tactile FEM: rigid indenters pressed into the gel, contact masks, metrics.
    #[command(subcommand)]
    Tactile(cmd_tactile::TactileCommand),
    /// Peg-in-hole with two DIGIT pads: expert demonstrations, behaviour cloning, evaluation, replay.
    #[command(subcommand)]
    Peg(cmd_peg::PegCommand),
}

fn main() -> std::process::ExitCode {
    heap::keep_freed_memory();
    pipe::end_quietly_when_the_reader_leaves();
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{}", error_report(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes, as anyhow prints them, without the backtrace that a set
/// `RUST_BACKTRACE` would add: a refused input is not a bug. `OCM_ERROR_BACKTRACE=1` adds it.
fn error_report(e: &anyhow::Error) -> String {
    if std::env::var_os("OCM_ERROR_BACKTRACE").is_some_and(|v| v == "1") {
        return format!("Error: {e:?}");
    }
    let mut out = format!("Error: {e}");
    let causes: Vec<String> = e.chain().skip(1).map(|c| c.to_string()).collect();
    if !causes.is_empty() {
        out.push_str("\n\nCaused by:");
        for (i, c) in causes.iter().enumerate() {
            if causes.len() == 1 {
                out.push_str(&format!("\n    {c}"));
            } else {
                out.push_str(&format!("\n    {i}: {c}"));
            }
        }
    }
    out
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Lut(cmd) => cmd_lut::run(cmd),
        Command::Model(cmd) => cmd_model::run(cmd),
        Command::Track(args) => cmd_track::run(args),
        Command::Fem(cmd) => cmd_fem::run(cmd),
        Command::Ident(args) => cmd_ident::run(args),
        Command::Mor(cmd) => cmd_mor::run(cmd),
        Command::Surrogate(cmd) => cmd_surrogate::run(cmd),
        Command::Learn(cmd) => cmd_learn::run(cmd),
        Command::Tactile(cmd) => cmd_tactile::run(cmd),
        Command::Peg(cmd) => cmd_peg::run(cmd),
        Command::Npe(cmd) => cmd_npe::run(cmd),
        Command::Rl(cmd) => cmd_rl::run(cmd),
    }
}
