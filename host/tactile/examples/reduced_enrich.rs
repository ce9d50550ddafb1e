//! Whether a basis that follows the contact could hold the held-out fields the POD basis
//! cannot: the projection limit of a saved reduced model's modes, alone and with two
//! per-placement modes from the rest stiffness (the linear response to a uniform normal load on
//! the indenter's footprint, and to a load on the footprint's rim), on held-out FEM runs.
//! The footprint comes from the indenter geometry alone (top nodes inside the placed indenter
//! at the sequence's deepest pose), not from the FEM field (`reduced::placement_model`, as
//! `ocm tactile reduce --bench --enrich` uses it).
//!
//! `cargo run -p ocm-tactile --example reduced_enrich -- ROM RANKS SETUPS [FEM_ROOTS]`
//! e.g. `-- out/tactile/rom 20,40 id3,id2,r2-0021-texture1 out/npe/fem,out/tactile/fem-random`.

use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::indent::Approach;
use ocm_tactile::indenter::Indenter;
use ocm_tactile::reduced::{
    DEFAULT_FOOTPRINT_LOADS, Enrichment, FemSequence, ReducedModel, RestStiffness, placement_model,
};
use ocm_tactile::setup::{Setup, digit_setups};
use std::path::{Path, PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err("usage: reduced_enrich ROM RANKS SETUPS [FEM_ROOTS]".into());
    }
    let rom = ReducedModel::load(Path::new(&args[0]))?;
    let ranks: Vec<usize> = args[1]
        .split(',')
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let names: Vec<&str> = args[2].split(',').collect();
    let roots: Vec<PathBuf> = args
        .get(3)
        .map(|s| s.as_str())
        .unwrap_or("out/npe/fem,out/tactile/fem-random")
        .split(',')
        .map(PathBuf::from)
        .collect();
    let digit = ocm_datadir::data_file(None, "digit")?;
    let gel = Gel::digit(digit.join(&rom.info.mesh), GelMaterial::default())?;
    rom.check_gel(&gel)?;
    let all = digit_setups(&digit)?;
    let n = gel.num_nodes();
    let rest = RestStiffness::new(&gel)?;

    for name in names {
        let dir = roots
            .iter()
            .map(|r| r.join(name))
            .find(|d| d.join("u_001.npy").is_file())
            .ok_or_else(|| format!("no FEM folder named {name}"))?;
        let setup = Setup::beside_fem(&dir, name, &digit, &all)?;
        let fem = FemSequence::read(&dir, n, Some(50e-6))?;
        let deepest = fem.depth_m.iter().copied().fold(0.0, f64::max);
        let indenter = Indenter::from_stl(&setup.stl)?;
        let approach = Approach::new(name, &gel, &indenter, setup.placement)?;
        for &r in &ranks {
            let m = rom.truncated(r)?;
            let enrich = Enrichment {
                rest: &rest,
                loads: &DEFAULT_FOOTPRINT_LOADS,
            };
            let em = placement_model(&m, enrich, &gel, &indenter, &approach, deepest)?;
            let limit = |model: &ReducedModel| -> Result<f64, Box<dyn std::error::Error>> {
                let mut worst = 0.0f64;
                for u in &fem.displacement {
                    let up = model.displacement(&model.project(u));
                    worst = worst.max(ocm_tactile::metrics::nodal_rmse(&up, u)?);
                }
                Ok(worst)
            };
            println!(
                "{name}: rank {r}: worst-frame projection {:.4} mm, with {} footprint mode(s) {:.4} mm",
                limit(&m)? * 1e3,
                em.rank() - r,
                limit(&em)? * 1e3
            );
        }
    }
    Ok(())
}
