//! The error-against-speed sweep of `ocm mor curve`: for each basis size and ECSW tolerance, the
//! held-out TCP RMSE against the full FEM and the speed-up per implicit step, with the full step
//! timed in the same run on the same machine.

use crate::drive::DriveConfig;
use crate::pod::{PodOptions, Truncation, pod, projection_error};
use crate::rom::ReducedModel;
use crate::run::{median, simulate_reduced, tcp_rmse_mm};
use crate::store::{ReducedProbe, Snapshots};
use crate::xs::XsProbe;
use crate::{MorError, Result, full};
use nalgebra::{DMatrix, DVector};
use ocm_fem::bellows::Bellows;
use serde::Serialize;

/// What to sweep.
#[derive(Debug, Clone)]
pub struct CurveOptions {
    /// Basis sizes.
    pub ranks: Vec<usize>,
    /// ECSW tolerances (0: plain Galerkin over every straining element).
    pub tolerances: Vec<f64>,
    /// ECSW trains on every k-th training snapshot.
    pub every: usize,
    /// Full-model steps re-timed in this run (from the first held-out sequence; 0 = all).
    pub full_timing_steps: usize,
    /// Also fit an operator-inference model at each rank (a row with method `opinf`).
    pub opinf: Option<crate::opinf::FitOptions>,
    /// More training snapshots (other seeds, same model) for the operator-inference fits.
    pub opinf_extra: Vec<Snapshots>,
}

/// One point of the curve.
#[derive(Debug, Clone, Serialize)]
pub struct CurvePoint {
    /// `galerkin` (every element), `ecsw` or `opinf` (operator inference).
    pub method: String,
    /// Basis size.
    pub rank: usize,
    /// ECSW tolerance (0 = Galerkin).
    pub ecsw_tolerance: f64,
    /// Elements in the force sum.
    pub elements: usize,
    /// Fraction of the training snapshot energy the basis captures.
    pub captured_energy: f64,
    /// Relative projection error of the held-out snapshots.
    pub held_out_projection_error: f64,
    /// Held-out TCP RMSE of the full solution projected on the basis (V V^T u), mm: the floor of
    /// any reduced model on this basis; the rest of `tcp_rmse_mm` is the Galerkin projection of
    /// the dynamics and the hyper-reduction.
    pub projected_tcp_rmse_mm: f64,
    /// Held-out TCP RMSE against the full FEM, mm (NaN when a run failed).
    pub tcp_rmse_mm: f64,
    /// Median wall time of a reduced step, ms.
    pub reduced_ms_per_step: f64,
    /// Median full step / median reduced step.
    pub speedup: f64,
    /// Newton iterations per step (mean).
    pub iterations_per_step: f64,
    /// Iteration-matrix refreshes per step (mean).
    pub tangents_per_step: f64,
    /// Wall time of the ECSW fit (of the operator-inference fit for `opinf`), s.
    pub ecsw_seconds: f64,
}

/// The sweep's result.
#[derive(Debug, Clone, Serialize)]
pub struct Curve {
    /// Median wall time of a full implicit step in this run, ms.
    pub full_ms_per_step: f64,
    /// Full steps timed.
    pub full_steps_timed: usize,
    /// TCP RMSE between the re-run full steps and the stored snapshots, mm (0 when deterministic).
    pub full_rerun_tcp_rmse_mm: f64,
    /// Singular values of the training snapshots (as many as the largest rank plus oversampling).
    pub singular_values: Vec<f64>,
    /// Wall time of the POD, s.
    pub pod_seconds: f64,
    /// The points, rank-major.
    pub points: Vec<CurvePoint>,
}

/// Runs the sweep on stored snapshots; `progress` gets a line per finished stage.
pub fn sweep(
    b: &Bellows,
    s: &Snapshots,
    opts: &CurveOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Curve> {
    let drive = DriveConfig {
        dt_s: s.rec.dt_s,
        ..DriveConfig::default()
    };
    let held = s.held_out(&drive);
    let Some((_, inputs0, xs0)) = held.first() else {
        return Err(MorError::Invalid(
            "no held-out sequences in the snapshots (use --held-out)".into(),
        ));
    };
    let maxr = opts.ranks.iter().copied().max().unwrap_or(0);
    if maxr == 0 || opts.ranks.contains(&0) {
        return Err(MorError::Invalid("ranks must be positive".into()));
    }
    for &t in &opts.tolerances {
        crate::rom::check_ecsw_tolerance(t)?;
    }
    // The full step, timed here so that both sides of the speed-up share machine and load.
    let n_full = if opts.full_timing_steps == 0 {
        inputs0.len()
    } else {
        opts.full_timing_steps.min(inputs0.len())
    };
    let tr = full::simulate(b, &inputs0[..n_full], drive.dt_s, false, |_| {})?;
    let full_sps = median(&tr.step_seconds);
    let full_rerun = tcp_rmse_mm(&tr.xs, &xs0[..n_full])?;
    progress(&format!(
        "full FEM: median {:.1} ms per step over {n_full} steps",
        full_sps * 1e3
    ));
    let train = s.matrix(0, s.train_rows());
    let t0 = std::time::Instant::now();
    let p = pod(
        train.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(maxr),
            ..PodOptions::default()
        },
    )?;
    let pod_seconds = t0.elapsed().as_secs_f64();
    drop(train);
    let held_m = s.matrix(s.train_rows(), s.disp.rows);
    let basis_all = DMatrix::from_fn(p.modes.nrows(), maxr, |i, j| p.modes[(i, j)]);
    let probe = XsProbe::of_bellows(b);
    let mut points = vec![];
    for &r in &opts.ranks {
        let v = basis_all.columns(0, r).into_owned();
        let energy = p.singular_values[..r].iter().map(|x| x * x).sum::<f64>() / p.total_energy;
        let perr = projection_error(p.modes.as_ref().get(.., ..r), held_m.as_ref());
        let gal = ReducedModel::galerkin(&b.model, v.clone(), &b.top_face)?;
        let floor = projected_tcp_rmse_mm(s, &v, &ReducedProbe::new(probe.clone(), &gal), &held)?;
        let tq = s.training_q(&v, opts.every);
        for &tol in &opts.tolerances {
            let t1 = std::time::Instant::now();
            let rom = if tol > 0.0 {
                gal.hyper_reduce(&tq, tol)?.model
            } else {
                gal.clone()
            };
            let ecsw_seconds = t1.elapsed().as_secs_f64();
            let rp = ReducedProbe::new(probe.clone(), &rom);
            let (mut sq, mut n, mut times) = (0.0, 0usize, vec![]);
            let (mut its, mut tans) = (0usize, 0usize);
            let mut failed = None;
            for (k, inputs, xs_full) in &held {
                match simulate_reduced(&rom, &rp, inputs, drive.dt_s) {
                    Ok(run) => {
                        let e = tcp_rmse_mm(&run.xs, xs_full)?;
                        sq += e * e * run.xs.len() as f64;
                        n += run.xs.len();
                        times.extend(run.step_seconds);
                        its += run.report.iterations;
                        tans += run.report.tangents;
                    }
                    Err(e) => failed = Some(format!("held-out sequence {k}: {e}")),
                }
            }
            let rmse = if failed.is_some() || n == 0 {
                f64::NAN
            } else {
                (sq / n as f64).sqrt()
            };
            let sps = median(&times);
            let pt = CurvePoint {
                method: if tol > 0.0 { "ecsw" } else { "galerkin" }.into(),
                rank: r,
                ecsw_tolerance: tol,
                elements: rom.elements.len(),
                captured_energy: energy,
                held_out_projection_error: perr,
                projected_tcp_rmse_mm: floor,
                tcp_rmse_mm: rmse,
                reduced_ms_per_step: sps * 1e3,
                speedup: full_sps / sps,
                iterations_per_step: its as f64 / n.max(1) as f64,
                tangents_per_step: tans as f64 / n.max(1) as f64,
                ecsw_seconds,
            };
            progress(&match failed {
                Some(f) => format!("rank {r}, tolerance {tol:e}: failed ({f})"),
                None => format!(
                    "rank {r}, tolerance {tol:e}: {} elements, TCP RMSE {rmse:.3} mm, {:.3} ms/step, {:.0}x",
                    pt.elements, pt.reduced_ms_per_step, pt.speedup
                ),
            });
            points.push(pt);
        }
        if let Some(fo) = &opts.opinf {
            let t1 = std::time::Instant::now();
            let extra: Vec<&Snapshots> = opts.opinf_extra.iter().collect();
            let rp = ReducedProbe::of_basis(probe.clone(), &v);
            let fitted = crate::opinf::fit_snapshots(s, &extra, &v, &probe, fo);
            let fit_seconds = t1.elapsed().as_secs_f64();
            let held_seqs = s.rec.sequences..s.rec.sequences + s.rec.held_out;
            let scored =
                fitted.and_then(|(m, _)| crate::opinf::snapshot_tcp_rmse_mm(&m, &rp, s, held_seqs));
            let (rmse, sps, failed) = match scored {
                Ok((e, times)) => (e, median(&times), None),
                Err(e) => (f64::NAN, f64::NAN, Some(e.to_string())),
            };
            let pt = CurvePoint {
                method: "opinf".into(),
                rank: r,
                ecsw_tolerance: 0.0,
                elements: 0,
                captured_energy: energy,
                held_out_projection_error: perr,
                projected_tcp_rmse_mm: floor,
                tcp_rmse_mm: rmse,
                reduced_ms_per_step: sps * 1e3,
                speedup: full_sps / sps,
                iterations_per_step: 0.0,
                tangents_per_step: 0.0,
                ecsw_seconds: fit_seconds,
            };
            progress(&match failed {
                Some(f) => format!("rank {r}, operator inference: failed ({f})"),
                None => format!(
                    "rank {r}, operator inference: TCP RMSE {rmse:.3} mm, {:.2} us/step, {:.0}x",
                    sps * 1e6,
                    pt.speedup
                ),
            });
            points.push(pt);
        }
    }
    Ok(Curve {
        full_ms_per_step: full_sps * 1e3,
        full_steps_timed: n_full,
        full_rerun_tcp_rmse_mm: full_rerun,
        singular_values: p.singular_values.clone(),
        pod_seconds,
        points,
    })
}

/// A held-out sequence: index, inputs, full-model X_S rows.
type HeldOut = (
    usize,
    Vec<crate::drive::Input>,
    Vec<[f64; 2 * crate::xs::XS_DIM]>,
);

/// Held-out TCP RMSE of the stored full displacements projected on `basis`, mm: the floor of
/// any reduced model on that basis.
pub fn projected_tcp_rmse_mm(
    s: &Snapshots,
    basis: &DMatrix<f64>,
    probe: &ReducedProbe,
    held: &[HeldOut],
) -> Result<f64> {
    let (n, steps) = (s.disp.cols, s.rec.steps);
    let zero = DVector::zeros(basis.ncols());
    let (mut sq, mut count) = (0.0, 0usize);
    for (k, _, xs_full) in held {
        let rows: Vec<_> = (0..steps)
            .map(|j| {
                let row = k * steps + j;
                let u = DVector::from_column_slice(&s.disp.data[row * n..(row + 1) * n]);
                probe.compact_state(&(basis.transpose() * u), &zero)
            })
            .collect();
        let e = tcp_rmse_mm(&rows, xs_full)?;
        sq += e * e * rows.len() as f64;
        count += rows.len();
    }
    Ok((sq / count.max(1) as f64).sqrt())
}

impl Curve {
    /// The curve as CSV (header names the units).
    pub fn csv(&self) -> String {
        let mut out = String::from(
            "rank,ecsw_tolerance,elements,captured_energy,held_out_projection_error,projected_tcp_rmse_mm,tcp_rmse_mm,reduced_ms_per_step,full_ms_per_step,speedup,iterations_per_step,tangents_per_step,method\n",
        );
        for p in &self.points {
            out.push_str(&format!(
                "{},{:e},{},{:.9},{:.4e},{:.4},{:.4},{:.5},{:.3},{:.2},{:.3},{:.3},{}\n",
                p.rank,
                p.ecsw_tolerance,
                p.elements,
                p.captured_energy,
                p.held_out_projection_error,
                p.projected_tcp_rmse_mm,
                p.tcp_rmse_mm,
                p.reduced_ms_per_step,
                self.full_ms_per_step,
                p.speedup,
                p.iterations_per_step,
                p.tangents_per_step,
                p.method
            ));
        }
        out
    }
}
