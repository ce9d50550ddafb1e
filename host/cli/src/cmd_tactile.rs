//! `ocm tactile`: the DIGIT gel pressed by rigid indenters, contact masks and metrics.

use crate::plot::{Chart, Series};
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::image_io::read_gray;
use ocm_tactile::indent::{IndentOptions, Indentation};
use ocm_tactile::indenter::Indenter;
use ocm_tactile::mask::{Grid, Mask, mask_from_fn};
use ocm_tactile::metrics;
use ocm_tactile::output::{StepRow, write_force_depth_csv, write_step};
use ocm_tactile::setup::digit_setups;
use std::path::PathBuf;

/// Which gel mesh.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum MeshArg {
    /// DIGIT_v8.vtk: 10,061 nodes, 43,150 tets.
    Fine,
    /// DIGIT_remesh2.vtk: 441 nodes.
    Coarse,
}

/// Tactile subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum TactileCommand {
    /// Presses an indenter of the set-up files into the gel in equal depth steps (default: 100
    /// steps of 10 um); writes per-step NPY fields, contact masks (PNG), VTK every few steps, the
    /// force-depth CSV and its plot.
    Indent {
        /// Set-up name from indenter_settings.json or unseen_indenter_settings.json (e.g. edge6).
        #[arg(long)]
        setup: String,
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Gel mesh.
        #[arg(long, value_enum, default_value = "fine")]
        mesh: MeshArg,
        /// Number of depth steps.
        #[arg(long, default_value_t = 100)]
        steps: usize,
        /// Depth step, um.
        #[arg(long, default_value_t = 10.0)]
        step_um: f64,
        /// Coulomb friction coefficient.
        #[arg(long, default_value_t = 0.0)]
        friction: f64,
        /// Young's modulus of the gel, Pa.
        #[arg(long, default_value_t = 0.3e6)]
        young_pa: f64,
        /// Poisson's ratio of the gel.
        #[arg(long, default_value_t = 0.45)]
        poisson: f64,
        /// Write a VTK file every this many steps (0: none; the last step always).
        #[arg(long, default_value_t = 10)]
        vtk_every: usize,
        /// Output folder.
        #[arg(long, default_value = "tactile-out")]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Compares two images: as masks (grey > 127) IoU, centroid and rotation errors in pixels
    /// and radians; as grey images L1, PSNR and SSIM.
    Metrics {
        /// First image (PNG or JPEG).
        a: PathBuf,
        /// Second image, same size.
        b: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
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

/// Runs an `ocm tactile` subcommand.
pub fn run(cmd: TactileCommand) -> anyhow::Result<()> {
    match cmd {
        TactileCommand::Indent {
            setup,
            data,
            mesh,
            steps,
            step_um,
            friction,
            young_pa,
            poisson,
            vtk_every,
            out,
            json,
        } => {
            let digit = ocm_datadir::data_file(data.as_deref(), "digit")?;
            let setups = digit_setups(&digit)?;
            let Some(s) = setups.iter().find(|s| s.name == setup) else {
                let names: Vec<&str> = setups.iter().map(|s| s.name.as_str()).collect();
                bail!(
                    "no set-up named '{setup}'; the set-up files list {}",
                    names.join(", ")
                );
            };
            let mesh_file = match mesh {
                MeshArg::Fine => "DIGIT_v8.vtk",
                MeshArg::Coarse => "DIGIT_remesh2.vtk",
            };
            let material = GelMaterial { young_pa, poisson };
            let gel = Gel::digit(digit.join(mesh_file), material)?;
            let indenter = Indenter::from_stl(&s.stl)?;
            let mut opts = IndentOptions::protocol(young_pa);
            opts.steps = steps;
            opts.step_m = step_um * 1e-6;
            opts.contact.friction = friction;
            std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
            let grid = Grid::for_gel(&gel);
            let mut run = Indentation::new(&s.name, &gel, &indenter, s.placement, opts)?;
            let pb = bar(steps, &format!("indent {}", s.name));
            let t0 = std::time::Instant::now();
            let mut rows = Vec::with_capacity(steps);
            let mut write_err = None;
            let outputs = run.run(|st| {
                let vtk = st.step == steps || (vtk_every > 0 && st.step % vtk_every == 0);
                match write_step(&out, &gel, &grid, st, vtk) {
                    Ok(m) => rows.push(StepRow::new(st, m)),
                    Err(e) => {
                        write_err.get_or_insert(e);
                    }
                }
                pb.inc(1);
            });
            pb.finish_and_clear();
            let elapsed = t0.elapsed().as_secs_f64();
            if let Some(e) = write_err {
                return Err(e.into());
            }
            let outputs = outputs?;
            write_force_depth_csv(&out.join("force_depth.csv"), &rows)?;
            Chart {
                title: &format!("Force-depth, {} ({} mesh)", s.name, mesh_file),
                x_label: "depth [mm]",
                y_label: "indenter force F_z [N]",
                series: vec![Series {
                    label: "FEM".into(),
                    points: rows.iter().map(|r| (r.depth_mm, r.force_n[2])).collect(),
                    dots: false,
                }],
                equal_axes: false,
            }
            .write(&out, "force_depth")?;
            let last = rows.last().context("no step ran")?;
            let iters: usize = outputs.iter().map(|o| o.newton_iterations).sum();
            let max_pen = outputs
                .iter()
                .map(|o| o.max_penetration_m)
                .fold(0.0, f64::max);
            let summary = serde_json::json!({
                "setup": s.name,
                "indenter": indenter.name,
                "mesh": mesh_file,
                "nodes": gel.num_nodes(),
                "steps": steps,
                "depth_mm": last.depth_mm,
                "force_n": last.force_n,
                "mask_area_mm2": last.mask.area_m2 * 1e6,
                "mask_centroid_mm": [last.mask.centroid_m[0] * 1e3, last.mask.centroid_m[1] * 1e3],
                "mask_angle_rad": last.mask.angle_rad,
                "newton_iterations": iters,
                "max_penetration_um": max_pen * 1e6,
                "penetration_tol_um": opts.contact.penetration_tol_m * 1e6,
                "seconds": elapsed,
                "seconds_per_step": elapsed / steps as f64,
                "out": out.display().to_string(),
            });
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!(
                    "{}: {} steps to {:.3} mm on {} ({} nodes): F_z {:.4} N, mask {:.3} mm^2 at ({:.3}, {:.3}) mm, axis {:.3} rad; {} Newton iterations, max penetration {:.3} um (tol {:.3}); {:.2} s/step; files in {}",
                    s.name,
                    steps,
                    last.depth_mm,
                    mesh_file,
                    gel.num_nodes(),
                    last.force_n[2],
                    last.mask.area_m2 * 1e6,
                    last.mask.centroid_m[0] * 1e3,
                    last.mask.centroid_m[1] * 1e3,
                    last.mask.angle_rad,
                    iters,
                    max_pen * 1e6,
                    opts.contact.penetration_tol_m * 1e6,
                    elapsed / steps as f64,
                    out.display()
                );
            }
            Ok(())
        }
        TactileCommand::Metrics { a, b, json } => {
            let ia = read_gray(&a)?;
            let ib = read_gray(&b)?;
            if (ia.rows, ia.cols) != (ib.rows, ib.cols) {
                bail!(
                    "{} is {}x{} but {} is {}x{}",
                    a.display(),
                    ia.cols,
                    ia.rows,
                    b.display(),
                    ib.cols,
                    ib.rows
                );
            }
            let grid = Grid {
                origin_m: [0.0, 0.0],
                pixel_m: 1.0,
                cols: ia.cols,
                rows: ia.rows,
            };
            let ma = mask_from_fn(grid, |r, c| ia.pixels[r * ia.cols + c] > 127.0);
            let mb: Mask = mask_from_fn(grid, |r, c| ib.pixels[r * ib.cols + c] > 127.0);
            let (sa, sb) = (ma.stats(), mb.stats());
            let v = serde_json::json!({
                "iou": metrics::iou(&ma, &mb)?,
                "centroid_error_px": metrics::centroid_error(&sa, &sb),
                "rotation_error_rad": metrics::rotation_error(sa.angle_rad, sb.angle_rad),
                "l1": metrics::l1(&ia.pixels, &ib.pixels)?,
                "psnr_db": metrics::psnr(&ia.pixels, &ib.pixels, 255.0)?,
                "ssim": metrics::ssim(&ia.pixels, &ib.pixels, ia.rows, ia.cols, 255.0)?,
            });
            if json {
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                for (k, x) in v.as_object().into_iter().flatten() {
                    println!("{k}: {x}");
                }
            }
            Ok(())
        }
    }
}
