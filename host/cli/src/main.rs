//! `ocm`: the command line of the ocm toolkit.

use clap::{Parser, Subcommand};

mod cmd_fem;
mod cmd_ident;

/// Soft and origami robotics toolkit: physics, LUTs, firmware, simulation.
#[derive(Parser, Debug)]
#[command(name = "ocm", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Finite-element simulation of soft bodies (bellows manipulator, DIGIT gel).
    #[command(subcommand)]
    Fem(cmd_fem::FemCommand),
    /// Find what the model gets wrong in measured data, name the cause, extend the model.
    Ident(cmd_ident::IdentArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Fem(cmd) => cmd_fem::run(cmd),
        Command::Ident(args) => cmd_ident::run(args),
    }
}
