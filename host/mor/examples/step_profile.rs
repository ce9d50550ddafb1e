//! Runs a stored reduced model (`ocm mor pod` + `ocm mor reduce` folder) over seeded drive
//! sequences and prints the Newton work and the median step time; made to be counted under
//! `valgrind --tool=callgrind --toggle-collect='*simulate_reduced*'` (instructions per step are
//! stable under load, wall times are not).
//! `cargo run --release -p ocm-mor --example step_profile -- ROM_DIR [sequences] [steps]`
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::drive::{DriveConfig, sequence};
use ocm_mor::rom::ReducedModel;
use ocm_mor::run::{median, simulate_reduced};
use ocm_mor::store::{self, ReducedProbe};
use ocm_mor::xs::XsProbe;
use std::path::PathBuf;

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(a.first().map_or("target/mor-rom", |s| s.as_str()));
    let arg = |k: usize, d: usize| a.get(k).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (nseq, steps) = (arg(1, 2), arg(2, 200));
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| ocm_mor::MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(path, BellowsConfig::default())?;
    let (basis, _) = store::load_basis(&dir, &store::model_hash(&b), 3 * b.model.num_nodes())?;
    let gal = ReducedModel::galerkin(&b.model, basis, &b.top_face)?;
    let (rom, _) = store::load_rom(&dir, &gal)?;
    let probe = ReducedProbe::new(XsProbe::of_bellows(&b), &rom);
    let drive = DriveConfig::default();
    let (mut times, mut its, mut tans) = (vec![], 0, 0);
    for k in 0..nseq {
        let inputs = sequence(&drive, 7, k as u64, steps);
        let run = simulate_reduced(&rom, &probe, &inputs, drive.dt_s)?;
        times.extend(run.step_seconds);
        its += run.report.iterations;
        tans += run.report.tangents;
    }
    let n = times.len() as f64;
    println!(
        "rank {}, {} elements: {:.3} ms/step (median of {n}), {:.3} iterations and {:.3} tangents per step",
        rom.rank(),
        rom.elements.len(),
        median(&times) * 1e3,
        its as f64 / n,
        tans as f64 / n
    );
    Ok(())
}
