//! `ocm fem`: finite-element runs, bellows pressure sweeps and material calibration.

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use ocm_fem::bellows::{Bellows, BellowsConfig, Law, RigidMode};
use ocm_fem::calibrate;
use ocm_fem::mesh::{stl, vtk};
use ocm_fem::scene::Scene;
use ocm_fem::sweep;
use std::path::PathBuf;

const BELLOWS_MESH: &str = "../shared/data/bellows-manipulator/ManipulatorWhole25.vtk";
const PRESSURE_TABLE: &str = "../shared/data/bellows-manipulator/Pressure_vs_Pos.csv";
const E50_CSV: &str = "../shared/data/bellows-manipulator/E50_stress_stretch.csv";

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
    Sweep {
        /// Bellows mesh (VTK, mm).
        #[arg(long, default_value = BELLOWS_MESH)]
        mesh: PathBuf,
        /// Pressure values per chamber, kPa (the grid is their cube).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "-20,0,20,35",
            allow_hyphen_values = true
        )]
        values_kpa: Vec<f64>,
        /// Constitutive law.
        #[arg(long, value_enum, default_value = "neo-hookean-bulk")]
        law: LawArg,
        /// Young's modulus, Pa.
        #[arg(long, default_value_t = 1.2e6)]
        young_pa: f64,
        /// Poisson's ratio.
        #[arg(long, default_value_t = 0.45)]
        poisson: f64,
        /// Rigid parts (base connectors, top frame): true rigid bodies or a stiff penalty.
        #[arg(long, value_enum, default_value = "constraint")]
        rigid: RigidArg,
        /// CSV output.
        #[arg(long, default_value = "bellows_sweep.csv")]
        out: PathBuf,
        /// Nodal displacement snapshots (states x 3N) as .npy.
        #[arg(long)]
        npy: Option<PathBuf>,
        /// Reference table to compare TCPs with (same pressures).
        #[arg(long, default_value = PRESSURE_TABLE)]
        reference: PathBuf,
        /// Print a JSON summary.
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
        /// CSV with columns stretch,stress.
        #[arg(long, default_value = E50_CSV)]
        csv: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// (E, nu) grid search (Ch.4.4.3): RMSE of bellows TCPs against a reference table.
    Grid {
        /// Bellows mesh (VTK, mm).
        #[arg(long, default_value = BELLOWS_MESH)]
        mesh: PathBuf,
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
        /// Reference table (pressures kPa, positions m).
        #[arg(long, default_value = PRESSURE_TABLE)]
        reference: PathBuf,
        /// Constitutive law.
        #[arg(long, value_enum, default_value = "neo-hookean-bulk")]
        law: LawArg,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Law names on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum LawArg {
    /// Corotational linear elasticity.
    Corotational,
    /// Neo-Hookean eq 2.1.
    NeoHookean,
    /// Neo-Hookean eq 5.6.
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

fn bar(n: usize, what: &str) -> ProgressBar {
    let b = ProgressBar::new(n as u64);
    if let Ok(style) =
        ProgressStyle::with_template("{msg} {bar:40} {pos}/{len} [{elapsed_precise} < {eta}]")
    {
        b.set_style(style);
    }
    b.set_message(what.to_string());
    b
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
            let pb = bar(n, "solving");
            let t0 = std::time::Instant::now();
            let results = prepared.run(|k, _| pb.set_position(k as u64))?;
            pb.finish_and_clear();
            let secs = t0.elapsed().as_secs_f64();
            if let Some(dir) = &out {
                std::fs::create_dir_all(dir)?;
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
        FemCommand::Sweep {
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
            let cfg = BellowsConfig {
                law: law.into(),
                young_pa,
                poisson,
                rigid: rigid.into(),
                ..BellowsConfig::default()
            };
            let b = Bellows::load(&mesh, cfg)?;
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
            let cmp = if reference.exists() {
                Some(sweep::compare(&pts, &sweep::read_reference(&reference)?)?)
            } else {
                None
            };
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "states": pts.len(), "seconds": secs, "csv": out, "comparison": cmp })
                );
            } else {
                println!("{} states in {secs:.1} s -> {}", pts.len(), out.display());
                if let Some(c) = cmp {
                    println!(
                        "vs {}: {} matched, TCP RMSE {:.2} mm (mesh frame), best frame rotation {:.1} deg -> RMSE {:.2} mm, lateral gain FEM/ref {:.2}",
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
        FemCommand::Calibrate(CalibrateCommand::Fit { csv, json }) => {
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
                        .map(|t| t.trim().parse::<f64>())
                        .collect::<Result<_, _>>()?;
                    if v.len() != 3 {
                        bail!("state '{s}' must be p1:p2:p3");
                    }
                    Ok([v[0], v[1], v[2]])
                })
                .collect::<anyhow::Result<_>>()?;
            let refs = sweep::read_reference(&reference)?;
            let pb = bar(youngs_pa.len() * poissons.len(), "(E, nu) grid");
            let mut k = 0;
            let (cells, best) = calibrate::grid_search(&youngs_pa, &poissons, |e, nu| {
                k += 1;
                pb.set_position(k);
                let cfg = BellowsConfig {
                    law: law.into(),
                    young_pa: e,
                    poisson: nu,
                    ..BellowsConfig::default()
                };
                let b = Bellows::load(&mesh, cfg)?;
                let pts = sweep::run(&b, &states, |_, _, _| {})?;
                Ok(sweep::compare(&pts, &refs)?.rmse_aligned_m)
            })?;
            pb.finish_and_clear();
            if json {
                println!("{}", serde_json::json!({ "cells": cells, "best": best }));
            } else {
                for c in &cells {
                    println!(
                        "E = {:8.3} MPa, nu = {:.3}: TCP RMSE {:.3} mm",
                        c.young_pa * 1e-6,
                        c.poisson,
                        c.error * 1e3
                    );
                }
                println!(
                    "best: E = {:.3} MPa, nu = {:.3}, RMSE {:.3} mm",
                    best.young_pa * 1e-6,
                    best.poisson,
                    best.error * 1e3
                );
            }
            Ok(())
        }
    }
}
