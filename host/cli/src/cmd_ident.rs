//! `ocm ident`: owned by the identification work; replaced wholesale there.

/// Arguments of `ocm ident`.
#[derive(clap::Args, Debug)]
pub struct IdentArgs {}

/// Runs `ocm ident`.
pub fn run(_args: IdentArgs) -> anyhow::Result<()> {
    anyhow::bail!("ocm ident is not available in this build")
}
