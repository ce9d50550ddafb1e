//! `ocm mor`: model-order reduction of the bellows FEM: snapshots, POD basis, reduced model with
//! ECSW, error-versus-speed curve, and sharded datasets of the compact state X_S.

use crate::cmd_fem::{BELLOWS_MESH, data_path};
use crate::plot::{Chart, Series};
use crate::progress::bar;
use anyhow::{Context, bail};
use nalgebra::DMatrix;
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::curve::CurveOptions;
use ocm_mor::dataset::{self, DatasetSpec, ModelKind};
use ocm_mor::drive::DriveConfig;
use ocm_mor::pod::{PodOptions, Truncation};
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::{self, PodRecord, ReducedProbe, RomRecord, Snapshots};
use ocm_mor::xs::XsProbe;
use ocm_mor::{full, opinf, run};
use std::path::PathBuf;

/// Model-order reduction subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum MorCommand {
    /// Drives the full bellows FEM (implicit Euler, Rayleigh damping, calibrated material) with
    /// seeded random pressure sequences (-20..35 kPa steps, ramps, holds) and tip forces (<= 2 N)
    /// and stores the nodal displacement snapshots, the inputs and X_S.
    Snapshots {
        #[command(flatten)]
        mesh: MeshArgs,
        /// Training sequences.
        #[arg(long, default_value_t = 8)]
        sequences: usize,
        /// Held-out sequences (simulated after the training ones, never used to fit).
        #[arg(long, default_value_t = 2)]
        held_out: usize,
        /// Steps per sequence (dt = 0.01 s).
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 100)]
        steps: usize,
        /// Seed of the inputs.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// POD basis of the training snapshots by randomized SVD; reports singular values, captured
    /// energy and the projection error of the held-out snapshots. With --bench, times the SVD of a
    /// seeded matrix of the dissertation's size (12,981 x 20,000 to rank 1,223) whose spectrum is
    /// that of --snapshots (measured, then continued at its decay rate), or Gaussian without.
    Pod {
        #[command(flatten)]
        mesh: MeshArgs,
        /// With --bench: the benchmark matrix takes the spectrum of these snapshots (else Gaussian).
        #[arg(long, required_unless_present = "bench")]
        snapshots: Option<PathBuf>,
        /// Keep exactly this many modes.
        #[arg(long)]
        rank: Option<usize>,
        /// Keep the fewest modes that capture this fraction of the energy.
        #[arg(long, default_value_t = 0.9999)]
        energy: f64,
        /// Largest rank searched with --energy.
        #[arg(long, default_value_t = 120)]
        max_rank: usize,
        /// Oversampling of the range finder.
        #[arg(long, default_value_t = 10)]
        oversampling: usize,
        /// Power iterations.
        #[arg(long, default_value_t = 2)]
        power_iterations: usize,
        /// Output folder for basis.npy and pod.json.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Benchmark: SVD of a rows x cols Gaussian matrix to --rank (default 1223).
        #[arg(long)]
        bench: bool,
        /// Benchmark rows.
        #[arg(long, default_value_t = 12_981)]
        rows: usize,
        /// Benchmark columns.
        #[arg(long, default_value_t = 20_000)]
        cols: usize,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Builds the Galerkin reduced model on a basis, hyper-reduces it with ECSW (NNLS on element
    /// contributions of the training snapshots), and scores it on the held-out sequences. With
    /// --method opinf, fits an operator-inference model (a polynomial map of the POD coordinates,
    /// regularisation chosen by the free-run TCP error on the last training sequences) instead.
    Reduce {
        #[command(flatten)]
        mesh: MeshArgs,
        /// Snapshot folder.
        #[arg(long)]
        snapshots: PathBuf,
        /// Basis folder (from `ocm mor pod`).
        #[arg(long)]
        basis: PathBuf,
        /// ECSW relative tolerance on the training forces.
        #[arg(long, default_value_t = 1e-3)]
        tolerance: f64,
        /// Use every k-th training snapshot for ECSW.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 10)]
        every: usize,
        /// Output folder for ecsw.npy and rom.json, or opinf.npy and opinf.json (default: the
        /// basis folder).
        #[arg(long)]
        out: Option<PathBuf>,
        /// ecsw: Galerkin projection with ECSW hyper-reduction; opinf: operator inference, a
        /// polynomial map fitted to the training snapshots' POD coordinates (non-intrusive).
        #[arg(long, value_enum, default_value = "ecsw")]
        method: MethodArg,
        #[command(flatten)]
        opinf: OpInfArgs,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Sweeps basis size and ECSW tolerance; writes TCP RMSE (mm) against speed-up per step, both
    /// against the full FEM on the held-out sequences, as CSV and PNG/SVG.
    Curve {
        #[command(flatten)]
        mesh: MeshArgs,
        /// Snapshot folder.
        #[arg(long)]
        snapshots: PathBuf,
        /// Basis sizes.
        #[arg(long, value_delimiter = ',', default_value = "8,16,24,32")]
        ranks: Vec<usize>,
        /// ECSW tolerances (0 = plain Galerkin, every element).
        #[arg(long, value_delimiter = ',', default_value = "1e-2,1e-3")]
        tolerances: Vec<f64>,
        /// Use every k-th training snapshot for ECSW.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 5)]
        every: usize,
        /// Full-FEM steps re-timed in this run (first held-out sequence; 0 = all of it).
        #[arg(long, default_value_t = 0)]
        full_steps: usize,
        /// Add an operator-inference row at each rank (method `opinf`).
        #[arg(long)]
        with_opinf: bool,
        #[command(flatten)]
        opinf: OpInfArgs,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Writes (time, P_S, tip force, X_S, dX_S/dt) sequences as NPY shards with a JSON manifest.
    /// Rerunning skips finished shards; the shards of a job array stack to the unsharded run.
    Dataset {
        #[command(flatten)]
        mesh: MeshArgs,
        /// Which model simulates.
        #[arg(long, value_enum)]
        model: ModelArg,
        /// Reduced-model folder (basis.npy, pod.json, ecsw.npy, rom.json) for --model reduced.
        #[arg(long, required_if_eq("model", "reduced"))]
        rom: Option<PathBuf>,
        /// Reduced model in --rom: ecsw (rom.json) or opinf (opinf.json, operator inference).
        #[arg(long, value_enum, default_value = "ecsw")]
        method: MethodArg,
        /// Rows (time steps of 0.01 s) in the whole dataset.
        #[arg(long)]
        samples: usize,
        /// Steps per sequence, each from rest.
        #[arg(long, default_value_t = 500)]
        sequence_steps: usize,
        /// This run's shard as I/N (0-based); default 0/1.
        #[arg(long, default_value = "0/1")]
        shard: String,
        /// Seed of the inputs.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
}

/// Where the bellows mesh comes from.
#[derive(clap::Args, Debug, Clone)]
pub struct MeshArgs {
    /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Bellows mesh (VTK, mm); default: the data directory's ManipulatorWhole25.vtk.
    #[arg(long)]
    mesh: Option<PathBuf>,
}

impl MeshArgs {
    fn load(&self) -> anyhow::Result<Bellows> {
        let p = data_path(self.mesh.clone(), self.data.as_deref(), BELLOWS_MESH)?;
        Ok(Bellows::load(&p, BellowsConfig::default())?)
    }
}

/// Reduction methods on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodArg {
    /// Galerkin projection with ECSW hyper-reduction.
    Ecsw,
    /// Operator inference (fitted polynomial map of the POD coordinates).
    Opinf,
}

/// Options of the operator-inference fit.
#[derive(clap::Args, Debug, Clone)]
pub struct OpInfArgs {
    /// opinf: quadratic and position-velocity terms of the first m coordinates.
    #[arg(long, default_value_t = 2)]
    quadratic_modes: usize,
    /// opinf: state lags (q_k, q_{k-1}, ...), at least 2.
    #[arg(long, default_value_t = 3)]
    state_lags: usize,
    /// opinf: input lags (w_{k+1}, w_k, ...), at least 1.
    #[arg(long, default_value_t = 2)]
    input_lags: usize,
    /// opinf: pressure-state and force-state bilinear terms of the first m coordinates.
    #[arg(long, default_value_t = 16)]
    bilinear_modes: usize,
    /// opinf: regularisations tried, each LINEAR or LINEAR:NONLINEAR (relative to unit-RMS
    /// features); the one with the smallest free-run TCP error on the validation sequences wins.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1e-6:1e-4,1e-5:1e-3,1e-5:3e-3,3e-5:1e-3,3e-5:1e-2,1e-4:1e-2,3e-5:3e-2"
    )]
    lambdas: Vec<String>,
    /// opinf: the last training sequences that choose the regularisation.
    #[arg(long, default_value_t = 8)]
    validation: usize,
    /// opinf: more snapshot folders of the same model (other seeds) to train on.
    #[arg(long, value_delimiter = ',')]
    extra_snapshots: Vec<PathBuf>,
}

impl OpInfArgs {
    fn options(&self) -> anyhow::Result<opinf::FitOptions> {
        Ok(opinf::FitOptions {
            terms: opinf::OpInfTerms {
                quadratic_modes: self.quadratic_modes,
                pressure_bilinear: true,
                bilinear_modes: self.bilinear_modes,
                force_bilinear: true,
                input_quadratic: true,
                state_lags: self.state_lags,
                input_lags: self.input_lags,
                implicit: false,
                velocity_bilinear: true,
            },
            lambdas: self
                .lambdas
                .iter()
                .map(|t| opinf::Regularisation::parse(t))
                .collect::<ocm_mor::Result<_>>()?,
            validation_sequences: self.validation,
        })
    }

    fn extra(&self, hash: &str) -> anyhow::Result<Vec<Snapshots>> {
        self.extra_snapshots
            .iter()
            .map(|d| Ok(store::load_snapshots(d, hash)?))
            .collect()
    }
}

/// Model kinds on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ModelArg {
    /// The full FEM.
    Full,
    /// The hyper-reduced model.
    Reduced,
}

fn peak_rss_gib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / (1024.0 * 1024.0))
}

fn galerkin(b: &Bellows, basis: DMatrix<f64>) -> anyhow::Result<ReducedModel> {
    Ok(ReducedModel::galerkin(&b.model, basis, &b.top_face)?)
}

/// Scores a reduced model on the held-out sequences: (TCP RMSE mm, median seconds per step).
fn score(b: &Bellows, rom: &ReducedModel, s: &Snapshots) -> anyhow::Result<(f64, f64)> {
    let probe = ReducedProbe::new(XsProbe::of_bellows(b), rom);
    let (mut sq, mut n, mut times) = (0.0, 0usize, vec![]);
    for (_, inputs, xs_full) in s.held_out(&DriveConfig::default()) {
        let r = run::simulate_reduced(rom, &probe, &inputs, s.rec.dt_s)?;
        let e = run::tcp_rmse_mm(&r.xs, &xs_full)?;
        sq += e * e * r.xs.len() as f64;
        n += r.xs.len();
        times.extend(r.step_seconds);
    }
    if n == 0 {
        bail!("no held-out sequences in the snapshot folder (use --held-out)");
    }
    Ok(((sq / n as f64).sqrt(), run::median(&times)))
}

fn basis_from_pod(p: &ocm_mor::pod::Pod) -> DMatrix<f64> {
    DMatrix::from_fn(p.modes.nrows(), p.modes.ncols(), |i, j| p.modes[(i, j)])
}

/// Runs an `ocm mor` subcommand.
pub fn run(cmd: MorCommand) -> anyhow::Result<()> {
    match cmd {
        MorCommand::Snapshots {
            mesh,
            sequences,
            held_out,
            steps,
            seed,
            out,
            json,
        } => {
            let b = mesh.load()?;
            let cfg = DriveConfig::default();
            let total = sequences + held_out;
            let pb = bar(total * steps, "full FEM steps");
            let (rec, disp, xs) =
                full::record_snapshots(&b, &cfg, seed, sequences, held_out, steps, |k| {
                    pb.set_position(k as u64)
                })?;
            pb.finish_and_clear();
            store::save_snapshots(&out, &rec, &disp, &xs)?;
            let dofs = rec.dofs;
            if json {
                println!("{}", serde_json::to_string(&rec)?);
            } else {
                println!(
                    "{} snapshots of {dofs} DOFs ({sequences} training + {held_out} held-out sequences of {steps} steps), full FEM {:.1} ms/step -> {}",
                    total * steps,
                    rec.seconds_per_step * 1e3,
                    out.display()
                );
            }
            Ok(())
        }
        MorCommand::Pod {
            mesh,
            snapshots,
            rank,
            energy,
            max_rank,
            oversampling,
            power_iterations,
            out,
            bench,
            rows,
            cols,
            json,
        } => {
            let truncation = match rank {
                Some(r) => Truncation::Rank(r),
                None if bench => Truncation::Rank(1223),
                None => Truncation::Energy {
                    fraction: energy,
                    max_rank,
                },
            };
            let opts = PodOptions {
                truncation,
                oversampling,
                power_iterations,
                seed: 1,
            };
            if bench {
                let rank = match truncation {
                    Truncation::Rank(r) => r,
                    Truncation::Energy { max_rank, .. } => max_rank,
                };
                // The spectrum: measured on real snapshots when given, else none (Gaussian).
                let (a, held, sigma, source) = match snapshots.as_ref() {
                    Some(sdir) => {
                        let b = mesh.load()?;
                        let s = store::load_snapshots(sdir, &store::model_hash(&b))?;
                        let train = s.matrix(0, s.train_rows());
                        let measured_rank = 300.min(train.nrows().min(train.ncols()) - 10);
                        let real = ocm_mor::pod::pod(
                            train.as_ref(),
                            &PodOptions {
                                truncation: Truncation::Rank(measured_rank),
                                ..opts
                            },
                        )?;
                        let measured = &real.singular_values[..measured_rank];
                        let k = (rank + 200).min(rows).min(cols);
                        let sigma = ocm_mor::pod::continued_spectrum(measured, k)?;
                        eprintln!(
                            "building the {rows} x {cols} matrix with the spectrum of {} real snapshots ({measured_rank} measured values, {} continued) ...",
                            s.train_rows(),
                            k.saturating_sub(measured_rank)
                        );
                        let (a, h) = ocm_mor::pod::spectrum_matrix(&sigma, rows, cols, 500, 7)?;
                        (
                            a,
                            Some(h),
                            Some(sigma),
                            format!("spectrum of {}", sdir.display()),
                        )
                    }
                    None => (
                        ocm_mor::pod::gaussian_matrix(rows, cols, 7),
                        None,
                        None,
                        "Gaussian (no decay)".to_string(),
                    ),
                };
                let rss_before = peak_rss_gib();
                let t0 = std::time::Instant::now();
                let p = ocm_mor::pod::pod(a.as_ref(), &opts)?;
                let secs = t0.elapsed().as_secs_f64();
                // Accuracy against the exact spectrum the matrix was built with.
                let sv_error = sigma.as_ref().map(|sg| {
                    (0..p.rank())
                        .map(|i| (p.singular_values[i] - sg[i]).abs() / sg[i])
                        .fold(0.0f64, f64::max)
                });
                let held_err = held.as_ref().map(|h| p.projection_error(h.as_ref()));
                let sv: Vec<f64> = p.singular_values.iter().take(p.rank()).copied().collect();
                let summary = serde_json::json!({
                    "rows": rows, "cols": cols, "rank": p.rank(), "oversampling": oversampling,
                    "power_iterations": power_iterations, "seconds": secs, "matrix": source,
                    "captured_energy": p.captured_energy(),
                    "max_relative_singular_value_error": sv_error,
                    "held_out_projection_error": held_err,
                    "peak_rss_gib_before_svd": rss_before,
                    "peak_rss_gib": peak_rss_gib(), "threads": rayon_threads(),
                    "singular_values": sv,
                });
                if json {
                    println!("{summary}");
                } else {
                    println!(
                        "randomized SVD of a {rows} x {cols} matrix ({source}) to rank {}: {secs:.1} s, peak memory {:.2} GiB; captured energy {:.9}, max relative singular-value error {:?}, held-out projection error {:?}; sigma_1 = {:.4e}, sigma_{} = {:.4e}",
                        p.rank(),
                        peak_rss_gib().unwrap_or(f64::NAN),
                        p.captured_energy(),
                        sv_error,
                        held_err,
                        sv[0],
                        p.rank(),
                        sv[p.rank() - 1]
                    );
                }
                return Ok(());
            }
            let (Some(sdir), Some(out)) = (snapshots, out) else {
                bail!("--snapshots and --out are required without --bench");
            };
            let b = mesh.load()?;
            let hash = store::model_hash(&b);
            let s = store::load_snapshots(&sdir, &hash)?;
            let train = s.matrix(0, s.train_rows());
            let t0 = std::time::Instant::now();
            let p = ocm_mor::pod::pod(train.as_ref(), &opts)?;
            let secs = t0.elapsed().as_secs_f64();
            drop(train);
            let held = s.matrix(s.train_rows(), s.disp.rows);
            let held_err = if held.ncols() > 0 {
                p.projection_error(held.as_ref())
            } else {
                f64::NAN
            };
            let basis = basis_from_pod(&p);
            let rec = PodRecord {
                model_hash: hash,
                basis_hash: store::basis_hash(&basis),
                dofs: basis.nrows(),
                rank: p.rank(),
                snapshots: s.train_rows(),
                singular_values: p.singular_values.clone(),
                captured_energy: p.captured_energy(),
                held_out_projection_error: held_err,
                seconds: secs,
            };
            store::save_basis(&out, &basis, &rec)?;
            if json {
                println!("{}", serde_json::to_string(&rec)?);
            } else {
                let sv: Vec<String> = p
                    .singular_values
                    .iter()
                    .take(8)
                    .map(|v| format!("{v:.3e}"))
                    .collect();
                println!(
                    "rank {} of {} snapshots in {secs:.2} s: captured energy {:.6}, held-out projection error {:.3e}; sigma = {} ... -> {}",
                    rec.rank,
                    rec.snapshots,
                    rec.captured_energy,
                    held_err,
                    sv.join(", "),
                    out.display()
                );
            }
            Ok(())
        }
        MorCommand::Reduce {
            mesh,
            snapshots,
            basis,
            tolerance,
            every,
            out,
            method,
            opinf: oargs,
            json,
        } => {
            let b = mesh.load()?;
            let hash = store::model_hash(&b);
            let s = store::load_snapshots(&snapshots, &hash)?;
            let (v, _) = store::load_basis(&basis, &hash, 3 * b.model.num_nodes())?;
            if method == MethodArg::Opinf {
                let extra = oargs.extra(&hash)?;
                let refs: Vec<&Snapshots> = extra.iter().collect();
                let probe = XsProbe::of_bellows(&b);
                let t0 = std::time::Instant::now();
                let (m, rec) = opinf::fit_snapshots(&s, &refs, &v, &probe, &oargs.options()?)?;
                let fit_secs = t0.elapsed().as_secs_f64();
                let out = out.unwrap_or(basis);
                opinf::save(&out, &m, &rec)?;
                let rp = ReducedProbe::of_basis(probe, &v);
                let held = s.rec.sequences..s.rec.sequences + s.rec.held_out;
                if held.is_empty() {
                    bail!("no held-out sequences in the snapshot folder (use --held-out)");
                }
                let (err, times) = opinf::snapshot_tcp_rmse_mm(&m, &rp, &s, held)?;
                let sps = run::median(&times);
                let speedup = s.rec.seconds_per_step / sps;
                if json {
                    println!(
                        "{}",
                        serde_json::json!({ "opinf": rec, "fit_seconds": fit_secs, "held_out_tcp_rmse_mm": err,
                            "reduced_seconds_per_step": sps, "full_seconds_per_step": s.rec.seconds_per_step, "speedup": speedup })
                    );
                } else {
                    println!(
                        "operator inference, rank {}, {} features, regularisation {}:{} ({fit_secs:.1} s, spectral radius {:.4}); held-out TCP RMSE {err:.3} mm, {:.2} us/step vs full {:.1} ms/step (snapshot run): {speedup:.0}x -> {}",
                        rec.rank,
                        rec.features,
                        rec.lambda.linear,
                        rec.lambda.nonlinear,
                        rec.spectral_radius,
                        sps * 1e6,
                        s.rec.seconds_per_step * 1e3,
                        out.display()
                    );
                }
                return Ok(());
            }
            let gal = galerkin(&b, v.clone())?;
            let t0 = std::time::Instant::now();
            let ecsw = gal.hyper_reduce(&s.training_q(&v, every), tolerance)?;
            let train_secs = t0.elapsed().as_secs_f64();
            let rec = RomRecord {
                basis_hash: store::basis_hash(&v),
                rom_hash: store::rom_hash(&ecsw.model),
                rank: v.ncols(),
                ecsw_tolerance: tolerance,
                elements: ecsw.model.elements.len(),
                full_elements: gal.elements.len(),
                relative_residual: ecsw.relative_residual,
            };
            let out = out.unwrap_or(basis);
            store::save_rom(&out, &ecsw.model, &rec)?;
            let (err, sps) = score(&b, &ecsw.model, &s)?;
            let speedup = s.rec.seconds_per_step / sps;
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "rom": rec, "ecsw_seconds": train_secs, "held_out_tcp_rmse_mm": err,
                        "reduced_seconds_per_step": sps, "full_seconds_per_step": s.rec.seconds_per_step, "speedup": speedup })
                );
            } else {
                println!(
                    "rank {}, ECSW keeps {} of {} elements (training residual {:.2e}, {train_secs:.1} s); held-out TCP RMSE {err:.3} mm, {:.3} ms/step vs full {:.1} ms/step: {speedup:.0}x -> {}",
                    rec.rank,
                    rec.elements,
                    rec.full_elements,
                    rec.relative_residual,
                    sps * 1e3,
                    s.rec.seconds_per_step * 1e3,
                    out.display()
                );
            }
            Ok(())
        }
        MorCommand::Curve {
            mesh,
            snapshots,
            ranks,
            tolerances,
            every,
            full_steps,
            with_opinf,
            opinf: oargs,
            out,
            json,
        } => {
            let b = mesh.load()?;
            let hash = store::model_hash(&b);
            let s = store::load_snapshots(&snapshots, &hash)?;
            std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
            let (fit, extra) = if with_opinf {
                (Some(oargs.options()?), oargs.extra(&hash)?)
            } else {
                (None, vec![])
            };
            let pb = bar(
                1 + ranks.len() * (tolerances.len() + usize::from(with_opinf)),
                "full timing, rank x tolerance",
            );
            let c = ocm_mor::curve::sweep(
                &b,
                &s,
                &CurveOptions {
                    ranks,
                    tolerances: tolerances.clone(),
                    every,
                    full_timing_steps: full_steps,
                    opinf: fit,
                    opinf_extra: extra,
                },
                &mut |line| {
                    pb.println(line);
                    pb.inc(1);
                },
            )?;
            pb.finish_and_clear();
            let csv = c.csv();
            let csv_path = out.join("curve.csv");
            std::fs::write(&csv_path, &csv)
                .with_context(|| format!("writing {}", csv_path.display()))?;
            let mut series: Vec<Series> = tolerances
                .iter()
                .map(|&tol| Series {
                    label: if tol > 0.0 {
                        format!("ECSW tolerance {tol:e}")
                    } else {
                        "Galerkin (all elements)".into()
                    },
                    points: c
                        .points
                        .iter()
                        .filter(|p| p.method != "opinf" && p.ecsw_tolerance == tol)
                        .map(|p| (p.speedup.log10(), p.tcp_rmse_mm))
                        .filter(|(x, y)| x.is_finite() && y.is_finite())
                        .collect(),
                    dots: false,
                })
                .collect();
            if with_opinf {
                series.push(Series {
                    label: "operator inference".into(),
                    points: c
                        .points
                        .iter()
                        .filter(|p| p.method == "opinf")
                        .map(|p| (p.speedup.log10(), p.tcp_rmse_mm))
                        .filter(|(x, y)| x.is_finite() && y.is_finite())
                        .collect(),
                    // One point per rank: a line through them would hide a single one.
                    dots: true,
                });
            }
            Chart {
                title: "Reduced bellows model: held-out TCP error against speed-up per step",
                x_label: "log10 of the speed-up per implicit step vs full FEM (median)",
                y_label: "held-out TCP RMSE (mm)",
                series,
                equal_axes: false,
            }
            .write(&out, "curve")?;
            if json {
                println!("{}", serde_json::to_string(&c)?);
            } else {
                println!(
                    "full FEM {:.1} ms/step (median of {} steps); POD {:.2} s",
                    c.full_ms_per_step, c.full_steps_timed, c.pod_seconds
                );
                print!("{csv}");
                println!("-> {}", out.display());
            }
            Ok(())
        }
        MorCommand::Dataset {
            mesh,
            model,
            rom,
            method,
            samples,
            sequence_steps,
            shard,
            seed,
            out,
            json,
        } => {
            let (i, n) = parse_shard(&shard)?;
            let b = mesh.load()?;
            let hash = store::model_hash(&b);
            let drive_cfg = DriveConfig::default();
            let probe = XsProbe::of_bellows(&b);
            let pb = bar(0, "dataset steps");
            let mut progress = |done: usize, total: usize| {
                pb.set_length(total as u64);
                pb.set_position(done as u64);
            };
            let outcome = match model {
                ModelArg::Full => {
                    let spec = DatasetSpec {
                        model: ModelKind::Full,
                        model_hash: hash,
                        basis_hash: None,
                        samples,
                        sequence_steps,
                        seed,
                        drive: drive_cfg,
                    };
                    dataset::write_shard(
                        &out,
                        &spec,
                        i,
                        n,
                        &mut |inputs| {
                            Ok(full::simulate(&b, inputs, drive_cfg.dt_s, false, |_| {})?.xs)
                        },
                        &mut progress,
                    )?
                }
                ModelArg::Reduced if method == MethodArg::Opinf => {
                    let dir = rom.context("--rom DIR is required for --model reduced")?;
                    let (v, _) = store::load_basis(&dir, &hash, 3 * b.model.num_nodes())?;
                    let (m, rec) = opinf::load(&dir, &v)?;
                    let rp = ReducedProbe::of_basis(probe, &v);
                    if (rec.dt_s - drive_cfg.dt_s).abs() > 1e-12 {
                        bail!(
                            "{}: fitted at dt {} s, the dataset steps {} s",
                            dir.join("opinf.json").display(),
                            rec.dt_s,
                            drive_cfg.dt_s
                        );
                    }
                    let spec = DatasetSpec {
                        model: ModelKind::ReducedOpinf,
                        model_hash: hash,
                        basis_hash: Some(opinf::model_hash(&rec)),
                        samples,
                        sequence_steps,
                        seed,
                        drive: drive_cfg,
                    };
                    dataset::write_shard(
                        &out,
                        &spec,
                        i,
                        n,
                        &mut |inputs| Ok(m.run(&rp, inputs)?.xs),
                        &mut progress,
                    )?
                }
                ModelArg::Reduced => {
                    let dir = rom.context("--rom DIR is required for --model reduced")?;
                    let (v, _) = store::load_basis(&dir, &hash, 3 * b.model.num_nodes())?;
                    let gal = galerkin(&b, v)?;
                    let (r, _) = store::load_rom(&dir, &gal)?;
                    let rp = ReducedProbe::new(probe, &r);
                    let spec = DatasetSpec {
                        model: ModelKind::Reduced,
                        model_hash: hash,
                        basis_hash: Some(store::rom_hash(&r)),
                        samples,
                        sequence_steps,
                        seed,
                        drive: drive_cfg,
                    };
                    dataset::write_shard(
                        &out,
                        &spec,
                        i,
                        n,
                        &mut |inputs| Ok(run::simulate_reduced(&r, &rp, inputs, drive_cfg.dt_s)?.xs),
                        &mut progress,
                    )?
                }
            };
            pb.finish_and_clear();
            if json {
                println!("{}", serde_json::to_string(&outcome)?);
            } else if outcome.skipped {
                println!(
                    "shard {i}/{n} already complete in {}: skipped",
                    outcome.dir.display()
                );
            } else {
                println!(
                    "shard {i}/{n}: {} rows (sequences {}..{}) in {:.1} s -> {}",
                    outcome.record.rows,
                    outcome.record.first_sequence,
                    outcome.record.end_sequence,
                    outcome.record.seconds,
                    outcome.dir.display()
                );
            }
            Ok(())
        }
    }
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn parse_shard(s: &str) -> anyhow::Result<(usize, usize)> {
    let (a, b) = s
        .split_once('/')
        .with_context(|| format!("--shard '{s}' must be I/N, e.g. 0/4"))?;
    let whole = |t: &str| -> anyhow::Result<usize> {
        t.trim()
            .parse()
            .with_context(|| format!("--shard '{s}' must be I/N with whole numbers, e.g. 0/4"))
    };
    let (i, n) = (whole(a)?, whole(b)?);
    if n == 0 || i >= n {
        bail!("--shard {i}/{n}: I must be below N");
    }
    Ok((i, n))
}
