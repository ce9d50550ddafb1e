//! Natural frequencies at rest of the full bellows FEM and of Galerkin reduced models of the
//! training snapshots: `cargo run --release -p ocm-mor --example modes -- S RANKS [MODES] [ADD]`
//! (S a snapshot folder of `ocm mor snapshots`, RANKS e.g. 16,32,48; ADD > 0 also prints the
//! reduced models whose POD basis is enriched with the first ADD rest modes).
//!
//! The full model's lowest modes come from `ocm_mor::modes::rest_modes`; each reduced model's
//! from its dense r x r pencil (K_r, M_r). Also printed: each full mode's captured share of
//! kinetic energy in the basis (mass-weighted projection) and the Rayleigh damping ratio at its
//! frequency.
use nalgebra::{DMatrix, DVector};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::modes::{enrich, hz, pencil, rest_modes};
use ocm_mor::pod::{PodOptions, Truncation, pod};
use ocm_mor::rom::ReducedModel;
use ocm_mor::store;
use std::path::PathBuf;

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(a.first().map_or("target/mor-figures", |s| s.as_str()));
    let ranks: Vec<usize> = a
        .get(1)
        .map_or("16,32,48", |s| s.as_str())
        .split(',')
        .filter_map(|t| t.parse().ok())
        .collect();
    let nmodes: usize = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(10);
    let add: usize = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(0);
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| ocm_mor::MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(&path, BellowsConfig::default())?;
    let model = &b.model;
    let t0 = std::time::Instant::now();
    let full = rest_modes(model, nmodes.max(add))?;
    println!(
        "full model: {} modes in {:.1} s",
        nmodes.max(add),
        t0.elapsed().as_secs_f64()
    );
    let zeta = |f: f64| {
        let w = 2.0 * std::f64::consts::PI * f;
        model.rayleigh_alpha / (2.0 * w) + model.rayleigh_beta * w / 2.0
    };
    for (k, f) in full.frequencies_hz.iter().enumerate().take(nmodes) {
        println!(
            "  mode {:2}: {f:8.3} Hz, Rayleigh zeta {:.3}",
            k + 1,
            zeta(*f)
        );
    }
    let s = store::load_snapshots(&dir, &store::model_hash(&b))?;
    let maxr = ranks.iter().copied().max().unwrap_or(1);
    let train = s.matrix(0, s.train_rows());
    let pd = pod(
        train.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(maxr),
            ..PodOptions::default()
        },
    )?;
    drop(train);
    let masses = model.nodal_masses();
    let adds: Vec<usize> = if add > 0 { vec![0, add] } else { vec![0] };
    for &r in &ranks {
        for &m in &adds {
            let v = DMatrix::from_fn(s.disp.cols, r, |i, j| pd.modes[(i, j)]);
            let v = enrich(&v, &full.shapes.columns(0, m).into_owned(), 1e-8)?;
            let rr = v.ncols();
            let rom = ReducedModel::galerkin(model, v.clone(), &b.top_face)?;
            let k = rom
                .internal(&DVector::zeros(rr), true)?
                .k
                .ok_or_else(|| ocm_mor::MorError::Invalid("no tangent".into()))?;
            let (vals, _) = pencil(&k, &rom.mass)?;
            println!(
                "POD rank {r} + {m} rest modes (rank {rr}): reduced frequencies (Hz) and the full modes' kinetic share in the basis"
            );
            for (kk, lam) in vals.iter().enumerate().take(nmodes.min(rr)) {
                let u = full.shapes.column(kk);
                let mu = DVector::from_fn(u.len(), |d, _| masses[d / 3] * u[d]);
                let c = rom
                    .mass
                    .clone()
                    .lu()
                    .solve(&(v.transpose() * &mu))
                    .unwrap_or_else(|| DVector::zeros(rr));
                let captured = c.dot(&(&rom.mass * &c)) / u.dot(&mu);
                let f = full.frequencies_hz[kk];
                println!(
                    "  {:2}: reduced {:8.3} Hz (full {f:8.3} Hz, {:+.2}%), full mode captured {captured:.5}",
                    kk + 1,
                    hz(*lam),
                    100.0 * (hz(*lam) / f - 1.0),
                );
            }
        }
    }
    Ok(())
}
