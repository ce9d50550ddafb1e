//! `ocm fem`: finite-element runs, bellows pressure sweeps and material calibration.

use crate::progress::bar;
use anyhow::{Context, bail};
use ocm_fem::bellows::{Bellows, BellowsConfig, Law, RigidMode};
use ocm_fem::calibrate;
use ocm_fem::mesh::{stl, vtk};
use ocm_fem::scene::Scene;
use ocm_fem::sweep;
use std::path::PathBuf;

/// Data files, relative to the data directory (`--data`, `OCM_DATA_DIR` or `../shared/data`).
pub const BELLOWS_MESH: &str = "bellows-manipulator/ManipulatorWhole25.vtk";
const PRESSURE_TABLE: &str = "bellows-manipulator/Pressure_vs_Pos.csv";
const E50_CSV: &str = "bellows-manipulator/E50_stress_stretch.csv";

/// `explicit`, else `rel` inside the data directory (`data`, `OCM_DATA_DIR` or `../shared/data`).
pub fn data_path(
    explicit: Option<PathBuf>,
    data: Option<&std::path::Path>,
    rel: &str,
) -> anyhow::Result<PathBuf> {
    match explicit {
        Some(p) => Ok(p),
        None => Ok(ocm_datadir::data_file(data, rel)?),
    }
}

/// FEM subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum FemCommand {
    /// Prints node, tet and triangle counts of a VTK or STL mesh.
    Info {
        /// Mesh file (.vtk or .stl).
        mesh: PathBuf,
    },
    /// Runs a scene file (TOML): static load cases or implicit dynamics; writes VTK results.
    Run {
        /// Scene file.
        scene: PathBuf,
        /// Folder for VTK output (one file per result).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Sweeps the bellows chamber pressures over a grid and writes the Fig 4.3 states as CSV.
    ///
    /// The material defaults to the committed calibration (host/fem/calibration/bellows_material.toml).
    /// Against the reference table it reports the raw TCP RMSE (mesh frame, nothing fitted) and the
    /// RMSE after the one fitted parameter, a rotation of the reference's x-y frame about z.
    Sweep {
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Bellows mesh (VTK, mm); default: the data directory's ManipulatorWhole25.vtk.
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Pressure values per chamber, kPa (the grid is their cube).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "-20,0,20,35",
            allow_hyphen_values = true
        )]
        values_kpa: Vec<f64>,
        /// Constitutive law (default: the calibrated one).
        #[arg(long, value_enum)]
        law: Option<LawArg>,
        /// Young's modulus, Pa (default: the calibrated one).
        #[arg(long)]
        young_pa: Option<f64>,
        /// Poisson's ratio (default: the calibrated one).
        #[arg(long)]
        poisson: Option<f64>,
        /// Rigid parts (base connectors, top frame): true rigid bodies or a stiff penalty.
        #[arg(long, value_enum, default_value = "constraint")]
        rigid: RigidArg,
        /// CSV output.
        #[arg(long, default_value = "bellows_sweep.csv")]
        out: PathBuf,
        /// Nodal displacement snapshots (states x 3N) as .npy.
        #[arg(long)]
        npy: Option<PathBuf>,
        /// Reference table to compare TCPs with (same pressures); default: the data directory's
        /// Pressure_vs_Pos.csv when present.
        #[arg(long)]
        reference: Option<PathBuf>,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Prints the committed bellows material calibration and its provenance.
    Material {
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Material calibration.
    #[command(subcommand)]
    Calibrate(CalibrateCommand),
}

/// Calibration subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum CalibrateCommand {
    /// Fits incompressible Neo-Hookean and Mooney-Rivlin to a uniaxial stress-stretch CSV (stress in kPa).
    Fit {
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// CSV with columns stretch,stress; default: the data directory's E50_stress_stretch.csv.
        #[arg(long)]
        csv: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// (E, nu) grid search (Ch.4.4.3): RMSE of bellows TCPs against a reference table, after the
    /// best rotation of the reference frame about z (the raw RMSE is printed beside it).
    Grid {
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Bellows mesh (VTK, mm); default: the data directory's ManipulatorWhole25.vtk.
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Young's moduli to try, Pa.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "2e5,3e5,4e5,6e5,9e5,1.2e6"
        )]
        youngs_pa: Vec<f64>,
        /// Poisson's ratios to try.
        #[arg(long, value_delimiter = ',', default_value = "0.3,0.4,0.45,0.49")]
        poissons: Vec<f64>,
        /// Pressure states (kPa) as p1:p2:p3, comma separated.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "20:0:0,0:20:0,0:0:20,10:10:0,-20:-20:-20,30:0:10"
        )]
        states: Vec<String>,
        /// Reference table (pressures kPa, positions m); default: the data directory's
        /// Pressure_vs_Pos.csv.
        #[arg(long)]
        reference: Option<PathBuf>,
        /// Constitutive law (default: the calibrated one).
        #[arg(long, value_enum)]
        law: Option<LawArg>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Law names on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum LawArg {
    /// Linear elasticity in a frame that turns with each element: small strains, large rotations.
    Corotational,
    /// Compressible Neo-Hookean with a logarithmic volume term, for large strains (eq 2.1).
    NeoHookean,
    /// Neo-Hookean with a separate bulk term on the volume change, for nearly
    /// incompressible gels such as the DIGIT's (eq 5.6).
    NeoHookeanBulk,
}

/// How the bellows' rigid parts are modelled.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum RigidArg {
    /// Rigid-body constraints (six DOFs per part, exactly rigid).
    Constraint,
    /// Stiff penalty (elements 100x stiffer).
    Penalty,
}

impl From<RigidArg> for RigidMode {
    fn from(r: RigidArg) -> Self {
        match r {
            RigidArg::Constraint => RigidMode::Constraint,
            RigidArg::Penalty => RigidMode::Penalty,
        }
    }
}

impl From<LawArg> for Law {
    fn from(l: LawArg) -> Self {
        match l {
            LawArg::Corotational => Law::Corotational,
            LawArg::NeoHookean => Law::NeoHookean,
            LawArg::NeoHookeanBulk => Law::NeoHookeanBulk,
        }
    }
}

/// Runs an `ocm fem` subcommand.
pub fn run(cmd: FemCommand) -> anyhow::Result<()> {
    match cmd {
        FemCommand::Info { mesh } => {
            let is_stl = mesh
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("stl"));
            let m = if is_stl {
                stl::read_path(&mesh)?
            } else {
                vtk::read_path(&mesh)?
            };
            let (lo, hi) = m.bounds();
            println!(
                "{}: {} points, {} tets, {} triangles, skipped cells {:?}, bounds {:?} .. {:?}",
                mesh.display(),
                m.points.len(),
                m.tets.len(),
                m.triangles.len(),
                m.skipped,
                lo,
                hi
            );
            Ok(())
        }
        FemCommand::Run { scene, out, json } => {
            let text = std::fs::read_to_string(&scene)
                .with_context(|| format!("reading {}", scene.display()))?;
            let sc = Scene::from_toml(&text)?;
            let base = scene.parent().map(PathBuf::from).unwrap_or_default();
            let prepared = sc.prepare(&base)?;
            let n = prepared
                .dynamic
                .as_ref()
                .map_or(prepared.loads.len(), |d| d.steps);
            // the output directory first: a path that cannot be written fails before the solve
            if let Some(dir) = &out {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating the output directory {}", dir.display()))?;
            }
            let pb = bar(n, "solving");
            let t0 = std::time::Instant::now();
            let results = prepared.run(|k, _| pb.set_position(k as u64))?;
            pb.finish_and_clear();
            let secs = t0.elapsed().as_secs_f64();
            if let Some(dir) = &out {
                let scale: Vec<f64> = prepared
                    .model
                    .element_scale
                    .iter()
                    .copied()
                    .chain(std::iter::repeat_n(1.0, prepared.mesh.triangles.len()))
                    .collect();
                for (k, r) in results.iter().enumerate() {
                    let path = dir.join(format!("result_{k:04}.vtk"));
                    vtk::write_path(
                        &path,
                        &prepared.mesh,
                        &r.label,
                        &[vtk::Field::Vector("displacement_m", &r.displacement)],
                        &[vtk::Field::Scalar("stiffness_scale", &scale)],
                    )?;
                }
            }
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "seconds": secs, "results": results })
                );
            } else {
                for r in &results {
                    print!(
                        "{}: max |u| = {:.4e} m, {} Newton iterations",
                        r.label, r.max_displacement_m, r.iterations
                    );
                    if let Some(b) = &r.bellows {
                        print!(
                            ", TCP = ({:.2}, {:.2}, {:.2}) mm, arc {:.2} mm, curvature {:.3} 1/m",
                            b.tcp_m[0] * 1e3,
                            b.tcp_m[1] * 1e3,
                            b.tcp_m[2] * 1e3,
                            b.arc_length_m * 1e3,
                            b.curvature_per_m
                        );
                    }
                    println!();
                }
                println!("{} results in {secs:.2} s", results.len());
            }
            Ok(())
        }
        FemCommand::Material { json } => {
            let m = ocm_fem::calibration::bellows_material();
            if json {
                println!("{}", serde_json::to_string(&m)?);
            } else {
                let p = &m.provenance;
                println!(
                    "bellows material: {:?}, E = {:.3} MPa, nu = {}, density {} kg/m^3",
                    m.law,
                    m.young_pa * 1e-6,
                    m.poisson,
                    m.density_kg_m3
                );
                let mm =
                    |v: Option<f64>| v.map_or("not recorded".to_string(), |x| format!("{x:.2} mm"));
                println!(
                    "from `{}` on {} against {}: best cell RMSE {} aligned, {} raw",
                    p.command,
                    p.mesh,
                    p.reference,
                    mm(p.grid_best_rmse_aligned_mm),
                    mm(p.grid_best_rmse_raw_mm)
                );
                println!(
                    "{}-state sweep: TCP RMSE {} raw (mesh frame), {:.2} mm after rotating the reference frame about z ({}); lateral gain FEM/ref {} (not fitted)",
                    p.sweep_states,
                    mm(p.sweep_rmse_raw_mm),
                    p.sweep_rmse_aligned_mm,
                    p.sweep_frame_rotation_deg
                        .map_or("angle not recorded".to_string(), |d| format!("{d:.1} deg")),
                    p.sweep_lateral_gain
                        .map_or("not recorded".to_string(), |g| format!("{g:.2}"))
                );
                println!("objective: {}", p.objective);
            }
            Ok(())
        }
        FemCommand::Sweep {
            data,
            mesh,
            values_kpa,
            law,
            young_pa,
            poisson,
            rigid,
            out,
            npy,
            reference,
            json,
        } => {
            let mesh = data_path(mesh, data.as_deref(), BELLOWS_MESH)?;
            let reference = match reference {
                Some(r) => Some(r),
                None => ocm_datadir::data_file(data.as_deref(), PRESSURE_TABLE).ok(),
            };
            let d = BellowsConfig::default();
            let cfg = BellowsConfig {
                law: law.map_or(d.law, Into::into),
                young_pa: young_pa.unwrap_or(d.young_pa),
                poisson: poisson.unwrap_or(d.poisson),
                rigid: rigid.into(),
                ..d
            };
            let b = Bellows::load(&mesh, cfg.clone())?;
            // the outputs' folders first: a path that cannot be written fails before the sweep
            for file in std::iter::once(&out).chain(npy.as_ref()) {
                if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("creating the folder of {}", file.display()))?;
                }
            }
            let states = sweep::grid(&values_kpa);
            let pb = bar(states.len(), "pressure states");
            let mut snaps: Vec<Vec<f64>> = vec![];
            let t0 = std::time::Instant::now();
            let pts = sweep::run(&b, &states, |k, _, s| {
                pb.set_position(k as u64 + 1);
                if npy.is_some() {
                    snaps.push(s.displacements(&b.model).into_iter().flatten().collect());
                }
            })?;
            pb.finish_and_clear();
            let secs = t0.elapsed().as_secs_f64();
            std::fs::write(&out, sweep::to_csv(&pts))
                .with_context(|| format!("writing {}", out.display()))?;
            if let Some(p) = &npy {
                ocm_fem::npy::write_snapshots(p, &snaps)?;
            }
            let cmp = match &reference {
                Some(r) => Some(sweep::compare(&pts, &sweep::read_reference(r)?)?),
                None => None,
            };
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "states": pts.len(), "seconds": secs, "csv": out,
                        "material": { "law": cfg.law, "young_pa": cfg.young_pa, "poisson": cfg.poisson },
                        "comparison": cmp,
                        "alignment": "rmse_aligned_m fits one angle: the rotation of the reference x-y frame about z; lateral_gain is reported, not fitted" })
                );
            } else {
                println!(
                    "{} states ({:?}, E = {:.3} MPa, nu = {}) in {secs:.1} s -> {}",
                    pts.len(),
                    cfg.law,
                    cfg.young_pa * 1e-6,
                    cfg.poisson,
                    out.display()
                );
                if let (Some(c), Some(reference)) = (cmp, &reference) {
                    println!(
                        "vs {}: {} matched, TCP RMSE {:.2} mm raw (mesh frame, nothing fitted); fitting one rotation of the reference frame about z ({:.1} deg) -> {:.2} mm; lateral gain FEM/ref {:.2} (not fitted)",
                        reference.display(),
                        c.matched,
                        c.rmse_m * 1e3,
                        c.frame_rotation_deg,
                        c.rmse_aligned_m * 1e3,
                        c.lateral_gain
                    );
                }
            }
            Ok(())
        }
        FemCommand::Calibrate(CalibrateCommand::Fit { data, csv, json }) => {
            let csv = data_path(csv, data.as_deref(), E50_CSV)?;
            let data = calibrate::read_stress_stretch_kpa(&csv)?;
            let nh = calibrate::fit_neo_hookean(&data)?;
            let mr = calibrate::fit_mooney_rivlin(&data)?;
            let e0 = calibrate::initial_modulus(&data, 0.03)?;
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "samples": data.len(), "stress_unit_assumed": "kPa", "initial_modulus_pa": e0, "fits": [nh, mr] })
                );
            } else {
                println!("{} samples (stress read as kPa)", data.len());
                println!("initial modulus (strain <= 3 %): E = {:.4} MPa", e0 * 1e-6);
                for f in [nh, mr] {
                    let p: Vec<String> = f
                        .params
                        .iter()
                        .map(|(n, v)| format!("{n} = {:.2} kPa", v * 1e-3))
                        .collect();
                    println!(
                        "{}: {}, E(small strain) = {:.3} MPa, RMSE = {:.2} kPa",
                        f.model,
                        p.join(", "),
                        f.young_pa * 1e-6,
                        f.rmse_pa * 1e-3
                    );
                }
            }
            Ok(())
        }
        FemCommand::Calibrate(CalibrateCommand::Grid {
            data,
            mesh,
            youngs_pa,
            poissons,
            states,
            reference,
            law,
            json,
        }) => {
            let states: Vec<[f64; 3]> = states
                .iter()
                .map(|s| {
                    let v: Vec<f64> = s
                        .split(':')
                        .map(|t| t.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
                        .collect::<Option<_>>()
                        .with_context(|| {
                            format!("--states: '{s}' must be three finite pressures p1:p2:p3, kPa")
                        })?;
                    if v.len() != 3 {
                        bail!("--states: '{s}' must be three pressures p1:p2:p3, kPa");
                    }
                    Ok([v[0], v[1], v[2]])
                })
                .collect::<anyhow::Result<_>>()?;
            let mesh = data_path(mesh, data.as_deref(), BELLOWS_MESH)?;
            let reference = data_path(reference, data.as_deref(), PRESSURE_TABLE)?;
            let law: Law = law.map_or(BellowsConfig::default().law, Into::into);
            let refs = sweep::read_reference(&reference)?;
            let mut raw = std::collections::HashMap::new();
            let pb = bar(youngs_pa.len() * poissons.len(), "(E, nu) grid");
            let mut k = 0;
            let (cells, best) = calibrate::grid_search(&youngs_pa, &poissons, |e, nu| {
                k += 1;
                pb.set_position(k);
                let cfg = BellowsConfig {
                    law,
                    young_pa: e,
                    poisson: nu,
                    ..BellowsConfig::default()
                };
                let b = Bellows::load(&mesh, cfg)?;
                let pts = sweep::run(&b, &states, |_, _, _| {})?;
                let c = sweep::compare(&pts, &refs)?;
                raw.insert((e.to_bits(), nu.to_bits()), c.rmse_m);
                Ok(c.rmse_aligned_m)
            })?;
            pb.finish_and_clear();
            let raw_of = |c: &calibrate::GridCell| {
                raw.get(&(c.young_pa.to_bits(), c.poisson.to_bits()))
                    .copied()
                    .unwrap_or(f64::NAN)
            };
            if json {
                let raw_cells: Vec<f64> = cells.iter().map(raw_of).collect();
                println!(
                    "{}",
                    serde_json::json!({ "cells": cells, "raw_rmse_m": raw_cells, "best": best,
                        "best_raw_rmse_m": raw_of(&best),
                        "error": "TCP RMSE after the best rotation of the reference frame about z, m" })
                );
            } else {
                for c in &cells {
                    println!(
                        "E = {:8.3} MPa, nu = {:.3}: TCP RMSE {:.3} mm aligned (frame rotated about z), {:.3} mm raw",
                        c.young_pa * 1e-6,
                        c.poisson,
                        c.error * 1e3,
                        raw_of(c) * 1e3
                    );
                }
                println!(
                    "best: E = {:.3} MPa, nu = {:.3}, RMSE {:.3} mm aligned, {:.3} mm raw",
                    best.young_pa * 1e-6,
                    best.poisson,
                    best.error * 1e3,
                    raw_of(&best) * 1e3
                );
            }
            Ok(())
        }
    }
}
