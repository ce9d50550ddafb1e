//! Solves the bellows FEM over a pressure grid and seeded random held-out pressures and caches
//! the samples the surrogate is built from (the same call as `ocm surrogate geometry`).
//! `cargo run -p ocm-surrogate --example fem_samples -- OUT.json [LEVELS] [HELD_OUT] [SEED]`
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_surrogate::fem_samples;
fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let out = a.first().cloned().unwrap_or("fem_samples.json".into());
    let levels: usize = a.get(1).map(|s| s.parse().expect("levels")).unwrap_or(6);
    let held: usize = a.get(2).map(|s| s.parse().expect("held out")).unwrap_or(30);
    let seed: u64 = a.get(3).map(|s| s.parse().expect("seed")).unwrap_or(1);
    let mesh =
        ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk").expect("mesh");
    let b = Bellows::load(mesh, BellowsConfig::default()).expect("bellows");
    let grid = fem_samples::pressure_grid(levels);
    let held_out = fem_samples::random_pressures(held, seed);
    let t = std::time::Instant::now();
    let n = grid.len() + held_out.len();
    let s = fem_samples::collect(&b, &grid, &held_out, |k| {
        eprintln!("{k}/{n} {:.1} s", t.elapsed().as_secs_f64())
    })
    .expect("sweep");
    s.write(std::path::Path::new(&out)).expect("write");
    eprintln!("layers {:?}", s.layers.ridge_z_m);
}
