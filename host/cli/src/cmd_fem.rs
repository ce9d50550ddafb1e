//! `ocm fem`: owned by the FEM work; replaced wholesale there.

/// FEM subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum FemCommand {}

/// Runs an `ocm fem` subcommand.
pub fn run(cmd: FemCommand) -> anyhow::Result<()> {
    match cmd {}
}
