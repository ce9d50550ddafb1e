//! `ocm tactile`: the DIGIT gel pressed by rigid indenters, contact masks and metrics.

use crate::plot::{Chart, Series};
use crate::progress::bar;
use anyhow::{Context, bail};
use ocm_tactile::gel::{Gel, GelMaterial, Skin, VolumetricLaw};
use ocm_tactile::image_io::read_gray;
use ocm_tactile::indent::{IndentOptions, Indentation};
use ocm_tactile::indenter::Indenter;
use ocm_tactile::mask::{Grid, Mask, mask_from_fn};
use ocm_tactile::metrics;
use ocm_tactile::output::{StepRow, write_force_depth_csv, write_step};
use ocm_tactile::setup::digit_setups;
use std::path::{Path, PathBuf};

/// Which gel mesh.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum MeshArg {
    /// DIGIT_v8.vtk: 10,061 nodes, 43,150 tets; a flat 15 x 20 x 2 mm box.
    Fine,
    /// DIGIT_remesh2.vtk: 441 nodes; its top is domed (18.5 x 25 mm, 4.07 mm at the apex).
    Coarse,
}

/// Which model computes a data set's fields.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum DatasetModel {
    /// The full contact FEM.
    Fem,
    /// The POD-reduced model (`ocm tactile reduce`).
    Reduced,
}

/// The gel law's volumetric part for `indent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum VolumetricArg {
    /// Eq 5.6: kappa/2 (J - 1)^2 beside the isochoric Neo-Hookean term.
    Bulk,
    /// Eq 2.1: -mu ln J + lambda/2 (ln J)^2 beside mu/2 (I1 - 3).
    LogJ,
}

impl VolumetricArg {
    fn law(self) -> VolumetricLaw {
        match self {
            VolumetricArg::Bulk => VolumetricLaw::Bulk,
            VolumetricArg::LogJ => VolumetricLaw::LogJ,
        }
    }
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
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 100)]
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
        /// The gel law's volumetric part: eq 5.6's bulk term, or eq 2.1's ln J terms (the same
        /// small-strain E and nu, far stiffer under strong compression).
        #[arg(long, value_enum, default_value = "bulk")]
        volumetric: VolumetricArg,
        /// Crown of the gel's top face: radius of curvature of a dome centred on the top face,
        /// mm (0: the flat mesh). `compare-real` fits 14 mm on the real edge6 frames.
        #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 0.0)]
        crown_radius_mm: f64,
        /// Thickness of a surface layer of another stiffness (elements whose centroid lies
        /// this far below the top face), um (0: none).
        #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 0.0)]
        skin_um: f64,
        /// The surface layer's stiffness over the gel body's (with --skin-um).
        #[arg(long, value_parser = crate::arg_check::positive, default_value_t = 1.0)]
        skin_stiffness: f64,
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
    /// Renders DIGIT frames (PNG) from the FEM displacement fields of `indent` with a real
    /// DIGIT's optical calibration (slopes -> colour change) on a real background; with --bench
    /// it measures frames per second instead.
    Render {
        /// Folder with u_NNN.npy displacement fields written by `ocm tactile indent`.
        fields: PathBuf,
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Gel mesh the fields belong to.
        #[arg(long, value_enum, default_value = "fine")]
        mesh: MeshArg,
        /// Background (RGB, 320 x 240 or 640 x 480). Default: frame 00 of the real edge6
        /// sequence (no contact).
        #[arg(long)]
        background: Option<PathBuf>,
        /// Optical calibration (.npz). Default: digit/optics/taxim_polycalib.npz.
        #[arg(long)]
        calib: Option<PathBuf>,
        /// Camera map with the fitted gain and smoothing (JSON, as `compare-real` writes to
        /// map.json). Default: the networks' landscape frame (rows along gel x, columns along
        /// gel y, 0.0625 mm per pixel on DIGIT_v8; a larger gel is scaled to fit), calibrated
        /// gain 1, no smoothing.
        #[arg(long)]
        map: Option<PathBuf>,
        /// Render every this many steps (and the last).
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 10)]
        every: usize,
        /// Output folder for render_NNN.png.
        #[arg(long, default_value = "render-out")]
        out: PathBuf,
        /// Benchmark: render this many frames per repeat (5 repeats; no PNGs), print frames/s.
        #[arg(long)]
        bench: Option<usize>,
        /// Worker threads (rendering and benchmark).
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 2)]
        threads: usize,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// The FEM against the real DIGIT frames of the edge indentation (real-frames-edge6):
    /// measured contact masks (background subtraction against frame 00, threshold) against
    /// the FEM masks at the same depths, the gel-to-image map and the step offset fitted on the
    /// even frames and scored on the odd ones; then frames rendered from the FEM against the
    /// real frames (L1, PSNR, SSIM, mask IoU). Writes PNGs and summary.json.
    CompareReal {
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Gel mesh.
        #[arg(long, value_enum, default_value = "fine")]
        mesh: MeshArg,
        /// Set-up of the real sequence.
        #[arg(long, default_value = "edge6")]
        setup: String,
        /// FEM cache: u_NNN.npy from an earlier run of this set-up and mesh are reused; else the
        /// FEM runs and writes them there.
        #[arg(long, default_value = "out/tactile/edge6-fem")]
        fem: PathBuf,
        /// FEM steps of 10 um.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 100)]
        steps: usize,
        /// Mask threshold: mean |frame - background| over R, G, B after a 5 x 5 box blur,
        /// grey levels. A comma-separated list is a set of candidates: each is fitted on the
        /// even frames, and the best fit is kept (default 6,7,8,10; with --fit, the one in its
        /// map.json). The contact SSIM and L1 are taken over the real contact at 10 grey levels
        /// whatever the threshold.
        #[arg(long, value_delimiter = ',', value_parser = crate::arg_check::positive)]
        threshold: Option<Vec<f64>>,
        /// How the FEM's masks are drawn: 0 is the depth mask (-u_z above 30 um, Ch.6.5.1); a
        /// positive value is a slope mask, |grad u_z| after the real masks' 5 x 5 box blur above
        /// it (dimensionless; the camera sees the surface's normals, not its depth). A
        /// comma-separated list is a set of candidates fitted on the even frames with every
        /// threshold, tilt and crown (default 0; with --fit, the one in its map.json).
        #[arg(long, value_delimiter = ',', value_parser = crate::arg_check::non_negative)]
        fem_slope: Option<Vec<f64>>,
        /// Candidate tilts of the indenter about its own x axis, degrees, comma-separated (the
        /// edge indenter's edge runs along its y axis, so this lowers one end of the edge). Each
        /// candidate, crossed with every --roll-deg, is a FEM run of its own (cached beside
        /// --fem); the one whose masks fit the even frames best is kept, the odd frames score
        /// it (default 0; with --fit, the one in its map.json).
        #[arg(long, value_delimiter = ',', allow_hyphen_values = true,
              value_parser = crate::arg_check::finite)]
        pitch_deg: Option<Vec<f64>>,
        /// Candidate tilts of the indenter about its own y axis, degrees, comma-separated (the
        /// edge indenter rolls about its edge, pressing one flank more than the other; default
        /// 0; with --fit, the one in its map.json).
        #[arg(long, value_delimiter = ',', allow_hyphen_values = true,
              value_parser = crate::arg_check::finite)]
        roll_deg: Option<Vec<f64>>,
        /// Candidate crowns of the gel's top face: radius of curvature of a dome (apex: see
        /// --crown-apex), mm, comma-separated; 0 is the flat gel of the mesh. Real DIGIT gels
        /// are domed; the dome is flat beyond 0.7 of the gel's free thickness below its apex
        /// (1.05 mm on the DIGIT gel, past the protocol's 1 mm). Each candidate, crossed with
        /// the tilts, is a FEM run of its own (cached beside --fem) and the best fit on the even
        /// frames is kept (default 14 on the fine mesh, fitted on these frames, and 0 on the
        /// coarse one, whose top is domed already; with --fit, the one in its map.json).
        #[arg(long, value_delimiter = ',', value_parser = crate::arg_check::non_negative)]
        crown_radius_mm: Option<Vec<f64>>,
        /// Where the crown's apex lies: at the centre of the gel's top face, or under the middle
        /// of the indenter's tip (default gel-centre; with --fit, the one in its map.json).
        #[arg(long, value_enum)]
        crown_apex: Option<CrownApex>,
        /// Candidate thicknesses of a surface layer of another stiffness, um, comma-separated
        /// (0: none; elements whose centroid lies this far below the top face). Each, crossed
        /// with every --skin-stiffness, crown and tilt, is a FEM run of its own (default 0; with
        /// --fit, the one in its map.json).
        #[arg(long, value_delimiter = ',', value_parser = crate::arg_check::non_negative)]
        skin_um: Option<Vec<f64>>,
        /// Candidate stiffnesses of that layer over the gel body's, comma-separated (default 1;
        /// with --fit, the one in its map.json).
        #[arg(long, value_delimiter = ',', value_parser = crate::arg_check::positive)]
        skin_stiffness: Option<Vec<f64>>,
        /// The camera's scale, mm of gel per pixel of the 240 x 320 frame, when it is known:
        /// the map fit then keeps it and fits only the rotation, shift and mirror.
        #[arg(long, value_parser = crate::arg_check::positive)]
        mm_per_px: Option<f64>,
        /// Candidate FEM steps (10 um) per real frame, comma-separated: real frame k is paired
        /// with step round((k - offset) x this). The real frames are samples evenly spaced in
        /// time over a video, not taken at the steps; above 1 the indenter moved more than 10 um
        /// between them (give --steps enough FEM steps to reach the last frame). Each is fitted
        /// on the even frames with every tilt, crown and threshold (default 1; with --fit, the
        /// one in its map.json).
        #[arg(long, value_delimiter = ',', value_parser = crate::arg_check::positive)]
        steps_per_frame: Option<Vec<f64>>,
        /// Reuse the map, step offset and rate, mask threshold, tilt, crown and skin of an earlier run (its map.json)
        /// instead of fitting them (the slow part); the optics are fitted anew.
        #[arg(long)]
        fit: Option<PathBuf>,
        /// Optical parameters fitted on the even frames beside the smoothing: one gain on the
        /// calibrated change, or a colour transform and a depth shading.
        #[arg(long, value_enum, default_value = "colour-depth")]
        optics: OpticsArg,
        /// Output folder.
        #[arg(long, default_value = "out/tactile/compare-real")]
        out: PathBuf,
        /// Print the JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Builds the NPE dataset: per set-up and depth the top-face nodal displacement and contact
    /// force (FEM, cached per set-up and reused), pose, depth, total force and the contact
    /// points in the sensor frame, as NPY with manifest.json naming shapes and units, and the
    /// contact mask of every sample as PNG (mask_SSS.png) with its area, centroid and angle.
    Dataset {
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Gel mesh.
        #[arg(long, value_enum, default_value = "fine")]
        mesh: MeshArg,
        /// Depth steps (all saved).
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 20)]
        steps: usize,
        /// Depth step, um.
        #[arg(long, default_value_t = 50.0)]
        step_um: f64,
        /// Contact-point grid spacing, mm.
        #[arg(long, default_value_t = 0.25)]
        spacing_mm: f64,
        /// Set-ups (comma-separated; default: all seen and unseen).
        #[arg(long, value_delimiter = ',')]
        setups: Vec<String>,
        /// Only set-ups whose FEM cache folder exists (assemble what has been computed).
        #[arg(long)]
        cached_only: bool,
        /// Random placements added to the set-ups: positions over the top face and rotations
        /// about z of the `--random-from` indenters.
        #[arg(long, default_value_t = 0)]
        random: usize,
        /// Seed of the random placements.
        #[arg(long, default_value_t = 0)]
        random_seed: u64,
        /// Set-ups whose indenters are placed at random (comma-separated; default: all seen).
        #[arg(long, value_delimiter = ',')]
        random_from: Vec<String>,
        /// Margin between the tip centre and the top face's edge for random placements, mm.
        #[arg(long, default_value_t = 2.0)]
        random_margin_mm: f64,
        /// Only the random placements (not the set-up files' placements).
        #[arg(long)]
        random_only: bool,
        /// Which model computes the fields: the full FEM (cached per set-up) or the reduced
        /// model of `ocm tactile reduce` (resumable: set-ups already in --out are kept).
        #[arg(long, value_enum, default_value = "fem")]
        model: DatasetModel,
        /// The reduced model's folder (for --model reduced).
        #[arg(long, default_value = "out/tactile/rom")]
        rom: PathBuf,
        /// Threads of the reduced model's signed-distance queries.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 2)]
        threads: usize,
        /// With --model reduced: grow the basis of each set-up by its two footprint modes (the
        /// rest stiffness' responses to normal loads on the indenter's footprint and its rim).
        #[arg(long)]
        enrich: bool,
        /// FEM cache: one folder per set-up of u_NNN.npy / f_NNN.npy.
        #[arg(long, default_value = "out/npe/fem")]
        cache: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out/npe/dataset")]
        out: PathBuf,
        /// Print the manifest as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Builds the reduced tactile model (eq 5.1-5.5): POD of the full-FEM displacement fields
    /// (whole gel) of every cached set-up not held out, the reduced stiffness at rest, saved as
    /// NPY with rom.json; with --bench, runs it through the held-out set-ups' depths and prints
    /// frames per second and the nodal RMSE against their FEM.
    Reduce(ReduceArgs),
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
    /// Trains the perception network (RGB delta image -> surface displacement, a 3-level
    /// U-Net) or the rendering network (splatted displacement -> RGB delta image, a 2-level
    /// U-Net) on the FEM data set rendered by the physically based renderer; the unseen
    /// set-ups are held out and scored (IoU, centroid, rotation; L1, PSNR, SSIM).
    Train(crate::cmd_tactile_net::TrainNetArgs),
    /// Runs a trained perception network on RGB frames: depth and contact-mask PNGs and the
    /// nodal field U of the top face (NPY).
    Perceive(crate::cmd_tactile_net::PerceiveArgs),
}

/// Runs an `ocm tactile` subcommand.
pub fn run(cmd: TactileCommand) -> anyhow::Result<()> {
    match cmd {
        TactileCommand::Reduce(a) => reduce(a),
        TactileCommand::Train(a) => crate::cmd_tactile_net::train(a),
        TactileCommand::Perceive(a) => crate::cmd_tactile_net::perceive(a),
        TactileCommand::Indent {
            setup,
            data,
            mesh,
            steps,
            step_um,
            friction,
            young_pa,
            poisson,
            volumetric,
            crown_radius_mm,
            skin_um,
            skin_stiffness,
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
            let material = GelMaterial {
                volumetric: volumetric.law(),
                ..GelMaterial::new(young_pa, poisson)
            };
            let layer = skin(skin_um, skin_stiffness);
            let gel = crowned_gel(
                &digit.join(mesh_file),
                material,
                s,
                [0.0; 2],
                crown_radius_mm,
                CrownApex::GelCentre,
                layer,
            )?;
            let skin_elements = gel
                .model
                .element_scale
                .iter()
                .filter(|&&k| k != 1.0)
                .count();
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
            let held_from = outputs.iter().find(|o| o.held_planes).map(|o| o.step);
            let shifted: usize = outputs.iter().map(|o| o.shifted_solves).sum();
            let summary = serde_json::json!({
                "setup": s.name,
                "indenter": indenter.name,
                "mesh": mesh_file,
                "crown_radius_mm": crown_radius_mm,
                "volumetric": material.volumetric,
                "skin_um": layer.thickness_m * 1e6,
                "skin_stiffness": layer.stiffness_ratio,
                "skin_elements": skin_elements,
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
                "held_planes_from_step": held_from,
                "shifted_newton_iterations": shifted,
                "seconds": elapsed,
                "seconds_per_step": elapsed / steps as f64,
                "out": out.display().to_string(),
            });
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!(
                    "{}: {} steps to {:.3} mm on {} ({} nodes): F_z {:.4} N, {}; {} Newton iterations ({} on an indefinite tangent, shifted), max penetration {:.3} um (tol {}); {:.2} s/step; files in {}",
                    s.name,
                    steps,
                    last.depth_mm,
                    mesh_file,
                    gel.num_nodes(),
                    last.force_n[2],
                    if last.mask.area_m2 > 0.0 {
                        format!(
                            "mask {:.3} mm^2 at ({:.3}, {:.3}) mm, axis {:.3} rad",
                            last.mask.area_m2 * 1e6,
                            last.mask.centroid_m[0] * 1e3,
                            last.mask.centroid_m[1] * 1e3,
                            last.mask.angle_rad
                        )
                    } else {
                        "mask empty (no top-face point pressed beyond the 30 um threshold)".into()
                    },
                    iters,
                    shifted,
                    max_pen * 1e6,
                    match held_from {
                        Some(k) => format!(
                            "{:.3}; held contact planes from step {k}, tol {:.3} there",
                            opts.contact.penetration_tol_m * 1e6,
                            opts.held_penetration_tol_m() * 1e6
                        ),
                        None => format!("{:.3}", opts.contact.penetration_tol_m * 1e6),
                    },
                    elapsed / steps as f64,
                    out.display()
                );
            }
            Ok(())
        }
        TactileCommand::Render {
            fields,
            data,
            mesh,
            background,
            calib,
            map,
            every,
            out,
            bench,
            threads,
            json,
        } => render(RenderArgs {
            fields,
            data,
            mesh,
            background,
            calib,
            map,
            every,
            out,
            bench,
            threads,
            json,
        }),
        TactileCommand::CompareReal {
            data,
            mesh,
            setup,
            fem,
            steps,
            threshold,
            fem_slope,
            pitch_deg,
            roll_deg,
            crown_radius_mm,
            crown_apex,
            skin_um,
            skin_stiffness,
            mm_per_px,
            steps_per_frame,
            fit,
            optics,
            out,
            json,
        } => compare_real(CompareArgs {
            data,
            mesh,
            setup,
            fem,
            steps,
            threshold,
            fem_slope,
            pitch_deg,
            roll_deg,
            crown_radius_mm,
            crown_apex,
            skin_um,
            skin_stiffness,
            mm_per_px,
            steps_per_frame,
            fit,
            optics,
            out,
            json,
        }),
        TactileCommand::Dataset {
            data,
            mesh,
            steps,
            step_um,
            spacing_mm,
            setups,
            cached_only,
            random,
            random_seed,
            random_from,
            random_margin_mm,
            random_only,
            model,
            rom,
            threads,
            enrich,
            cache,
            out,
            json,
        } => {
            if random_only && random == 0 {
                bail!(
                    "--random-only keeps only the random placements, and --random is 0: give \
                     --random N (N > 0), or drop --random-only"
                );
            }
            let digit = ocm_datadir::data_file(data.as_deref(), "digit")?;
            let mesh_file = match mesh {
                MeshArg::Fine => "DIGIT_v8.vtk",
                MeshArg::Coarse => "DIGIT_remesh2.vtk",
            };
            let gel = Gel::digit(digit.join(mesh_file), GelMaterial::default())?;
            let all = digit_setups(&digit)?;
            if let Some(bad) = setups.iter().find(|n| !all.iter().any(|s| &s.name == *n)) {
                bail!("no set-up named '{bad}'");
            }
            if let Some(bad) = random_from
                .iter()
                .find(|n| !all.iter().any(|s| &s.name == *n))
            {
                bail!("--random-from: no set-up named '{bad}'");
            }
            let base: Vec<_> = all
                .iter()
                .filter(|s| {
                    if random_from.is_empty() {
                        !s.unseen
                    } else {
                        random_from.contains(&s.name)
                    }
                })
                .cloned()
                .collect();
            let placed = ocm_tactile::dataset::random_setups(
                &gel,
                &base,
                random,
                random_seed,
                random_margin_mm * 1e-3,
            )?;
            let chosen: Vec<_> = all
                .into_iter()
                .filter(|_| !random_only)
                .filter(|s| setups.is_empty() || setups.contains(&s.name))
                .chain(placed)
                .filter(|s| !cached_only || cache.join(&s.name).is_dir())
                .collect();
            let opts = ocm_tactile::dataset::DatasetOptions {
                steps,
                step_m: step_um * 1e-6,
                grid_spacing_m: spacing_mm * 1e-3,
            };
            let pb = bar(chosen.len(), "dataset");
            let t0 = std::time::Instant::now();
            let tick = |n: &str, _| {
                pb.set_message(format!("dataset {n}"));
                pb.inc(1);
            };
            let m = match model {
                DatasetModel::Fem => ocm_tactile::dataset::build(
                    &gel, mesh_file, &chosen, &opts, &cache, &out, tick,
                )?,
                DatasetModel::Reduced => {
                    let rm = ocm_tactile::reduced::ReducedModel::load(&rom)?;
                    let ro =
                        ocm_tactile::reduced::ReducedOptions::for_modulus(gel.material.young_pa);
                    let rest = if enrich {
                        Some(ocm_tactile::reduced::RestStiffness::new(&gel)?)
                    } else {
                        None
                    };
                    let loads = ocm_tactile::reduced::DEFAULT_FOOTPRINT_LOADS;
                    let e = rest.as_ref().map(|rest| ocm_tactile::reduced::Enrichment {
                        rest,
                        loads: &loads,
                    });
                    rayon_pool(threads)?.install(|| {
                        ocm_tactile::dataset::build_reduced(
                            &gel, mesh_file, &chosen, &opts, &rm, &rom, ro, e, &out, tick,
                        )
                    })?
                }
            };
            pb.finish_and_clear();
            let secs = t0.elapsed().as_secs_f64();
            if json {
                println!("{}", serde_json::to_string_pretty(&m)?);
            } else {
                let samples: usize = m.setups.iter().map(|s| s.samples).sum();
                println!(
                    "{} samples of {} set-ups ({} stopped early) on {} ({} top nodes) in {} \
                     ({:.1} s, {:.1} samples/s, model {})",
                    samples,
                    m.setups.len(),
                    m.stopped.len(),
                    mesh_file,
                    m.top_nodes,
                    out.display(),
                    secs,
                    samples as f64 / secs,
                    m.model
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

fn mesh_file(mesh: MeshArg) -> &'static str {
    match mesh {
        MeshArg::Fine => "DIGIT_v8.vtk",
        MeshArg::Coarse => "DIGIT_remesh2.vtk",
    }
}

struct RenderArgs {
    fields: PathBuf,
    data: Option<PathBuf>,
    mesh: MeshArg,
    background: Option<PathBuf>,
    calib: Option<PathBuf>,
    map: Option<PathBuf>,
    every: usize,
    out: PathBuf,
    bench: Option<usize>,
    threads: usize,
    json: bool,
}

/// Step numbers of the u_NNN.npy files in `dir`, sorted.
fn field_steps(dir: &std::path::Path) -> anyhow::Result<Vec<usize>> {
    let mut steps = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let name = e?.file_name().to_string_lossy().to_string();
        if let Some(n) = name
            .strip_prefix("u_")
            .and_then(|r| r.strip_suffix(".npy"))
            .and_then(|n| n.parse::<usize>().ok())
        {
            steps.push(n);
        }
    }
    steps.sort_unstable();
    if steps.is_empty() {
        bail!(
            "{} holds no u_NNN.npy fields (write them with `ocm tactile indent --out`)",
            dir.display()
        );
    }
    Ok(steps)
}

fn read_field(path: &std::path::Path, nodes: usize) -> anyhow::Result<Vec<[f64; 3]>> {
    let a = ocm_fem::npy::read_f64_2d(path)?;
    if a.rows != nodes || a.cols != 3 {
        bail!(
            "{} is {} x {}, the gel mesh has {nodes} nodes (x 3): wrong --mesh?",
            path.display(),
            a.rows,
            a.cols
        );
    }
    Ok(a.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

fn render(a: RenderArgs) -> anyhow::Result<()> {
    use ocm_tactile::optics::bench::bench_render;
    use ocm_tactile::optics::{CameraMap, PolyCalib, Renderer, RgbImage, SurfaceSampler};
    use ocm_tactile::real::{COLS, ROWS};
    let digit = ocm_datadir::data_file(a.data.as_deref(), "digit")?;
    let gel = Gel::digit(digit.join(mesh_file(a.mesh)), GelMaterial::default())?;
    let calib_path = a
        .calib
        .unwrap_or_else(|| digit.join(ocm_tactile::real::DEFAULT_CALIB));
    let calib = PolyCalib::from_npz(&calib_path)?;
    let bg_path = a
        .background
        .unwrap_or_else(|| digit.join(ocm_tactile::real::DEFAULT_BACKGROUND));
    let bg = RgbImage::read_sized(&bg_path, ROWS, COLS)?;
    let mut renderer = Renderer::new(calib, &bg)?;
    let map = match &a.map {
        Some(p) => {
            let v = read_map_json(p)?;
            // The optics fitted by compare-real travel with the map.
            if let Some(m) = v.get("colour") {
                let m: [[f32; 3]; 3] = serde_json::from_value(m.clone())
                    .with_context(|| format!("{}: colour is not 3 x 3", p.display()))?;
                renderer.colour = m;
            }
            if let Some(g) = v.get("depth_gain_per_m") {
                renderer.depth_gain = serde_json::from_value(g.clone()).with_context(|| {
                    format!("{}: depth_gain_per_m is not 3 numbers", p.display())
                })?;
            }
            if let Some(g) = v.get("gain").and_then(serde_json::Value::as_f64) {
                renderer.gain = g as f32;
            }
            if let Some(sm) = v.get("smooth_px").and_then(serde_json::Value::as_f64) {
                renderer.smooth_px = sm as f32;
            }
            serde_json::from_value::<CameraMap>(v.get("map").cloned().unwrap_or(v))
                .with_context(|| format!("{}: no camera map", p.display()))?
        }
        // The networks' landscape frame: the whole gel in the 240 x 320 image.
        None => ocm_tactile::optics::camera::fit_landscape(&gel, ROWS, COLS),
    };
    let sampler = SurfaceSampler::new(&gel, ROWS, COLS, &map);
    let steps = field_steps(&a.fields)?;
    if let Some(frames) = a.bench {
        let fields: Vec<Vec<[f64; 3]>> = steps
            .iter()
            .map(|s| read_field(&a.fields.join(format!("u_{s:03}.npy")), gel.num_nodes()))
            .collect::<anyhow::Result<_>>()?;
        let b = bench_render(&renderer, &sampler, &fields, frames, 5, a.threads)?;
        let v = serde_json::json!({
            "frames_per_repeat": b.frames,
            "repeats": b.fps.len(),
            "threads": b.threads,
            "image": [b.size[0], b.size[1]],
            "fps": b.fps,
            "median_fps": b.median_fps,
            "smooth_px": renderer.smooth_px,
            "goal_fps": 300,
            "goal_met": b.median_fps >= 300.0,
            "mesh": mesh_file(a.mesh),
            "fields": steps.len(),
        });
        if a.json {
            println!("{}", serde_json::to_string_pretty(&v)?);
        } else {
            println!(
                "renderer: median {:.0} frames/s on {} threads ({} x {} px, {} frames x {} repeats; goal 300)",
                b.median_fps,
                b.threads,
                b.size[1],
                b.size[0],
                b.frames,
                b.fps.len()
            );
        }
        return Ok(());
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let pool = rayon_pool(a.threads)?;
    let last = *steps.last().context("no steps")?;
    let chosen: Vec<usize> = steps
        .iter()
        .copied()
        .filter(|s| s % a.every == 0 || *s == last)
        .collect();
    let pb = bar(chosen.len(), "render");
    let mut written = Vec::new();
    for s in &chosen {
        let u = read_field(&a.fields.join(format!("u_{s:03}.npy")), gel.num_nodes())?;
        let img = pool.install(|| ocm_tactile::real::render_step(&renderer, &sampler, &u))?;
        let p = a.out.join(format!("render_{s:03}.png"));
        img.write_png(&p)?;
        written.push(p.display().to_string());
        pb.inc(1);
    }
    pb.finish_and_clear();
    let v = serde_json::json!({
        "mesh": mesh_file(a.mesh),
        "calibration": calib_path.display().to_string(),
        "background": bg_path.display().to_string(),
        "map": map,
        "pixels_on_gel": sampler.covered(),
        "images": written,
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "rendered {} frames ({} x {} px, {} on the gel) into {}",
            written.len(),
            COLS,
            ROWS,
            sampler.covered(),
            a.out.display()
        );
    }
    Ok(())
}

fn rayon_pool(threads: usize) -> anyhow::Result<ocm_tactile::optics::bench::Pool> {
    Ok(ocm_tactile::optics::bench::pool(threads)?)
}

struct CompareArgs {
    data: Option<PathBuf>,
    mesh: MeshArg,
    setup: String,
    fem: PathBuf,
    steps: usize,
    threshold: Option<Vec<f64>>,
    fem_slope: Option<Vec<f64>>,
    pitch_deg: Option<Vec<f64>>,
    roll_deg: Option<Vec<f64>>,
    crown_radius_mm: Option<Vec<f64>>,
    crown_apex: Option<CrownApex>,
    skin_um: Option<Vec<f64>>,
    skin_stiffness: Option<Vec<f64>>,
    mm_per_px: Option<f64>,
    steps_per_frame: Option<Vec<f64>>,
    fit: Option<PathBuf>,
    optics: OpticsArg,
    out: PathBuf,
    json: bool,
}

/// Where `compare-real` puts the apex of a crowned gel.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CrownApex {
    /// Under the middle of the indenter's tip (where the flat gel is first pressed).
    Tip,
    /// At the centre of the gel's top face (the sensor's own axis).
    GelCentre,
}

/// Optical parameters `compare-real` fits.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum OpticsArg {
    /// One gain on the calibrated colour change.
    Gain,
    /// A 3 x 3 colour transform of the calibrated change and a depth shading per channel.
    ColourDepth,
}

/// Reads map.json as `compare-real` writes it (or a bare camera map).
fn read_map_json(p: &std::path::Path) -> anyhow::Result<serde_json::Value> {
    let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not JSON", p.display()))
}

fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

fn mean(v: &[f64]) -> f64 {
    let s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    s.iter().sum::<f64>() / s.len().max(1) as f64
}

/// Real-mask thresholds `compare-real` fits among by default, grey levels (see the tactile
/// README: 7 fits the edge6 frames best, the earlier fixed 10 is kept among them).
const DEFAULT_THRESHOLDS: [f64; 4] = [6.0, 7.0, 8.0, 10.0];

/// Crown radius of the gel `compare-real` assumes by default, mm: fitted on the edge6 frames
/// among 10-25 mm with the apex at the gel's centre (see the tactile README).
const DEFAULT_CROWN_RADIUS_MM: f64 = 14.0;

/// The crown's cap (`ocm_tactile::gel::CROWN_MAX_DROP_SHARE`) of the maps written before
/// `map.json` recorded it.
const FIRST_CROWN_CAP_SHARE: f64 = 0.5;

/// The name `--crown-apex` takes for `apex`.
fn apex_name(apex: CrownApex) -> String {
    clap::ValueEnum::to_possible_value(&apex)
        .map(|v| v.get_name().to_string())
        .unwrap_or_default()
}

/// Displacement fields of a FEM run, one per step.
type Fields = Vec<Vec<[f64; 3]>>;

/// The candidate `compare-real` keeps: its shape's index, the real mask's threshold and the
/// FEM mask's slope (`--fem-slope`), the gel, its fields and the map fitted on them.
type Kept = (
    usize,
    [f64; 2],
    Gel,
    Fields,
    Option<ocm_tactile::real::MaskFit>,
);

/// The surface layer of `skin_um` um at `ratio` times the body's stiffness; a layer that
/// changes nothing (no thickness, or the body's stiffness) is written as 0 um at 1.
fn skin(skin_um: f64, ratio: f64) -> Skin {
    let layer = Skin {
        thickness_m: skin_um * 1e-6,
        stiffness_ratio: ratio,
    };
    if has_skin(&layer) {
        layer
    } else {
        Skin {
            thickness_m: 0.0,
            stiffness_ratio: 1.0,
        }
    }
}

/// The FEM mask of `--fem-slope` value `slope`: 0 is the depth mask.
fn mask_rule(slope: f64) -> ocm_tactile::mask::MaskRule {
    use ocm_tactile::mask::MaskRule;
    if slope > 0.0 {
        MaskRule::Slope(slope)
    } else {
        MaskRule::Depth
    }
}

/// Whether `skin` changes the gel.
fn has_skin(skin: &Skin) -> bool {
    skin.thickness_m > 0.0 && skin.stiffness_ratio != 1.0
}

/// The FEM cache of a candidate tilt, crown radius (mm, 0: flat) and surface layer: `fem`
/// itself untilted, flat and uniform, else a sibling folder named after them.
fn shape_cache(fem: &Path, tilt: [f64; 2], crown_mm: f64, apex: CrownApex, skin: &Skin) -> PathBuf {
    if tilt == [0.0, 0.0] && crown_mm == 0.0 && !has_skin(skin) {
        return fem.to_path_buf();
    }
    let mut name = fem
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "fem".into());
    if tilt != [0.0, 0.0] {
        name = format!("{name}-pitch{}-roll{}", tilt[0], tilt[1]);
    }
    if crown_mm != 0.0 {
        // The cap is part of the shape: caches made with another cap are not reused.
        name = format!(
            "{name}-crown{crown_mm}-cap{}",
            ocm_tactile::gel::CROWN_MAX_DROP_SHARE
        );
        if apex == CrownApex::GelCentre {
            name.push_str("-centre");
        }
    }
    if has_skin(skin) {
        name = format!(
            "{name}-skin{}x{}",
            skin.thickness_m * 1e6,
            skin.stiffness_ratio
        );
    }
    fem.with_file_name(name)
}

/// The gel at `path` with its top crowned to `crown_mm` (0: flat) about `apex` (the centre of
/// its top face, or the point under the middle of the tip of set-up `s`'s indenter tilted by
/// `tilt`) and its surface layer stiffened by `skin`.
fn crowned_gel(
    path: &Path,
    material: GelMaterial,
    s: &ocm_tactile::setup::Setup,
    tilt: [f64; 2],
    crown_mm: f64,
    apex: CrownApex,
    skin: Skin,
) -> anyhow::Result<Gel> {
    let mut gel = if crown_mm == 0.0 {
        Gel::digit(path, material)?
    } else {
        let apex_m = match apex {
            CrownApex::Tip => {
                let indenter = Indenter::from_stl(&s.stl)?;
                let mut euler = s.placement.euler_deg;
                euler[0] += tilt[0];
                euler[1] += tilt[1];
                let rot = ocm_tactile::indenter::Pose::rotation_from_degrees(euler);
                // The tip's middle: where the flat gel is first pressed (its lowest 20 um).
                let tip = indenter.tip_center_xy(&rot, 20e-6);
                [s.placement.xy_m[0] + tip[0], s.placement.xy_m[1] + tip[1]]
            }
            CrownApex::GelCentre => {
                let (lo, hi) = Gel::digit(path, material)?.top_bounds();
                [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])]
            }
        };
        let crown = ocm_tactile::gel::Crown {
            radius_m: crown_mm * 1e-3,
            apex_m,
        };
        Gel::digit_crowned(path, material, Some(&crown))?
    };
    if has_skin(&skin) {
        gel.stiffen_skin(&skin)?;
    }
    Ok(gel)
}

/// The FEM displacement fields of the set-up `s` tilted by `tilt` (degrees about the indenter's
/// own x and y axes, added to its Euler angles), read from `dir` when complete there, else run
/// and written there; with the run's seconds when it ran.
fn edge_fem(
    a: &CompareArgs,
    gel: &Gel,
    grid: &Grid,
    s: &ocm_tactile::setup::Setup,
    tilt: [f64; 2],
    dir: &Path,
) -> anyhow::Result<(Fields, Option<f64>)> {
    use ocm_tactile::real;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    if let Some(f) = real::read_cached_steps(dir, a.steps, gel.num_nodes()) {
        return Ok((f, None));
    }
    let indenter = Indenter::from_stl(&s.stl)?;
    let opts = IndentOptions {
        steps: a.steps,
        ..IndentOptions::protocol(gel.material.young_pa)
    };
    let mut placement = s.placement;
    placement.euler_deg[0] += tilt[0];
    placement.euler_deg[1] += tilt[1];
    let mut run = Indentation::new(&s.name, gel, &indenter, placement, opts)?;
    let pb = bar(
        a.steps,
        &format!(
            "FEM {} ({}, pitch {} roll {} deg)",
            s.name,
            mesh_file(a.mesh),
            tilt[0],
            tilt[1]
        ),
    );
    let t0 = std::time::Instant::now();
    let mut rows = Vec::new();
    let mut write_err = None;
    let outputs = run.run(|st| {
        match write_step(dir, gel, grid, st, st.step == a.steps) {
            Ok(m) => rows.push(StepRow::new(st, m)),
            Err(e) => {
                write_err.get_or_insert(e);
            }
        }
        pb.inc(1);
    });
    pb.finish_and_clear();
    if let Some(e) = write_err {
        return Err(e.into());
    }
    let outputs = outputs?;
    let secs = t0.elapsed().as_secs_f64();
    write_force_depth_csv(&dir.join("force_depth.csv"), &rows)?;
    Ok((
        outputs.into_iter().map(|o| o.displacement).collect(),
        Some(secs),
    ))
}

fn compare_real(a: CompareArgs) -> anyhow::Result<()> {
    use ocm_tactile::optics::{PolyCalib, Renderer};
    use ocm_tactile::real::{self, CompareOptions, MaskOptions};
    let t_start = std::time::Instant::now();
    // The candidates: as given, else from --fit's map.json, else the defaults.
    let given = [
        &a.threshold,
        &a.fem_slope,
        &a.pitch_deg,
        &a.roll_deg,
        &a.crown_radius_mm,
        &a.skin_um,
        &a.skin_stiffness,
        &a.steps_per_frame,
    ]
    .iter()
    .map(|v| v.as_ref().map_or(1, Vec::len))
    .product::<usize>();
    if a.fit.is_some() && given > 1 {
        bail!(
            "--fit reuses a fitted map: give the tilt, crown, skin, thresholds and steps per frame it was fitted with as one --pitch-deg, --roll-deg, --crown-radius-mm, --skin-um, --skin-stiffness, --threshold, --fem-slope and --steps-per-frame, or none (got {given} candidates)"
        );
    }
    let saved = a.fit.as_deref().map(read_map_json).transpose()?;
    let saved_value = |key: &str| -> Option<f64> {
        saved
            .as_ref()
            .and_then(|v| v.pointer(key))
            .and_then(serde_json::Value::as_f64)
    };
    // As given, else from map.json, else the defaults. A map.json that lacks the key predates
    // that candidate: it was made with `before` (the fixed mask threshold, no tilt, a flat gel).
    let or_saved =
        |given: &Option<Vec<f64>>, key: &str, default: &[f64], before: f64| match (given, &saved) {
            (Some(v), _) => v.clone(),
            (None, Some(_)) => vec![saved_value(key).unwrap_or(before)],
            (None, None) => default.to_vec(),
        };
    let thresholds = or_saved(
        &a.threshold,
        "/threshold",
        &DEFAULT_THRESHOLDS,
        real::MaskOptions::default().threshold,
    );
    let rates = or_saved(&a.steps_per_frame, "/steps_per_frame", &[1.0], 1.0);
    let slopes = or_saved(&a.fem_slope, "/fem_slope", &[0.0], 0.0);
    let tilts: Vec<[f64; 2]> = or_saved(&a.pitch_deg, "/tilt_deg/pitch", &[0.0], 0.0)
        .into_iter()
        .flat_map(|p| {
            or_saved(&a.roll_deg, "/tilt_deg/roll", &[0.0], 0.0)
                .into_iter()
                .map(move |r| [p, r])
        })
        .collect();
    // The coarse mesh's top is domed already (the fine one is a flat box): it is not crowned
    // by default.
    let default_crown = match a.mesh {
        MeshArg::Fine => DEFAULT_CROWN_RADIUS_MM,
        MeshArg::Coarse => 0.0,
    };
    let crowns = or_saved(
        &a.crown_radius_mm,
        "/crown_radius_mm",
        &[default_crown],
        0.0,
    );
    // A map fitted on a crown with another cap belongs to another gel shape.
    if let (Some(p), Some(_)) = (&a.fit, &saved)
        && crowns.iter().any(|&c| c != 0.0)
    {
        let cap = saved_value("/crown_cap_share").unwrap_or(FIRST_CROWN_CAP_SHARE);
        let now = ocm_tactile::gel::CROWN_MAX_DROP_SHARE;
        if cap != now {
            bail!(
                "{}: the map was fitted on a crown capped at {cap} of the gel's free thickness; this version caps it at {now}, a different gel shape: rerun compare-real without --fit",
                p.display()
            );
        }
    }
    let saved_apex = saved
        .as_ref()
        .and_then(|v| v.pointer("/crown_apex"))
        .and_then(serde_json::Value::as_str)
        .map(|n| {
            <CrownApex as clap::ValueEnum>::from_str(n, false)
                .map_err(|e| anyhow::anyhow!("map.json: crown_apex {n:?}: {e}"))
        })
        .transpose()?;
    let apex = a.crown_apex.or(saved_apex).unwrap_or(CrownApex::GelCentre);
    let skins: Vec<Skin> = or_saved(&a.skin_um, "/skin_um", &[0.0], 0.0)
        .into_iter()
        .flat_map(|t| {
            or_saved(&a.skin_stiffness, "/skin_stiffness", &[1.0], 1.0)
                .into_iter()
                .map(move |k| skin(t, k))
        })
        .fold(Vec::new(), |mut v, k| {
            if !v.contains(&k) {
                v.push(k);
            }
            v
        });
    let mut shapes: Vec<([f64; 2], f64, Skin)> = Vec::new();
    for &t in &tilts {
        for &c in &crowns {
            shapes.extend(skins.iter().map(|&k| (t, c, k)));
        }
    }
    let candidates = shapes.len() * thresholds.len() * slopes.len() * rates.len();
    let digit = ocm_datadir::data_file(a.data.as_deref(), "digit")?;
    let frames = real::load_frames(&digit.join("real-frames-edge6"), "edge6")?;
    let bg = frames[0].clone();
    let setups = digit_setups(&digit)?;
    let Some(s) = setups.iter().find(|s| s.name == a.setup) else {
        bail!("no set-up named '{}'", a.setup);
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    // The FEM of each candidate tilt (from its cache when complete); with more than one
    // candidate (tilt and mask threshold), the map and step offset are fitted against each on
    // the even frames and the best fit is kept; the odd frames score only the one kept.
    let mut tried = Vec::new();
    // The real masks of each threshold, measured once for every shape and FEM mask rule.
    let real_masks: Vec<Vec<ocm_tactile::mask::Mask>> = if candidates == 1 {
        Vec::new()
    } else {
        thresholds
            .iter()
            .map(|&threshold| {
                let mask = MaskOptions { threshold };
                real::measured_masks(&frames, &mask)
            })
            .collect::<Result<_, _>>()?
    };
    let mut best: Option<Kept> = None;
    let mut best_iou = f64::NEG_INFINITY;
    let mut fem_seconds = Vec::new();
    for (i, &(tilt, crown, skin)) in shapes.iter().enumerate() {
        let gel = crowned_gel(
            &digit.join(mesh_file(a.mesh)),
            GelMaterial::default(),
            s,
            tilt,
            crown,
            apex,
            skin,
        )?;
        let grid = Grid::for_gel(&gel);
        let dir = shape_cache(&a.fem, tilt, crown, apex, &skin);
        let (fields, secs) = edge_fem(&a, &gel, &grid, s, tilt, &dir)?;
        fem_seconds.extend(secs);
        if candidates == 1 {
            best = Some((i, [thresholds[0], slopes[0]], gel, fields, None));
            break;
        }
        let mut kept = None;
        let fem_masks: Vec<Vec<ocm_tactile::mask::Mask>> = slopes
            .iter()
            .map(|&sl| real::fem_masks(&gel, &fields, mask_rule(sl)))
            .collect();
        for ((&threshold, real_masks), (&slope, fem)) in thresholds
            .iter()
            .zip(&real_masks)
            .flat_map(|t| slopes.iter().zip(&fem_masks).map(move |s| (t, s)))
        {
            let mask = MaskOptions { threshold };
            let pairs = real::MaskPairs::from_masks(real_masks.clone(), fem.clone(), mask);
            for &rate in &rates {
                let (lo, hi) = pairs.offsets(CompareOptions::default().offset_window, rate)?;
                let pb = bar(
                    1,
                    &format!(
                        "map fit: pitch {} roll {} deg, crown {crown} mm, skin {} um x {}, threshold {threshold}, FEM slope {slope}, {rate} steps per frame",
                        tilt[0],
                        tilt[1],
                        skin.thickness_m * 1e6,
                        skin.stiffness_ratio
                    ),
                );
                let fit = pairs.fit(lo..=hi, a.mm_per_px.map(|v| 1e3 / v), rate)?;
                pb.finish_and_clear();
                tried.push(serde_json::json!({
                    "pitch_deg": tilt[0],
                    "roll_deg": tilt[1],
                    "crown_radius_mm": crown,
                    "skin_um": skin.thickness_m * 1e6,
                    "skin_stiffness": skin.stiffness_ratio,
                    "threshold": threshold,
                    "fem_slope": slope,
                    "steps_per_frame": rate,
                    "fem_cache": dir.display().to_string(),
                    "fit_iou": fit.fit_iou,
                    "offset_steps": fit.offset_steps,
                }));
                if fit.fit_iou > best_iou {
                    best_iou = fit.fit_iou;
                    kept = Some(([threshold, slope], fit));
                }
            }
        }
        if let Some((threshold, fit)) = kept {
            best = Some((i, threshold, gel, fields, Some(fit)));
        }
    }
    let Some((chosen, [threshold, slope], gel, fields, tilt_fit)) = best else {
        bail!("no tilt candidates");
    };
    // A single candidate is not fitted here: its rate is the one given (or saved).
    let rate = tilt_fit.map_or(rates[0], |f| f.steps_per_frame);
    let (tilt, crown, skin) = shapes[chosen];
    let mask_opts = MaskOptions { threshold };
    let fixed_fit = match (&a.fit, &saved) {
        (Some(p), Some(v)) => Some(real::MaskFit {
            map: serde_json::from_value(v.get("map").cloned().unwrap_or_default())
                .with_context(|| format!("{}: no camera map", p.display()))?,
            offset_steps: v
                .get("offset_steps")
                .and_then(serde_json::Value::as_u64)
                .with_context(|| format!("{}: no offset_steps", p.display()))?
                as usize,
            steps_per_frame: rate,
            fit_iou: v
                .get("fit_iou")
                .and_then(serde_json::Value::as_f64)
                .unwrap_or(f64::NAN),
        }),
        _ => None,
    };
    let opts = CompareOptions {
        mask: mask_opts,
        optics: match a.optics {
            OpticsArg::Gain => real::OpticsFit::Gain,
            OpticsArg::ColourDepth => real::OpticsFit::ColourDepth,
        },
        // the tilts' map fits stand (each is what a single run would fit)
        fixed_fit: fixed_fit.or(tilt_fit),
        px_per_m: a.mm_per_px.map(|v| 1e3 / v),
        steps_per_frame: rate,
        fem_mask: mask_rule(slope),
        ..CompareOptions::default()
    };
    let calib = PolyCalib::from_npz(digit.join(real::DEFAULT_CALIB))?;
    let mut renderer = Renderer::new(calib, &bg)?;
    let pb = bar(2, "compare-real");
    let c = real::compare(&gel, &fields, &frames, &mut renderer, &opts, &mut |stage| {
        pb.set_message(stage.to_string());
        pb.inc(1);
    })?;
    pb.finish_and_clear();
    let score = &c.score_frames;
    let mut pngs = Vec::new();
    for k in [
        score[score.len() / 4],
        score[score.len() / 2],
        *score.last().context("no scoring frames")?,
    ] {
        pngs.extend(real::write_figures(
            &a.out, &gel, &fields, &frames, &renderer, &c, &opts, k,
        )?);
    }
    let ious: Vec<f64> = c.masks.iter().map(|m| m.iou).collect();
    let cens: Vec<f64> = c.masks.iter().map(|m| m.centroid_error_mm).collect();
    let rots: Vec<f64> = c.masks.iter().map(|m| m.rotation_error_rad).collect();
    let col = |v: &[real::RenderScore], f: fn(&real::RenderScore) -> f64| -> Vec<f64> {
        v.iter().map(f).collect()
    };
    let opt = |v: &[real::RenderScore], f: fn(&real::RenderScore) -> Option<f64>| -> Vec<f64> {
        v.iter().filter_map(f).collect()
    };
    let summary_render = |v: &[real::RenderScore]| {
        serde_json::json!({
            "l1_median": median(&col(v, |r| r.l1)),
            "psnr_db_median": median(&col(v, |r| r.psnr_db)),
            "ssim_median": median(&col(v, |r| r.ssim)),
            "ssim_min": col(v, |r| r.ssim).into_iter().fold(f64::INFINITY, f64::min),
            "mask_iou_median": median(&col(v, |r| r.mask_iou)),
            "contact_ssim_median": median(&opt(v, |r| r.contact_ssim)),
            "contact_ssim_min": opt(v, |r| r.contact_ssim).into_iter().fold(f64::INFINITY, f64::min),
            "contact_l1_median": median(&opt(v, |r| r.contact_l1)),
            "contact_frames": opt(v, |r| r.contact_ssim).len(),
        })
    };
    // The goal is judged where the contact is: over the whole frame the unchanged background
    // alone scores about 0.95.
    let ssim_med = median(&opt(&c.render, |r| r.contact_ssim));
    let skin_json = serde_json::json!({
        "thickness_um": skin.thickness_m * 1e6,
        "stiffness_ratio": skin.stiffness_ratio,
        "tried": skins
            .iter()
            .map(|k| [k.thickness_m * 1e6, k.stiffness_ratio])
            .collect::<Vec<_>>(),
    });
    let mut v = serde_json::json!({
        "setup": s.name,
        "mesh": mesh_file(a.mesh),
        "nodes": gel.num_nodes(),
        "fem_steps": fields.len(),
        "fem_seconds": fem_seconds,
        "fem_cache": shape_cache(&a.fem, tilt, crown, apex, &skin).display().to_string(),
        "tilt_deg": {"pitch": tilt[0], "roll": tilt[1]},
        "crown_radius_mm": crown,
        "crown_apex": apex_name(apex),
        "crown_cap_share": ocm_tactile::gel::CROWN_MAX_DROP_SHARE,
        "crowns_tried": crowns,
        "skin": skin_json,
        "tilts_tried": tried,
        "frames": frames.len(),
        "fit_frames": "even 2..98",
        "score_frames": "odd 1..99",
        "mask_threshold": threshold,
        "thresholds_tried": thresholds,
        "map": c.fit.map,
        "map_mm_per_px": 1e3 / c.fit.map.px_per_m,
        "offset_steps": c.fit.offset_steps,
        "steps_per_frame": c.fit.steps_per_frame,
        "steps_per_frame_tried": rates,
        "offsets_tried": c.offsets_tried,
        "fit_iou": c.fit.fit_iou,
        "masks": {
            "scored_depths": c.masks.len(),
            "iou_median": median(&ious),
            "iou_mean": mean(&ious),
            "centroid_error_mm_median": median(&cens),
            "rotation_error_rad_median": median(&rots),
            "goal_iou": 0.85,
            "goal_met": median(&ious) >= 0.85,
            "per_depth": c.masks,
        },
        "render": {
            "optics": format!("{:?}", opts.optics),
            "gain_fitted": c.gain,
            "smooth_px_fitted": c.smooth_px,
            "colour_fitted": c.colour,
            "depth_gain_per_m_fitted": c.depth_gain,
            "scalar_gain_only": summary_render(&c.render_scalar_gain),
            "fit_ssim": c.fit_ssim,
            "fitted_gain": summary_render(&c.render),
            "calibrated_gain_1": summary_render(&c.render_gain1),
            "background_only_baseline": summary_render(&c.background_only),
            "goal_ssim": 0.93,
            "goal_ssim_on": "contact_ssim (windows overlapping the real contact)",
            "goal_met": ssim_med >= 0.93,
            "per_depth": c.render,
        },
        "images": pngs,
        "seconds": t_start.elapsed().as_secs_f64(),
    });
    // Beside the rest: the macro above is at its recursion limit.
    v["fem_mask"] = serde_json::json!({"slope": slope, "tried": slopes});
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&v)?,
    )
    .with_context(|| format!("writing {}", a.out.display()))?;
    std::fs::write(
        a.out.join("map.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "map": c.fit.map,
            "offset_steps": c.fit.offset_steps,
            "steps_per_frame": c.fit.steps_per_frame,
            "fit_iou": c.fit.fit_iou,
            "threshold": threshold,
            "fem_slope": slope,
            "tilt_deg": {"pitch": tilt[0], "roll": tilt[1]},
            "crown_radius_mm": crown,
            "crown_apex": apex_name(apex),
            "crown_cap_share": ocm_tactile::gel::CROWN_MAX_DROP_SHARE,
            "skin_um": skin.thickness_m * 1e6,
            "skin_stiffness": skin.stiffness_ratio,
            "gain": c.gain,
            "smooth_px": c.smooth_px,
            "colour": c.colour,
            "depth_gain_per_m": c.depth_gain,
        }))?,
    )?;
    let plot_iou = Chart {
        title: &format!("FEM vs real masks, {} (odd frames scored)", s.name),
        x_label: "real frame",
        y_label: "IoU",
        series: vec![
            Series {
                label: "mask IoU".into(),
                points: c.masks.iter().map(|m| (m.frame as f64, m.iou)).collect(),
                dots: true,
            },
            Series {
                label: "rendered SSIM (contact region)".into(),
                points: c
                    .render
                    .iter()
                    .filter_map(|m| Some((m.frame as f64, m.contact_ssim?)))
                    .collect(),
                dots: true,
            },
        ],
        equal_axes: false,
    };
    plot_iou.write(&a.out, "scores")?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "{} on {}: map {:.4} mm/px, angle {:.3} rad, mirror {}, offset {} frames, {} steps per frame, FEM mask {} (fit IoU {:.3}); masks on the odd frames: IoU median {:.3} (goal 0.85), centroid {:.3} mm, rotation {:.3} rad; rendered (gain {:.2}): contact-region SSIM median {:.3} (goal 0.93), L1 {:.2}, PSNR {:.1} dB, mask IoU {:.3}; files in {}",
            s.name,
            mesh_file(a.mesh),
            1e3 / c.fit.map.px_per_m,
            c.fit.map.angle_rad,
            c.fit.map.mirror,
            c.fit.offset_steps,
            c.fit.steps_per_frame,
            mask_rule(slope),
            c.fit.fit_iou,
            median(&ious),
            median(&cens),
            median(&rots),
            c.gain,
            ssim_med,
            median(&col(&c.render, |r| r.l1)),
            median(&col(&c.render, |r| r.psnr_db)),
            median(&col(&c.render, |r| r.mask_iou)),
            a.out.display()
        );
    }
    Ok(())
}

/// Arguments of `ocm tactile reduce`.
#[derive(clap::Args, Debug)]
pub struct ReduceArgs {
    /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Gel mesh.
    #[arg(long, value_enum, default_value = "fine")]
    mesh: MeshArg,
    /// FEM folders: set-up folders of u_NNN.npy, or folders of them (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "out/npe/fem,out/tactile/fem-random"
    )]
    fem: Vec<PathBuf>,
    /// Set-ups kept out of the basis and scored by --bench (comma-separated names; default:
    /// the unseen indenters' set-ups).
    #[arg(long, value_delimiter = ',')]
    holdout: Vec<String>,
    /// Depth step of FEM folders that stopped before writing force_depth.csv, um.
    #[arg(long, default_value_t = 50.0)]
    step_um: f64,
    /// Modes kept.
    #[arg(long, default_value_t = 40)]
    rank: usize,
    /// Power iterations of the randomized SVD.
    #[arg(long, default_value_t = 2)]
    power_iterations: usize,
    /// Seed of the randomized SVD.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where the model is written (or read with --load).
    #[arg(long, default_value = "out/tactile/rom")]
    out: PathBuf,
    /// Read the model in --out instead of building it.
    #[arg(long)]
    load: bool,
    /// Score on the held-out set-ups: frames per second and nodal RMSE against the FEM.
    #[arg(long)]
    bench: bool,
    /// Bench with only the first K modes of the model (comma-separated ranks; default: all).
    #[arg(long, value_delimiter = ',')]
    ranks: Vec<usize>,
    /// Factor on the reduced model's default normal penalty (1/100 of the full model's).
    #[arg(long, default_value_t = 1.0)]
    penalty_scale: f64,
    /// Augmented-Lagrangian multiplier updates per reduced frame.
    #[arg(long, default_value_t = 0)]
    updates: usize,
    /// Threads for the signed-distance queries.
    #[arg(long, value_parser = crate::arg_check::count, default_value_t = 2)]
    threads: usize,
    /// Add two modes per placement to the basis (the rest stiffness' responses to a normal
    /// load on the indenter's footprint and on its rim), built inside each timed run.
    #[arg(long)]
    enrich: bool,
    /// With --enrich: the footprint loads whose responses become modes, comma-separated, out of
    /// foot, rim, ring2, out, out_rim, radial, tilt_x, tilt_y, skirt; nl_<load> adds the
    /// second-order field of that load's response.
    #[arg(long, value_delimiter = ',', default_value = "foot,rim")]
    enrich_loads: Vec<String>,
    /// Replace the rest stiffness' K_r q by the gel's Neo-Hookean internal force, hyper-reduced
    /// by ECSW weights fitted on the FEM frames of the set-ups the basis was built from (each
    /// projected on its own placement's basis).
    #[arg(long)]
    nonlinear: bool,
    /// With --nonlinear: relative tolerance of the ECSW fit.
    #[arg(long, default_value_t = 0.02)]
    ecsw_tol: f64,
    /// With --nonlinear: FEM frames per training set-up (evenly spaced, the deepest included).
    #[arg(long, default_value_t = 3)]
    ecsw_frames: usize,
    /// With --nonlinear: read the ECSW weights (NPY, rows element, weight) instead of fitting
    /// them; a fit writes <out>/ecsw_r<rank>.npy.
    #[arg(long)]
    ecsw: Option<PathBuf>,
    /// Linearisation passes per reduced frame (default: the reduced options').
    #[arg(long)]
    passes: Option<usize>,
    /// Hold the contact's area-weighted mean gap at zero by a uniform pressure multiplier on
    /// top of the per-node penalty.
    #[arg(long)]
    hold_mean_gap: bool,
    /// Timed repeats of each held-out sequence.
    #[arg(long, value_parser = crate::arg_check::count, default_value_t = 5)]
    repeats: usize,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// ECSW weights of the nonlinear reduced force for the basis `m`: read from --ecsw, or fitted
/// on --ecsw-frames FEM frames of every set-up the basis was built from (those found under the
/// --fem folders), each projected on its own placement's basis (with `enrich`, its footprint
/// modes), and written to <out>/ecsw_r<rank>.npy. Returns the sampled gel and a JSON summary.
fn reduce_ecsw(
    a: &ReduceArgs,
    gel: &Gel,
    digit: &std::path::Path,
    all: &[ocm_tactile::setup::Setup],
    folders: &[(String, PathBuf)],
    m: &ocm_tactile::reduced::ReducedModel,
    enrich: Option<ocm_tactile::reduced::Enrichment>,
) -> anyhow::Result<(ocm_tactile::reduced::hyper::NonlinearGel, serde_json::Value)> {
    use ocm_tactile::reduced::hyper::{EcswTraining, NonlinearGel, fit_ecsw};
    use ocm_tactile::reduced::{FemSequence, placement_model};
    let t0 = std::time::Instant::now();
    if let Some(path) = &a.ecsw {
        let w = ocm_fem::npy::read_f64_2d(path)?;
        if w.cols != 2 {
            bail!(
                "{}: {} columns, expected 2 (element, weight)",
                path.display(),
                w.cols
            );
        }
        let mut pairs = Vec::with_capacity(w.rows);
        for (k, row) in w.data.chunks(2).enumerate() {
            if !(row[0] >= 0.0 && row[0].fract() == 0.0) {
                bail!(
                    "{} row {k}: element {} is not an index",
                    path.display(),
                    row[0]
                );
            }
            pairs.push((row[0] as usize, row[1]));
        }
        let nl = NonlinearGel::new(gel, &pairs)
            .with_context(|| format!("ECSW weights {}", path.display()))?;
        let info = serde_json::json!({"ecsw": path, "elements": nl.len()});
        return Ok((nl, info));
    }
    if a.ecsw_frames == 0 {
        bail!("--ecsw-frames must be at least 1");
    }
    let train: Vec<&(String, PathBuf)> = folders
        .iter()
        .filter(|(n, _)| m.info.sources.contains(n))
        .collect();
    if train.is_empty() {
        bail!("--nonlinear: none of the basis' set-ups is under the --fem folders");
    }
    let pb = bar(train.len(), "ECSW fields");
    let mut models = Vec::new();
    let mut fields = Vec::new();
    for (name, dir) in &train {
        let setup = ocm_tactile::setup::Setup::beside_fem(dir, name, digit, all)?;
        let seq = FemSequence::read(dir, gel.num_nodes(), Some(a.step_um * 1e-6))?;
        let n = seq.displacement.len();
        if n == 0 {
            pb.inc(1);
            continue;
        }
        let k = a.ecsw_frames.min(n);
        let pick: Vec<usize> = (1..=k).map(|j| (j * n).div_ceil(k) - 1).collect();
        let model = match enrich {
            Some(e) => {
                let deepest = seq.depth_m.iter().copied().fold(0.0, f64::max);
                let ind = Indenter::from_stl(&setup.stl)?;
                let approach =
                    ocm_tactile::indent::Approach::new(name, gel, &ind, setup.placement)?;
                placement_model(m, e, gel, &ind, &approach, deepest)?
            }
            None => m.clone(),
        };
        models.push(model);
        fields.push(
            pick.iter()
                .map(|&j| seq.displacement[j].clone())
                .collect::<Vec<_>>(),
        );
        pb.inc(1);
    }
    pb.finish_and_clear();
    let training: Vec<EcswTraining> = models
        .iter()
        .zip(&fields)
        .map(|(model, f)| EcswTraining {
            model,
            fields: f.iter().map(|u| u.as_slice()).collect(),
        })
        .collect();
    let candidates = NonlinearGel::all_elements(gel)?;
    let fit = fit_ecsw(&candidates, &training, a.ecsw_tol)?;
    let nl = NonlinearGel::new(gel, &fit.weights)?;
    let path = a.out.join(format!("ecsw_r{}.npy", m.rank()));
    let flat: Vec<f64> = fit
        .weights
        .iter()
        .flat_map(|&(e, w)| [e as f64, w])
        .collect();
    ocm_fem::npy::write_f64_2d_path(&path, &flat, fit.weights.len(), 2)?;
    let info = serde_json::json!({
        "ecsw": path,
        "elements": nl.len(),
        "candidates": fit.candidates,
        "relative_residual": fit.relative_residual,
        "tolerance": a.ecsw_tol,
        "training_set_ups": training.len(),
        "training_fields": fit.fields,
        "skipped_fields": fit.skipped,
        "rows": fit.rows,
        "fit_seconds": t0.elapsed().as_secs_f64(),
    });
    if !a.json {
        println!(
            "ECSW: {} of {} elements, residual {:.2e} on {} fields of {} set-ups ({:.0} s)",
            nl.len(),
            fit.candidates,
            fit.relative_residual,
            fit.fields,
            training.len(),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok((nl, info))
}

/// Set-up folders (holding u_001.npy) under the given FEM roots, by name.
fn fem_folders(roots: &[PathBuf]) -> anyhow::Result<Vec<(String, PathBuf)>> {
    let mut out = Vec::new();
    for root in roots {
        if root.join("u_001.npy").is_file() {
            let name = root
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            out.push((name, root.clone()));
            continue;
        }
        let mut sub: Vec<PathBuf> = std::fs::read_dir(root)
            .with_context(|| format!("FEM folder {}", root.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.join("u_001.npy").is_file() && p.join("f_001.npy").is_file())
            .collect();
        sub.sort();
        for p in sub {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            out.push((name, p));
        }
    }
    Ok(out)
}

fn reduce(a: ReduceArgs) -> anyhow::Result<()> {
    use ocm_tactile::reduced::{
        FemSequence, ReducedModel, ReducedOptions, deepest_depth_within, score_sequence,
        worst_frame,
    };
    if !(a.penalty_scale.is_finite() && a.penalty_scale > 0.0) {
        bail!(
            "--penalty-scale must be a positive number, got {}",
            a.penalty_scale
        );
    }
    let digit = ocm_datadir::data_file(a.data.as_deref(), "digit")?;
    let mesh_file = mesh_file(a.mesh);
    let gel = Gel::digit(digit.join(mesh_file), GelMaterial::default())?;
    let all = digit_setups(&digit)?;
    let holdout: Vec<String> = if a.holdout.is_empty() {
        all.iter()
            .filter(|s| s.unseen)
            .map(|s| s.name.clone())
            .collect()
    } else {
        a.holdout.clone()
    };
    let folders = fem_folders(&a.fem)?;
    if !a.holdout.is_empty()
        && let Some(bad) = holdout
            .iter()
            .find(|h| !folders.iter().any(|(n, _)| n == *h))
    {
        bail!("--holdout: no FEM folder named '{bad}' under the --fem folders");
    }
    let t0 = std::time::Instant::now();
    let model = if a.load {
        let m = ReducedModel::load(&a.out)?;
        m.check_gel(&gel)?;
        m
    } else {
        let train: Vec<&(String, PathBuf)> = folders
            .iter()
            .filter(|(n, _)| !holdout.contains(n))
            .collect();
        if train.is_empty() {
            bail!("no FEM folder left to build the basis from");
        }
        let pb = bar(train.len(), "snapshots");
        let mut snaps = Vec::new();
        let mut sources = Vec::new();
        for (name, dir) in &train {
            let seq = FemSequence::read(dir, gel.num_nodes(), Some(a.step_um * 1e-6))?;
            snaps.extend(seq.displacement);
            sources.push(name.clone());
            pb.inc(1);
        }
        pb.finish_and_clear();
        let opts = ocm_mor::pod::PodOptions {
            truncation: ocm_mor::pod::Truncation::Rank(a.rank),
            oversampling: 10,
            power_iterations: a.power_iterations,
            seed: a.seed,
        };
        let m = ReducedModel::build(&gel, mesh_file, &snaps, sources, &opts)?;
        m.save(&a.out)?;
        m
    };
    let build_s = t0.elapsed().as_secs_f64();
    let mut report = serde_json::json!({
        "model": a.out,
        "rank": model.rank(),
        "snapshots": model.info.snapshots,
        "set_ups": model.info.sources.len(),
        "captured_energy": model.info.captured_energy,
        "build_seconds": build_s,
    });
    if a.bench {
        let pool = rayon_pool(a.threads)?;
        let ranks = if a.ranks.is_empty() {
            vec![model.rank()]
        } else {
            a.ranks.clone()
        };
        let mut seqs = Vec::new();
        for h in &holdout {
            let Some((_, dir)) = folders.iter().find(|(n, _)| n == h) else {
                continue;
            };
            let setup = ocm_tactile::setup::Setup::beside_fem(dir, h, &digit, &all)?;
            seqs.push((
                setup,
                FemSequence::read(dir, gel.num_nodes(), Some(a.step_um * 1e-6))?,
            ));
        }
        let loads: Vec<&str> = a.enrich_loads.iter().map(|s| s.as_str()).collect();
        ocm_tactile::reduced::check_footprint_loads(&loads)?;
        let rest = if a.enrich {
            Some(ocm_tactile::reduced::RestStiffness::new(&gel)?)
        } else {
            None
        };
        let enrich = rest.as_ref().map(|rest| ocm_tactile::reduced::Enrichment {
            rest,
            loads: &loads,
        });
        let mut per_rank = Vec::new();
        for &r in &ranks {
            let m = model.truncated(r)?;
            let mut opts = ReducedOptions::for_modulus(gel.material.young_pa);
            opts.normal_penalty_pa_m *= a.penalty_scale;
            opts.max_updates = a.updates;
            if let Some(p) = a.passes {
                opts.max_passes = p;
            }
            opts.hold_mean_gap = a.hold_mean_gap;
            let ecsw = if a.nonlinear {
                Some(pool.install(|| reduce_ecsw(&a, &gel, &digit, &all, &folders, &m, enrich))?)
            } else {
                None
            };
            let nonlinear = ecsw.as_ref().map(|(nl, _)| nl);
            let mut scores = Vec::new();
            for (setup, seq) in &seqs {
                scores.push(pool.install(|| {
                    score_sequence(&m, &gel, setup, seq, opts, a.repeats, enrich, nonlinear)
                })?);
            }
            // Frames per second of each repeat over all sequences together; the median repeat.
            let frames: usize = scores.iter().map(|s| s.frames).sum();
            let fps: Vec<f64> = (0..a.repeats)
                .map(|k| frames as f64 / scores.iter().map(|s| s.seconds[k]).sum::<f64>())
                .collect();
            let all_rmse: Vec<f64> = scores.iter().flat_map(|s| s.rmse_m.clone()).collect();
            let top_rmse: Vec<f64> = scores.iter().flat_map(|s| s.rmse_top_m.clone()).collect();
            let proj: Vec<f64> = scores
                .iter()
                .flat_map(|s| s.projection_rmse_m.clone())
                .collect();
            let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
            let worst = worst_frame(&scores);
            let entry = serde_json::json!({
                "rank": r,
                "enriched": a.enrich,
                "enrich_loads": if a.enrich { loads.clone() } else { Vec::new() },
                "hold_mean_gap": a.hold_mean_gap,
                "nonlinear": ecsw.as_ref().map(|(_, info)| info.clone()),
                "frames": frames,
                "frames_per_s_median": median(&fps),
                "frames_per_s": fps,
                "rmse_mm_median": median(&all_rmse) * 1e3,
                "rmse_mm_max": max(&all_rmse) * 1e3,
                "frames_rmse_within_0_05_mm": all_rmse.iter().filter(|&&e| e <= 0.05e-3).count(),
                "depth_mm_every_frame_within_0_05_mm": deepest_depth_within(&scores, 0.05e-3).map(|d| d * 1e3),
                "rmse_top_mm_median": median(&top_rmse) * 1e3,
                "rmse_top_mm_max": max(&top_rmse) * 1e3,
                "projection_rmse_mm_median": median(&proj) * 1e3,
                "projection_rmse_mm_max": max(&proj) * 1e3,
                "passes_per_frame": scores.iter().map(|s| s.passes as f64).sum::<f64>() / frames as f64,
                "queries_per_frame": scores.iter().map(|s| s.queries as f64).sum::<f64>() / frames as f64,
                "max_penetration_um": scores.iter().map(|s| s.max_penetration_m).fold(0.0, f64::max) * 1e6,
                "worst_frame": worst.as_ref().map(|w| serde_json::json!({
                    "setup": w.setup,
                    "depth_mm": w.depth_m * 1e3,
                    "rmse_mm": w.rmse_m * 1e3,
                    "rmse_top_mm": w.rmse_top_m * 1e3,
                    "projection_rmse_mm": w.projection_rmse_m * 1e3,
                })),
                "set_ups": scores.iter().map(|s| serde_json::json!({
                    "setup": s.setup,
                    "frames": s.frames,
                    "rmse_mm_median": median(&s.rmse_m) * 1e3,
                    "rmse_mm_max": max(&s.rmse_m) * 1e3,
                    "rmse_top_mm_max": max(&s.rmse_top_m) * 1e3,
                    "projection_rmse_mm_max": max(&s.projection_rmse_m) * 1e3,
                    "force_z_n_last": s.force_z_n.last(),
                })).collect::<Vec<_>>(),
            });
            if !a.json {
                println!(
                    "rank {r}: {:.0} frames/s (median of {} repeats, {} frames, {} threads, {:.1} passes \
                     and {:.0} queries per frame); nodal RMSE median {:.4} / max {:.4} mm (top face \
                     {:.4} / {:.4}; projection {:.4} / {:.4}); penetration up to {:.1} um",
                    median(&fps),
                    fps.len(),
                    frames,
                    a.threads,
                    entry["passes_per_frame"].as_f64().unwrap_or(0.0),
                    entry["queries_per_frame"].as_f64().unwrap_or(0.0),
                    median(&all_rmse) * 1e3,
                    max(&all_rmse) * 1e3,
                    median(&top_rmse) * 1e3,
                    max(&top_rmse) * 1e3,
                    median(&proj) * 1e3,
                    max(&proj) * 1e3,
                    entry["max_penetration_um"].as_f64().unwrap_or(0.0)
                );
                if let Some(w) = &worst {
                    println!(
                        "  worst frame: {} at {:.3} mm, nodal RMSE {:.4} mm (top face {:.4}; projection {:.4})",
                        w.setup,
                        w.depth_m * 1e3,
                        w.rmse_m * 1e3,
                        w.rmse_top_m * 1e3,
                        w.projection_rmse_m * 1e3
                    );
                }
            }
            per_rank.push(entry);
        }
        report["bench"] = serde_json::Value::Array(per_rank);
        report["held_out"] =
            serde_json::json!(seqs.iter().map(|(s, _)| s.name.clone()).collect::<Vec<_>>());
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "reduced model: rank {} from {} snapshots of {} set-ups ({:.4} of the energy) in {}",
            model.rank(),
            model.info.snapshots,
            model.info.sources.len(),
            model.info.captured_energy,
            a.out.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A FEM cache belongs to one gel shape: a skin without thickness or of the body's own
    /// stiffness is the plain gel's cache, any other skin, crown or tilt a folder of its own.
    #[test]
    fn every_gel_shape_has_its_own_fem_cache() {
        let fem = Path::new("out/tactile/edge6-fem");
        let apex = CrownApex::Tip;
        let plain = shape_cache(fem, [0.0; 2], 0.0, apex, &skin(0.0, 1.0));
        assert_eq!(plain, fem);
        assert_eq!(shape_cache(fem, [0.0; 2], 0.0, apex, &skin(0.0, 10.0)), fem);
        assert_eq!(
            shape_cache(fem, [0.0; 2], 0.0, apex, &skin(450.0, 1.0)),
            fem
        );
        // Written alike, so that the summary and map.json do not name a ratio without a layer.
        assert_eq!(skin(0.0, 10.0), skin(450.0, 1.0));
        assert_eq!(skin(0.0, 10.0).stiffness_ratio, 1.0);
        let mut names = std::collections::BTreeSet::new();
        for tilt in [[0.0, 0.0], [0.0, -8.0]] {
            for crown in [0.0, 25.0] {
                for (t, k) in [(0.0, 1.0), (450.0, 10.0), (450.0, 20.0), (600.0, 10.0)] {
                    names.insert(shape_cache(fem, tilt, crown, apex, &skin(t, k)));
                }
            }
        }
        assert_eq!(names.len(), 2 * 2 * 4);
        assert_eq!(
            shape_cache(fem, [0.0, -8.0], 25.0, apex, &skin(450.0, 10.0)),
            Path::new("out/tactile/edge6-fem-pitch0-roll-8-crown25-cap0.7-skin450x10")
        );
    }
}
