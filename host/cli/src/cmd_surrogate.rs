//! `ocm surrogate`: the rigid-link surrogate of the bellows manipulator: FEM samples and
//! geometry, URDF, actuation mapping with plots, and the simulation benchmark.

use crate::cmd_fem::{BELLOWS_MESH, data_path};
use crate::plot::{Chart, Series};
use crate::progress::{bar, bar_if};
use anyhow::Context;
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_surrogate::bench::{BenchConfig, Engine};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::fem_samples::{self, FemSamples};
use ocm_surrogate::mapping::MatchConfig;
use ocm_surrogate::model::SurrogateModel;
use std::path::PathBuf;

/// Surrogate subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum SurrogateCommand {
    /// Solves the full static FEM over a pressure grid (-20..35 kPa per chamber, continued from
    /// state to state) and seeded random held-out pressures, stores the boundary nodes of every
    /// bellows layer and the TCP (fem_samples.json), and measures the layers: regression planes,
    /// contact radii R_i, R_min, link dimensions (geometry.json).
    Geometry {
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Bellows mesh (VTK, mm); default: the data directory's ManipulatorWhole25.vtk.
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Pressure levels per chamber of the training grid.
        #[arg(long, default_value_t = 6)]
        levels: usize,
        /// Held-out random pressure triples.
        #[arg(long, default_value_t = 30)]
        held_out: usize,
        /// Seed of the held-out pressures.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Writes the URDF of the surrogate measured on FEM samples (surrogate.urdf).
    Urdf {
        /// FEM samples (from `ocm surrogate geometry`).
        samples: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Algorithm 1 (bounded L-BFGS-B under the grouped constraints) on every sample, f_SP and its
    /// inverse, errors on training and held-out samples, force calibration on the jig over the
    /// whole pressure range (the FEM clamped by its top frame, the surrogate held by its TCP, both
    /// at the FEM's rest pose); writes surrogate.json, surrogate.urdf, map_errors.csv,
    /// force_calibration.csv and the plots workspace_xz / workspace_yz / map_error /
    /// force_calibration_x|y|z.
    Map {
        /// FEM samples (from `ocm surrogate geometry`).
        samples: PathBuf,
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Bellows mesh (VTK, mm); default: the data directory's ManipulatorWhole25.vtk.
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Force-calibration pressures besides the eight corners of -20..35 kPa (seeded random,
        /// the same range); 0 skips the calibration.
        #[arg(long, default_value_t = 24)]
        force_samples: usize,
        /// Held-out force-calibration pressures (seeded random, in turn inside -10..10, -20..20
        /// and -20..35 kPa, so the fit's error is reported per range), scored only.
        #[arg(long, default_value_t = 24)]
        force_held_out: usize,
        /// How the surrogate is held on the force jig: pinned (the TCP point) or clamped (the
        /// TCP and the plate's orientation). The FEM is always clamped by its top frame.
        #[arg(long, default_value = "pinned")]
        force_hold: String,
        /// Iteration cap of Algorithm 1.
        #[arg(long, default_value_t = 200)]
        max_iterations: usize,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Steps per second of batched surrogate environments, free and with contact (median of
    /// repeats; one line per engine).
    Bench {
        /// Surrogate model (from `ocm surrogate map`).
        model: PathBuf,
        /// all, batch (reduced coordinates, free), batch-contact (reduced coordinates, plate
        /// above the TCP, penalty contact) or rapier (multibody, plate above the TCP, rigid
        /// contact of every link).
        #[arg(long, default_value = "all")]
        engine: String,
        /// Environments.
        #[arg(long, default_value_t = 64)]
        envs: usize,
        /// Steps per environment and repeat.
        #[arg(long, default_value_t = 500)]
        steps: usize,
        /// Threads.
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Repeats.
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

fn mkdir(out: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))
}

/// Runs a surrogate subcommand.
pub fn run(cmd: SurrogateCommand) -> anyhow::Result<()> {
    match cmd {
        SurrogateCommand::Geometry {
            data,
            mesh,
            levels,
            held_out,
            seed,
            out,
            json,
        } => {
            mkdir(&out)?;
            let path = data_path(mesh, data.as_deref(), BELLOWS_MESH)?;
            let b = Bellows::load(&path, BellowsConfig::default())?;
            let grid = fem_samples::pressure_grid(levels);
            let held = fem_samples::random_pressures(held_out, seed);
            let pb = bar(grid.len() + held.len(), "FEM statics");
            let s = fem_samples::collect(&b, &grid, &held, |k| pb.set_position(k as u64))?;
            pb.finish_and_clear();
            s.write(&out.join("fem_samples.json"))?;
            let g = ocm_surrogate::geometry::measure(&s)?;
            std::fs::write(out.join("geometry.json"), serde_json::to_string_pretty(&g)?)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&g)?);
            } else {
                for (k, l) in g.layers.iter().enumerate() {
                    println!(
                        "layer {}: z {:.1} mm, R {:.2} mm ({:.2}..{:.2}), plane rms {:.2} mm",
                        k + 1,
                        l.rest_height_m * 1e3,
                        l.radius_mean_m * 1e3,
                        l.radius_range_m[0] * 1e3,
                        l.radius_range_m[1] * 1e3,
                        l.plane_rms_m * 1e3
                    );
                }
                println!(
                    "R_min {:.2} mm, arc {:.1}..{:.1} mm, segment {:.2} mm; wrote {}",
                    g.r_min_m * 1e3,
                    g.arc_length_range_m[0] * 1e3,
                    g.arc_length_range_m[1] * 1e3,
                    g.chain.segment_length_m * 1e3,
                    out.display()
                );
            }
        }
        SurrogateCommand::Urdf { samples, out, json } => {
            mkdir(&out)?;
            let s = FemSamples::read(&samples)?;
            let g = ocm_surrogate::geometry::measure(&s)?;
            let path = out.join("surrogate.urdf");
            std::fs::write(
                &path,
                ocm_surrogate::urdf::to_urdf("ocm_bellows_surrogate", &g.chain, &Limits::default()),
            )?;
            if json {
                println!("{}", serde_json::to_string_pretty(&g.chain)?);
            } else {
                println!("wrote {}", path.display());
            }
        }
        SurrogateCommand::Map {
            samples,
            data,
            mesh,
            force_samples,
            force_held_out,
            force_hold,
            max_iterations,
            out,
            json,
        } => {
            mkdir(&out)?;
            let s = FemSamples::read(&samples)?;
            let cfg = MatchConfig {
                max_iterations,
                ..MatchConfig::default()
            };
            let pb = bar(s.samples.len() + s.held_out.len(), "Algorithm 1");
            let mut m =
                SurrogateModel::build(&s, Limits::default(), cfg, |k| pb.set_position(k as u64))?;
            pb.finish_and_clear();
            let hold = match force_hold.as_str() {
                "pinned" => ocm_surrogate::force::JigHold::TcpPinned,
                "clamped" => ocm_surrogate::force::JigHold::PlateClamped,
                h => anyhow::bail!("unknown --force-hold {h:?} (pinned or clamped)"),
            };
            if force_samples > 0 {
                let path = data_path(mesh, data.as_deref(), BELLOWS_MESH)?;
                let b = Bellows::load(&path, BellowsConfig::default())?;
                let p = SurrogateModel::calibration_pressures(force_samples, 2);
                let held = ocm_surrogate::force::nested_random_pressures(force_held_out, 3);
                let pb = bar(p.len() + held.len(), "force jig");
                let fs = m.calibrate_force(
                    &b,
                    &p,
                    &held,
                    &ocm_surrogate::sim::SceneConfig::default(),
                    hold,
                    |k| pb.set_position(k as u64),
                )?;
                pb.finish_and_clear();
                let mut csv = String::from(
                    "set,p1_kpa,p2_kpa,p3_kpa,sur_fx_n,sur_fy_n,sur_fz_n,fem_fx_n,fem_fy_n,fem_fz_n\n",
                );
                for (i, p) in fs.pressures_kpa.iter().enumerate() {
                    let (a, b) = (fs.surrogate_n[i], fs.fem_n[i]);
                    csv.push_str(&format!(
                        "{},{},{},{},{},{},{},{},{},{}\n",
                        if i < fs.fit { "fit" } else { "held_out" },
                        p[0],
                        p[1],
                        p[2],
                        a[0],
                        a[1],
                        a[2],
                        b[0],
                        b[1],
                        b[2]
                    ));
                }
                if let Some(c) = &m.force_calibration {
                    force_plot(c, &fs, &out)?;
                }
                std::fs::write(out.join("force_calibration.csv"), csv)?;
            }
            m.write(&out.join("surrogate.json"))?;
            std::fs::write(
                out.join("surrogate.urdf"),
                ocm_surrogate::urdf::to_urdf("ocm_bellows_surrogate", &m.geometry.chain, &m.limits),
            )?;
            plots(&m, &s, &out)?;
            let motion = range_of_motion(&m);
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&serde_json::json!({
                        "training": m.training, "held_out": m.held_out,
                        "range_of_motion": motion,
                        "force_calibration": m.force_calibration
                    }))?
                );
            } else {
                println!(
                    "Algorithm 1 on the {} training samples: |theta| up to {:.4} rad (limit {}), d {:.4}..{:.4} m (limits {}..{}), an extension at its upper limit in {} samples",
                    m.training_postures.len(),
                    motion.max_abs_rotation_rad,
                    m.limits.revolute_rad[1],
                    motion.extension_m[0],
                    motion.extension_m[1],
                    m.limits.prismatic_m[0],
                    m.limits.prismatic_m[1],
                    motion.samples_at_extension_limit
                );
                let h = &m.held_out;
                println!(
                    "held-out ({}): TCP RMSE {:.3} mm (max {:.3}), joints {:.3} deg / {:.3} mm, inverse {:.3} kPa; wrote {}",
                    h.samples,
                    h.mapped_tcp_rmse_m * 1e3,
                    h.mapped_tcp_max_m * 1e3,
                    h.rotation_mae_rad.to_degrees(),
                    h.extension_mae_m * 1e3,
                    h.inverse_rmse_kpa,
                    out.display()
                );
                if let Some(c) = &m.force_calibration {
                    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                        println!(
                            "force {axis}: FEM = {:.4} x surrogate + {:.3} N, fit RMSE {:.3} N, R^2 {:.3} ({} pressures); held-out RMSE {:.3} N ({})",
                            c.slope[k],
                            c.offset_n[k],
                            c.rmse_n[k],
                            c.r2[k],
                            c.samples,
                            c.held_out_rmse_n[k],
                            c.held_out_samples
                        );
                    }
                    for r in &c.by_range {
                        let f = |v: [f64; 3]| format!("{:.3} / {:.3} / {:.3}", v[0], v[1], v[2]);
                        println!(
                            "force, every chamber in {}..{} kPa: RMSE x/y/z {} N over {} pressures (held-out {} N over {}); FEM span {} N",
                            r.range_kpa[0],
                            r.range_kpa[1],
                            f(r.rmse_n),
                            r.samples,
                            f(r.held_out_rmse_n),
                            r.held_out_samples,
                            f(r.fem_span_n)
                        );
                    }
                }
            }
        }
        SurrogateCommand::Bench {
            model,
            engine,
            envs,
            steps,
            threads,
            repeats,
            json,
        } => {
            let m = SurrogateModel::read(&model)?;
            let engines = if engine == "all" {
                Engine::ALL.to_vec()
            } else {
                vec![Engine::parse(&engine)?]
            };
            let mut reports = vec![];
            let pb = bar_if(engines.len() * repeats, "bench repeats", !json);
            for (e, engine) in engines.iter().enumerate() {
                let r = ocm_surrogate::bench::run_with_progress(
                    &m.geometry.chain,
                    &m.limits,
                    &BenchConfig {
                        engine: *engine,
                        envs,
                        steps,
                        threads,
                        repeats,
                        seed: 1,
                    },
                    |k| pb.set_position((e * repeats + k) as u64),
                )?;
                if !json {
                    pb.suspend(|| {
                        println!(
                            "{:>9.0} steps/s  {} (median of {repeats}; {envs} envs x {steps} steps on {threads} threads; TCP in contact {:.0} % of steps)",
                            r.steps_per_s_median,
                            r.engine,
                            100.0 * r.contact_fraction
                        )
                    });
                }
                reports.push(r);
            }
            pb.finish_and_clear();
            if json {
                println!("{}", serde_json::to_string_pretty(&reports)?);
            }
        }
    }
    Ok(())
}

/// How much of the joint limits Algorithm 1 uses to follow the FEM over the training samples.
#[derive(serde::Serialize)]
struct RangeOfMotion {
    max_abs_rotation_rad: f64,
    extension_m: [f64; 2],
    samples_at_extension_limit: usize,
}

fn range_of_motion(m: &SurrogateModel) -> RangeOfMotion {
    use ocm_surrogate::chain::{JointKind, KINDS};
    let (mut rot, mut lo, mut hi, mut at) = (0.0f64, f64::INFINITY, f64::NEG_INFINITY, 0);
    let top = m.limits.prismatic_m[1];
    for q in &m.training_postures {
        let mut hit = false;
        for (j, &v) in q.iter().enumerate() {
            if KINDS[j] == JointKind::Prismatic {
                (lo, hi) = (lo.min(v), hi.max(v));
                hit |= v >= top - 1e-9;
            } else {
                rot = rot.max(v.abs());
            }
        }
        at += usize::from(hit);
    }
    RangeOfMotion {
        max_abs_rotation_rad: rot,
        extension_m: [lo, hi],
        samples_at_extension_limit: at,
    }
}

/// FEM jig force against the calibrated surrogate force, one plot per component
/// (force_calibration_x / _y / _z, Fig 4.13 D style).
fn force_plot(
    c: &ocm_surrogate::force::ForceCalibration,
    fs: &ocm_surrogate::model::ForceSamples,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let point = |i: usize| {
            (
                c.slope[k] * fs.surrogate_n[i][k] + c.offset_n[k],
                fs.fem_n[i][k],
            )
        };
        let (lo, hi) = fs
            .fem_n
            .iter()
            .map(|f| f[k])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let x_label = format!("calibrated surrogate F_{axis} (N)");
        let y_label = format!("FEM F_{axis} (N)");
        Chart {
            title: "Force calibration: FEM jig force against the calibrated surrogate's",
            x_label: &x_label,
            y_label: &y_label,
            series: vec![
                Series {
                    label: "fit pressures".into(),
                    points: (0..fs.fit).map(point).collect(),
                    dots: true,
                },
                Series {
                    label: "held-out pressures".into(),
                    points: (fs.fit..fs.fem_n.len()).map(point).collect(),
                    dots: true,
                },
                Series {
                    label: "identity".into(),
                    points: vec![(lo, lo), (hi, hi)],
                    dots: false,
                },
            ],
            equal_axes: true,
        }
        .write(out, &format!("force_calibration_{axis}"))?;
    }
    Ok(())
}

/// Workspace of FEM and surrogate TCPs (Fig 4.20 style) and the per-sample mapping error.
fn plots(m: &SurrogateModel, s: &FemSamples, out: &std::path::Path) -> anyhow::Result<()> {
    let chain = &m.geometry.chain;
    let mut csv = String::from(
        "set,p1_kpa,p2_kpa,p3_kpa,fem_x_m,fem_y_m,fem_z_m,sur_x_m,sur_y_m,sur_z_m,error_m\n",
    );
    let mut fem = vec![];
    let mut sur = vec![];
    let mut err = vec![];
    for (set, list) in [("training", &s.samples), ("held_out", &s.held_out)] {
        for (k, smp) in list.iter().enumerate() {
            let q = m.map.posture(&smp.pressures_kpa)?;
            let t = chain.tcp(&q);
            let e = (t - nalgebra::Vector3::from(smp.tcp_m)).norm();
            csv.push_str(&format!(
                "{set},{},{},{},{},{},{},{},{},{},{}\n",
                smp.pressures_kpa[0],
                smp.pressures_kpa[1],
                smp.pressures_kpa[2],
                smp.tcp_m[0],
                smp.tcp_m[1],
                smp.tcp_m[2],
                t.x,
                t.y,
                t.z,
                e
            ));
            fem.push(smp.tcp_m);
            sur.push([t.x, t.y, t.z]);
            if set == "held_out" {
                err.push((k as f64, e * 1e3));
            }
        }
    }
    std::fs::write(out.join("map_errors.csv"), csv)?;
    for (stem, a, b, label) in [
        ("workspace_xz", 0, 2, "x (mm)"),
        ("workspace_yz", 1, 2, "y (mm)"),
    ] {
        let pts = |v: &Vec<[f64; 3]>| v.iter().map(|p| (p[a] * 1e3, p[b] * 1e3)).collect();
        Chart {
            title: "TCP workspace: FEM and surrogate at f_SP(P)",
            x_label: label,
            y_label: "z (mm)",
            series: vec![
                Series {
                    label: "FEM".into(),
                    points: pts(&fem),
                    dots: true,
                },
                Series {
                    label: "surrogate".into(),
                    points: pts(&sur),
                    dots: true,
                },
            ],
            equal_axes: true,
        }
        .write(out, stem)?;
    }
    Chart {
        title: "Surrogate TCP error at f_SP(P), held-out pressures",
        x_label: "held-out sample",
        y_label: "TCP error (mm)",
        series: vec![Series {
            label: "|X_P(f_SP(P)) - X_S(P)|".into(),
            points: err,
            dots: true,
        }],
        equal_axes: false,
    }
    .write(out, "map_error")?;
    Ok(())
}
