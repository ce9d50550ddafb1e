//! Where the held-out TCP error of the reduced model comes from, per rank: the basis alone (the
//! full solution projected on V, the floor any reduced model on V has), plain Galerkin over every
//! straining element (projection of the dynamics, no hyper-reduction) and ECSW at each tolerance
//! (adds the hyper-reduction), each at the default Newton tolerance.
//! `cargo run --release -p ocm-mor --example error_budget -- DIR ranks tols every [galerkin 0|1]`
//! with DIR snapshots of `ocm mor snapshots` (or of the `figures` example). Environment:
//! MOR_RTOL (reduced Newton tolerance), MOR_AGE (damping tangent age), MOR_CA (extrapolating
//! predictor), MOR_STATIC (static pressure cases: full vs projected vs Galerkin, plate rigidity,
//! the Galerkin residual at the projected solution split into the rigid plate's constraint forces
//! and the rest, and the Galerkin statics with the plate's constraint forces removed), MOR_ENERGY
//! (strain energy of projected held-out states), MOR_WEIGHT=k (stiffness-weighted POD of every
//! k-th training snapshot instead of the Euclidean one), MOR_SERIES=PREFIX (per-step TCP error,
//! TCP speed and inputs to PREFIX-rank-model-tol.csv, then after ';' the TCP error vector in mm and
//! the full and reduced TCP velocities in mm/s), MOR_BETA=b (Rayleigh stiffness damping b
//! for the held-out runs of both models; the full held-out runs are re-simulated), MOR_SUBSTEPS
//! (lists the held-out full steps the solver cut). Every run also prints the held-out TCP RMSE
//! in three bands of the full model's TCP speed. MOR_MODES=m appends the full model's m lowest
//! rest modes to each POD basis (`ocm_mor::modes`); the printed rank is then POD rank + m.
//! MOR_HELD=k keeps the first k held-out sequences only; MOR_PLATE=f adds the rigid top frame's
//! elements at f times their stiffness (`ReducedModel::galerkin_with_body_penalty`); MOR_PG
//! replaces Galerkin by Petrov-Galerkin with the test basis J0^-1 V
//! (`ocm_mor::modes::step_test_basis`, `ReducedModel::petrov_galerkin`); MOR_STEPRESP=m appends
//! the first m POD modes of the full model's step responses to unit chamber pressures at
//! training states. MOR_LSPG runs least-squares Petrov-Galerkin (`ocm_mor::lspg`, Gauss-Newton on
//! the full step residual, no hyper-reduction) instead of the Galerkin models (MOR_LSPG_GTOL: its
//! stationarity tolerance; MOR_LSPG_FD: Jacobian by differences; MOR_LSPG_J0: residual weighted by the
//! inverse step matrix at rest; MOR_LSPG_CHECK: the assembled Jacobian against differences) and times the full step on the first held-out sequence.
use nalgebra::{DMatrix, DVector};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::curve::projected_tcp_rmse_mm;
use ocm_mor::drive::DriveConfig;
use ocm_mor::pod::{PodOptions, Truncation, pod};
use ocm_mor::rom::ReducedModel;
use ocm_mor::run::{median, simulate_reduced, tcp_rmse_mm};
use ocm_mor::store::{self, ReducedProbe};
use ocm_mor::xs::XsProbe;
use std::path::PathBuf;

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(a.first().map_or("target/mor-figures", |s| s.as_str()));
    let list = |k: usize, d: &str| -> Vec<String> {
        a.get(k)
            .map_or(d, |s| s.as_str())
            .split(',')
            .map(str::to_string)
            .collect()
    };
    let ranks: Vec<usize> = list(1, "16,24,32")
        .iter()
        .filter_map(|t| t.parse().ok())
        .collect();
    let tols: Vec<f64> = list(2, "1e-2,3e-3")
        .iter()
        .filter_map(|t| t.parse().ok())
        .collect();
    let every: usize = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(40);
    let galerkin = a.get(4).is_some_and(|s| s == "1");
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| ocm_mor::MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(&path, BellowsConfig::default())?;
    let s = store::load_snapshots(&dir, &store::model_hash(&b))?;
    // MOR_BETA: another Rayleigh stiffness damping for the held-out runs of both models (the
    // basis stays the one of the snapshots): is the transient error the damping's?
    let beta: Option<f64> = std::env::var("MOR_BETA").ok().and_then(|v| v.parse().ok());
    // MOR_PENALTY_FRAME: both models with the scene's penalty top frame and base (stiff elements,
    // nodal dynamics) instead of rigid bodies; the basis stays the one of the snapshots.
    let penalty = std::env::var("MOR_PENALTY_FRAME").is_ok();
    let b = if beta.is_some() || penalty {
        let d = BellowsConfig::default();
        Bellows::load(
            &path,
            BellowsConfig {
                rayleigh_beta: beta.unwrap_or(d.rayleigh_beta),
                rigid: if penalty {
                    ocm_fem::bellows::RigidMode::Penalty
                } else {
                    d.rigid
                },
                ..d
            },
        )?
    } else {
        b
    };
    let resimulate = beta.is_some() || penalty;
    let drive = DriveConfig {
        dt_s: s.rec.dt_s,
        ..DriveConfig::default()
    };
    let mut held = s.held_out(&drive);
    // MOR_HELD=k: only the first k held-out sequences (long runs at high rank).
    if let Some(k) = std::env::var("MOR_HELD").ok().and_then(|v| v.parse().ok()) {
        held.truncate(k);
    }
    if std::env::var("MOR_SUBSTEPS").is_ok() {
        for (k, inputs, _) in &held {
            let tr = ocm_mor::full::simulate(&b, inputs, drive.dt_s, false, |_| {})?;
            let cut: Vec<(usize, usize)> = tr
                .substeps
                .iter()
                .enumerate()
                .filter(|(_, n)| **n > 1)
                .map(|(j, n)| (j, *n))
                .collect();
            eprintln!("held-out sequence {k}: full steps cut (step, sub-steps): {cut:?}");
        }
    }
    // MOR_SUBSTEP=k: both models take k steps of dt/k per input step (X_S kept every k-th):
    // a mismatch that is a difference of time discretisations shrinks with k, one of the models
    // does not.
    let sub: usize = std::env::var("MOR_SUBSTEP")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
        .max(1);
    let expand = |inputs: &[ocm_mor::drive::Input]| -> Vec<ocm_mor::drive::Input> {
        inputs
            .iter()
            .flat_map(|i| std::iter::repeat_n(*i, sub))
            .collect()
    };
    let h = drive.dt_s / sub as f64;
    if resimulate || sub > 1 {
        for (_, inputs, xs) in &mut held {
            let tr = ocm_mor::full::simulate(&b, &expand(inputs), h, false, |_| {})?;
            *xs = tr.xs.into_iter().skip(sub - 1).step_by(sub).collect();
        }
    }
    let n = s.disp.cols;
    let maxr = ranks.iter().copied().max().unwrap_or(1);
    let train = s.matrix(0, s.train_rows());
    let p = pod(
        train.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(maxr),
            ..PodOptions::default()
        },
    )?;
    let weighted = match std::env::var("MOR_WEIGHT")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        Some(every) => {
            let t0 = std::time::Instant::now();
            let cols: Vec<usize> = (0..s.train_rows()).step_by(every).collect();
            let xs = faer::Mat::<f64>::from_fn(n, cols.len(), |i, j| train[(i, cols[j])]);
            let w = ocm_mor::weighted::stiffness_pod(&b.model, xs.as_ref(), maxr)?;
            eprintln!(
                "stiffness POD of {} columns: {:.1} s",
                cols.len(),
                t0.elapsed().as_secs_f64()
            );
            Some(w.basis)
        }
        None => None,
    };
    let shapes = if std::env::var("MOR_STATIC_SHAPES").is_ok() {
        Some(ocm_mor::modes::static_shapes(&b.model, &b.top_face)?)
    } else {
        None
    };
    let vel = match std::env::var("MOR_VEL")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        Some(m) if m > 0 => {
            let steps = s.rec.steps;
            let d = faer::Mat::<f64>::from_fn(n, s.train_rows(), |i, j| {
                let prev = if j.is_multiple_of(steps) {
                    0.0
                } else {
                    train[(i, j - 1)]
                };
                train[(i, j)] - prev
            });
            let pv = pod(
                d.as_ref(),
                &PodOptions {
                    truncation: Truncation::Rank(m),
                    ..PodOptions::default()
                },
            )?;
            Some(DMatrix::from_fn(n, m, |i, j| pv.modes[(i, j)]))
        }
        _ => None,
    };
    // MOR_KVEL=m: also the first m modes of the stiffness-weighted POD of the step increments
    // u_j - u_(j-1) (every 4th step and every step that follows an input jump).
    let kvel = match std::env::var("MOR_KVEL")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        Some(m) if m > 0 => {
            let steps = s.rec.steps;
            let inc = |i: usize, j: usize| {
                let prev = if j.is_multiple_of(steps) {
                    0.0
                } else {
                    train[(i, j - 1)]
                };
                train[(i, j)] - prev
            };
            let norms: Vec<f64> = (0..s.train_rows())
                .map(|j| (0..n).map(|i| inc(i, j).powi(2)).sum::<f64>())
                .collect();
            let mut sorted = norms.clone();
            sorted.sort_by(f64::total_cmp);
            let big = sorted[sorted.len() * 95 / 100];
            let cols: Vec<usize> = (0..s.train_rows())
                .filter(|&j| j.is_multiple_of(4) || norms[j] >= big)
                .collect();
            let xs = faer::Mat::<f64>::from_fn(n, cols.len(), |i, j| inc(i, cols[j]));
            let t0 = std::time::Instant::now();
            let w = ocm_mor::weighted::stiffness_pod(&b.model, xs.as_ref(), m)?;
            eprintln!(
                "stiffness POD of {} increments: {:.1} s",
                cols.len(),
                t0.elapsed().as_secs_f64()
            );
            Some(w.basis)
        }
        _ => None,
    };
    // MOR_STEPRESP=m: also the first m POD modes of the full model's step responses
    // J(u)^-1 f_c(u) to a unit pressure in each chamber c at every 80th training state u (J the
    // backward-Euler step matrix with the tangent there at zero pressure), each normalised.
    let stepresp = match std::env::var("MOR_STEPRESP")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        Some(m) if m > 0 => {
            let t0 = std::time::Instant::now();
            let pat = ocm_fem::model::Pattern::new(&b.model)?;
            let nc = b.model.cavities.len();
            let mut cols: Vec<Vec<f64>> = vec![];
            for j in (0..s.train_rows()).step_by(80) {
                let x: Vec<f64> = (0..n)
                    .map(|d| b.model.rest[d / 3][d % 3] + train[(d, j)])
                    .collect();
                let ext = |p: Vec<f64>| -> ocm_mor::Result<Vec<f64>> {
                    Ok(b.model
                        .evaluate(
                            &pat,
                            &x,
                            &ocm_fem::model::Loads { pressures_pa: p },
                            1.0,
                            false,
                        )?
                        .f_ext)
                };
                let f0 = ext(vec![0.0; nc])?;
                let mut loads = DMatrix::<f64>::zeros(n, nc);
                for c in 0..nc {
                    let mut p = vec![0.0; nc];
                    p[c] = 1.0;
                    let fc = ext(p)?;
                    for d in 0..n {
                        loads[(d, c)] = fc[d] - f0[d];
                    }
                }
                let resp = ocm_mor::modes::step_test_basis_at(
                    &b.model,
                    &loads,
                    drive.dt_s,
                    &x,
                    &vec![0.0; nc],
                )?;
                for c in 0..nc {
                    let col = resp.column(c);
                    let nrm = col.norm();
                    if nrm > 0.0 {
                        cols.push(col.iter().map(|v| v / nrm).collect());
                    }
                }
            }
            let a = faer::Mat::<f64>::from_fn(n, cols.len(), |i, j| cols[j][i]);
            let pr = pod(
                a.as_ref(),
                &PodOptions {
                    truncation: Truncation::Rank(m.min(cols.len())),
                    ..PodOptions::default()
                },
            )?;
            eprintln!(
                "step responses: {} columns, {:.1} s",
                cols.len(),
                t0.elapsed().as_secs_f64()
            );
            Some(DMatrix::from_fn(n, pr.modes.ncols(), |i, j| {
                pr.modes[(i, j)]
            }))
        }
        _ => None,
    };
    drop(train);
    let rest = match std::env::var("MOR_MODES")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        Some(m) if m > 0 => {
            let modes = ocm_mor::modes::rest_modes(&b.model, m)?;
            eprintln!("rest modes (Hz): {:.3?}", modes.frequencies_hz);
            Some(modes)
        }
        _ => None,
    };
    let probe = XsProbe::of_bellows(&b);
    println!(
        "rank,model,ecsw_tolerance,elements,tcp_rmse_mm,reduced_ms_median,iterations_per_step"
    );
    for &r in &ranks {
        let v = match &weighted {
            Some(w) => w.columns(0, r).into_owned(),
            None => DMatrix::from_fn(n, r, |i, j| p.modes[(i, j)]),
        };
        // MOR_MODES=m: the POD basis enriched with the full model's m lowest rest modes.
        let v = match &rest {
            Some(m) => ocm_mor::modes::enrich(&v, &m.shapes, 1e-8)?,
            None => v,
        };
        // MOR_STATIC_SHAPES: also the static responses at rest to each chamber and tip force.
        let v = match &shapes {
            Some(sh) => ocm_mor::modes::enrich(&v, sh, 1e-8)?,
            None => v,
        };
        // MOR_VEL=m: also the first m POD modes of the step increments u_j - u_(j-1).
        let v = match &vel {
            Some(w) => ocm_mor::modes::enrich(&v, w, 1e-8)?,
            None => v,
        };
        let v = match &kvel {
            Some(w) => ocm_mor::modes::enrich(&v, w, 1e-8)?,
            None => v,
        };
        let v = match &stepresp {
            Some(w) => ocm_mor::modes::enrich(&v, w, 1e-8)?,
            None => v,
        };
        let r = v.ncols();
        eprintln!("basis rank {r}");
        // MOR_PLATE=f: the rigid top frame's own elements resist non-rigid motion at f times
        // their stiffness.
        let plate: Option<f64> = std::env::var("MOR_PLATE").ok().and_then(|v| v.parse().ok());
        // MOR_PG: Petrov-Galerkin with the test basis J0^-1 V (the step matrix at rest).
        let gal = if std::env::var("MOR_PG").is_ok() {
            let t0 = std::time::Instant::now();
            let w = ocm_mor::modes::step_test_basis(&b.model, &v, h)?;
            eprintln!("test basis: {:.2} s", t0.elapsed().as_secs_f64());
            ReducedModel::petrov_galerkin(&b.model, v.clone(), w, &b.top_face)?
        } else {
            ReducedModel::galerkin_with_body_penalty(&b.model, v.clone(), &b.top_face, plate)?
        };
        let rp = ReducedProbe::new(probe.clone(), &gal);
        let tcp0 = rp.compact_state(&DVector::zeros(r), &DVector::zeros(r));
        let floor = projected_tcp_rmse_mm(&s, &v, &rp, &held)?;
        println!("{r},projection,0,0,{floor:.4},0,0");
        if std::env::var("MOR_ENERGY").is_ok() {
            let strain = ocm_mor::rom::straining_elements(&b.model);
            let energy = |u: &[f64]| -> f64 {
                let x: Vec<nalgebra::Vector3<f64>> = (0..b.model.num_nodes())
                    .map(|i| {
                        b.model.rest[i]
                            + nalgebra::Vector3::new(u[3 * i], u[3 * i + 1], u[3 * i + 2])
                    })
                    .collect();
                strain
                    .iter()
                    .map(|&e| {
                        ocm_fem::element::evaluate(
                            e,
                            &b.model.elements[e],
                            &b.model.material,
                            b.model.element_k0(e),
                            b.model.element_scale[e],
                            &x,
                            false,
                        )
                        .map_or(f64::NAN, |ev| ev.energy)
                    })
                    .sum()
            };
            for (k, _, _) in held.iter().take(2) {
                for j in (19..s.rec.steps).step_by(30) {
                    let row = k * s.rec.steps + j;
                    let u = DVector::from_column_slice(&s.disp.data[row * n..(row + 1) * n]);
                    let up = &v * (v.transpose() * &u);
                    eprintln!(
                        "  energy seq {k} step {j}: full {:.4e} J, projected {:.4e} J",
                        energy(u.as_slice()),
                        energy(up.as_slice())
                    );
                }
            }
        }
        if std::env::var("MOR_STATIC").is_ok() {
            let mut solver = ocm_fem::solve::statics::StaticSolver::new(&b.model)?;
            for p in [
                [35.0, 0.0, 0.0],
                [20.0, 35.0, -20.0],
                [-20.0, -20.0, -20.0],
                [10.0, 10.0, 10.0],
                [35.0, 35.0, 0.0],
            ] {
                let Ok((st, _)) = b.solve_kpa(&mut solver, &p) else {
                    continue;
                };
                let xf = probe.of_full_state(&st);
                let u: Vec<f64> = (0..n)
                    .map(|d| st.x[d] - b.model.rest[d / 3][d % 3])
                    .collect();
                let qp = v.transpose() * DVector::from_column_slice(&u);
                let xp = rp.compact_state(&qp, &DVector::zeros(r));
                let inp = ocm_mor::drive::Input {
                    pressure_kpa: p,
                    tip_force_n: [0.0; 3],
                };
                let qg = match gal.solve_static(&inp, 8) {
                    Ok(q) => q,
                    Err(e) => {
                        eprintln!("  static {p:?}: reduced statics failed: {e}");
                        continue;
                    }
                };
                let xg = rp.compact_state(&qg, &DVector::zeros(r));
                // Split the Galerkin residual at the projected solution: the full solution's own
                // nodal residual (non-zero only where the rigid plate's constraint forces act)
                // seen through V, and the rest (the projection error of the deformable part).
                // One Newton step from q_p against each part shows which one moves q_g.
                let pat = ocm_fem::model::Pattern::new(&b.model)?;
                let ev = b
                    .model
                    .evaluate(&pat, &st.x, &b.loads_kpa(&p), 1.0, false)?;
                let net: Vec<f64> = ev.f_int.iter().zip(&ev.f_ext).map(|(a, c)| a - c).collect();
                let rc = v.transpose() * DVector::from_column_slice(&net);
                let (res, kt) = gal.static_residual(&qp, &inp)?;
                let lu = kt.lu();
                let step = |rhs: &DVector<f64>| &qp - lu.solve(rhs).unwrap_or_else(|| rhs * 0.0);
                let (qc, qr, qn) = (step(&rc), step(&(&res - &rc)), step(&res));
                let e = |q: &DVector<f64>| {
                    let x = rp.compact_state(q, &DVector::zeros(r));
                    ((x[0] - xf[0]).powi(2) + (x[1] - xf[1]).powi(2) + (x[2] - xf[2]).powi(2))
                        .sqrt()
                        * 1e3
                };
                // The Galerkin statics with the plate's constraint forces of the full solution
                // added as a constant load: what the reduced model would give if the plate's
                // constraint forces did no virtual work on V (Newton from q_p).
                let mut qk = qp.clone();
                for _ in 0..30 {
                    let (res, kt) = gal.static_residual(&qk, &inp)?;
                    let d = kt
                        .lu()
                        .solve(&(res - &rc))
                        .unwrap_or_else(|| qk.clone() * 0.0);
                    qk -= &d;
                    if d.norm() < 1e-12 * qk.norm() {
                        break;
                    }
                }
                eprintln!(
                    "  galerkin with the plate's constraint forces removed: TCP err {:.3} mm",
                    e(&qk)
                );
                let on_plate: f64 = (0..n)
                    .filter(|d| b.top_frame.contains(&(d / 3)))
                    .map(|d| net[d].powi(2))
                    .sum::<f64>()
                    .sqrt();
                let free_nodes: f64 = (0..n)
                    .filter(|d| !b.model.fixed[*d] && !b.top_frame.contains(&(d / 3)))
                    .map(|d| net[d].powi(2))
                    .sum::<f64>()
                    .sqrt();
                eprintln!(
                    "  residual split {p:?}: |net| plate {on_plate:.3e} N, free {free_nodes:.3e} N; |V^T net| {:.3e}, |R(q_p)| {:.3e}, rest {:.3e}; one Newton step from q_p: plate part only -> TCP err {:.3} mm, projection part only -> {:.3} mm, both -> {:.3} mm",
                    rc.norm(),
                    res.norm(),
                    (&res - &rc).norm(),
                    e(&qc),
                    e(&qr),
                    e(&qn),
                );
                let nonrigid = |q: &DVector<f64>| -> f64 {
                    let uu = &v * q;
                    let pos = |i: usize| {
                        b.model.rest[i]
                            + nalgebra::Vector3::new(uu[3 * i], uu[3 * i + 1], uu[3 * i + 2])
                    };
                    let fr = &b.top_frame;
                    let c0 = fr
                        .iter()
                        .map(|&i| b.model.rest[i])
                        .sum::<nalgebra::Vector3<f64>>()
                        / fr.len() as f64;
                    let c1 = fr.iter().map(|&i| pos(i)).sum::<nalgebra::Vector3<f64>>()
                        / fr.len() as f64;
                    let mut h = nalgebra::Matrix3::zeros();
                    for &i in fr {
                        h += (pos(i) - c1) * (b.model.rest[i] - c0).transpose();
                    }
                    let rr = ocm_fem::element::polar_rotation(&h);
                    (fr.iter()
                        .map(|&i| (pos(i) - c1 - rr * (b.model.rest[i] - c0)).norm_squared())
                        .sum::<f64>()
                        / fr.len() as f64)
                        .sqrt()
                        * 1e3
                };
                eprintln!(
                    "  plate non-rigidity (rms mm): projected {:.4}, galerkin {:.4}",
                    nonrigid(&qp),
                    nonrigid(&qg)
                );
                let d = |a: &[f64; 16], c: &[f64; 16]| {
                    ((a[0] - c[0]).powi(2) + (a[1] - c[1]).powi(2) + (a[2] - c[2]).powi(2)).sqrt()
                        * 1e3
                };
                eprintln!(
                    "  static {p:?}: TCP motion {:.2} mm, projection err {:.3} mm, galerkin err {:.3} mm, |qg-qp|/|qp| {:.3e}",
                    d(&xf, &tcp0),
                    d(&xp, &xf),
                    d(&xg, &xf),
                    (&qg - &qp).norm() / qp.norm()
                );
            }
        }
        // MOR_LSPG: least-squares Petrov-Galerkin (Gauss-Newton on the full step residual with
        // the current Jacobian, no hyper-reduction) instead of the Galerkin models; also times
        // the full step on the first held-out sequence in this process.
        if std::env::var("MOR_LSPG").is_ok() {
            let mut lspg = ocm_mor::lspg::Lspg::new(&b.model, v.clone(), &b.top_face)?;
            lspg.options.finite_difference_jacobian = std::env::var("MOR_LSPG_FD").is_ok();
            if std::env::var("MOR_LSPG_J0").is_ok() {
                lspg.weight_by_rest_step_matrix(h)?;
            }
            if let Some(g) = std::env::var("MOR_LSPG_GTOL")
                .ok()
                .and_then(|v| v.parse().ok())
            {
                lspg.options.gtol = g;
            }
            // MOR_LSPG_CHECK: the assembled Jacobian (through the rigid fit V_s) against
            // differences of the residual, after 20 steps of the first held-out sequence.
            if std::env::var("MOR_LSPG_CHECK").is_ok()
                && let Some((_, inputs, _)) = held.first()
            {
                let fd = lspg.options.finite_difference_jacobian;
                lspg.options.finite_difference_jacobian = true;
                let mut st = lspg.rest_state();
                for inp in &inputs[..20] {
                    lspg.step(&mut st, inp, h)?;
                }
                let next = st.q.clone() + &st.v * h;
                let (res, jd) = lspg.residual(&st, &inputs[20], h, &next)?;
                lspg.options.finite_difference_jacobian = false;
                let (_, ja) = lspg.residual(&st, &inputs[20], h, &next)?;
                lspg.options.finite_difference_jacobian = fd;
                let nb = lspg.rows() - 6;
                let part = |m: &DMatrix<f64>, body: bool| {
                    if body {
                        m.rows(nb, 6).norm()
                    } else {
                        m.rows(0, nb).norm()
                    }
                };
                let d = &ja - &jd;
                eprintln!(
                    "  lspg Jacobian check rank {r}: |R| {:.3e}; differences |J| free rows {:.3e}, body rows {:.3e}; assembled - differences: free {:.3e}, body {:.3e}; descent cosine of the assembled GN step {:.3e}",
                    res.norm(),
                    part(&jd, false),
                    part(&jd, true),
                    part(&d, false),
                    part(&d, true),
                    {
                        let g = ja.tr_mul(&res);
                        let dq = (ja.tr_mul(&ja))
                            .lu()
                            .solve(&(-&g))
                            .unwrap_or_else(|| g.clone());
                        let gt = jd.tr_mul(&res);
                        gt.dot(&dq) / (gt.norm() * dq.norm())
                    }
                );
            }
            let (mut sq, mut cnt, mut times, mut its) = (0.0, 0usize, vec![], 0usize);
            let mut bands = [(0.0, 0usize); 3];
            for (k, inputs, xs_full) in &held {
                let run = match lspg.simulate(&rp, &expand(inputs), h) {
                    Ok(run) => run,
                    Err(e) => {
                        eprintln!("  lspg rank {r}, held-out sequence {k}: {e}");
                        continue;
                    }
                };
                let run_xs: Vec<_> = run.xs.into_iter().skip(sub - 1).step_by(sub).collect();
                for (x, y) in run_xs.iter().zip(xs_full) {
                    let e2 = (0..3).map(|d| (x[d] - y[d]).powi(2)).sum::<f64>();
                    let speed = (8..11).map(|d| y[d].powi(2)).sum::<f64>().sqrt() * 1e3;
                    let band = [30.0, 300.0].iter().position(|&b| speed < b).unwrap_or(2);
                    bands[band].0 += e2;
                    bands[band].1 += 1;
                }
                let e = tcp_rmse_mm(&run_xs, xs_full)?;
                eprintln!("  lspg rank {r}, held-out sequence {k}: TCP RMSE {e:.4} mm");
                sq += e * e * run_xs.len() as f64;
                cnt += run_xs.len();
                times.extend(run.step_seconds);
                its += run.report.iterations;
            }
            let full_ms = match held.first() {
                Some((_, inputs, _)) => {
                    median(
                        &ocm_mor::full::simulate(&b, inputs, drive.dt_s, false, |_| {})?
                            .step_seconds,
                    ) * 1e3
                }
                None => f64::NAN,
            };
            println!(
                "{r},lspg,0,{},{:.4},{:.4},{:.3}",
                b.model.elements.len(),
                (sq / cnt.max(1) as f64).sqrt(),
                median(&times) * 1e3,
                its as f64 / cnt.max(1) as f64
            );
            let band = |i: usize| (bands[i].0 / bands[i].1.max(1) as f64).sqrt() * 1e3;
            eprintln!(
                "  lspg: full step median {full_ms:.3} ms; TCP RMSE by full TCP speed: < 30 mm/s {:.3} mm ({}), 30-300 {:.3} mm ({}), > 300 {:.3} mm ({})",
                band(0),
                bands[0].1,
                band(1),
                bands[1].1,
                band(2),
                bands[2].1
            );
            continue;
        }
        let tq = s.training_q(&v, every);
        let mut models = vec![];
        if galerkin {
            models.push((0.0, gal.clone(), "galerkin"));
        }
        for &t in &tols {
            models.push((t, gal.hyper_reduce(&tq, t)?.model, "ecsw"));
        }
        let age: usize = std::env::var("MOR_AGE")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(ocm_mor::rom::DEFAULT_DAMPING_TANGENT_AGE);
        let rtol: f64 = std::env::var("MOR_RTOL")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(ocm_mor::rom::DEFAULT_RTOL);
        for (t, rom, label) in &mut models {
            rom.damping_tangent_age = age;
            rom.rtol = rtol;
            if std::env::var("MOR_CA").is_ok() {
                rom.predictor = ocm_mor::rom::Predictor::ConstantAcceleration;
            }
            let (mut sq, mut cnt, mut times, mut its) = (0.0, 0usize, vec![], 0usize);
            let (mut nr, mut nf) = (0.0, 0.0);
            let mut series = String::new();
            // Squared TCP error and count per band of the full model's TCP speed: is the error
            // in the holds or in the transients after input steps?
            const BANDS_MM_S: [f64; 3] = [30.0, 300.0, f64::INFINITY];
            let mut bands = [(0.0, 0usize); 3];
            for (k, inputs, xs_full) in &held {
                let mut run = simulate_reduced(rom, &rp, &expand(inputs), h)?;
                if sub > 1 {
                    run.xs = run.xs.into_iter().skip(sub - 1).step_by(sub).collect();
                }
                for (j, (x, y)) in run.xs.iter().zip(xs_full).enumerate() {
                    let e = (0..3).map(|d| (x[d] - y[d]).powi(2)).sum::<f64>().sqrt();
                    let speed = (8..11).map(|d| y[d].powi(2)).sum::<f64>().sqrt();
                    let band = BANDS_MM_S
                        .iter()
                        .position(|&b| speed * 1e3 < b)
                        .unwrap_or(2);
                    bands[band].0 += e * e;
                    bands[band].1 += 1;
                    if std::env::var("MOR_SERIES").is_ok() {
                        series.push_str(&format!(
                            "{k},{j},{:.4},{:.4},{:?},{:?};{:.4?};{:.2?};{:.2?}\n",
                            e * 1e3,
                            speed * 1e3,
                            inputs[j].pressure_kpa,
                            inputs[j].tip_force_n,
                            [0, 1, 2].map(|d| (x[d] - y[d]) * 1e3),
                            [8, 9, 10].map(|d| y[d] * 1e3),
                            [8, 9, 10].map(|d| x[d] * 1e3),
                        ));
                    }
                }
                for (x, y) in run.xs.iter().zip(xs_full) {
                    nr += (x[0] - tcp0[0]).powi(2)
                        + (x[1] - tcp0[1]).powi(2)
                        + (x[2] - tcp0[2]).powi(2);
                    nf += (y[0] - tcp0[0]).powi(2)
                        + (y[1] - tcp0[1]).powi(2)
                        + (y[2] - tcp0[2]).powi(2);
                }
                let e = tcp_rmse_mm(&run.xs, xs_full)?;
                sq += e * e * run.xs.len() as f64;
                cnt += run.xs.len();
                times.extend(run.step_seconds);
                its += run.report.iterations;
            }
            if let Ok(path) = std::env::var("MOR_SERIES") {
                let p = format!("{path}-{r}-{label}-{t:e}.csv");
                std::fs::write(&p, &series).map_err(|e| ocm_mor::MorError::io(p.as_ref(), e))?;
            }
            println!(
                "{r},{},{t:e},{},{:.4},{:.4},{:.3}",
                label,
                rom.elements.len(),
                (sq / cnt as f64).sqrt(),
                median(&times) * 1e3,
                its as f64 / cnt as f64
            );
            eprintln!(
                "  rms TCP motion reduced {:.3} mm, full {:.3} mm",
                (nr / cnt as f64).sqrt() * 1e3,
                (nf / cnt as f64).sqrt() * 1e3
            );
            let band = |i: usize| (bands[i].0 / bands[i].1.max(1) as f64).sqrt() * 1e3;
            eprintln!(
                "  TCP RMSE by full TCP speed: < 30 mm/s {:.3} mm ({} steps), 30-300 {:.3} mm ({}), > 300 {:.3} mm ({})",
                band(0),
                bands[0].1,
                band(1),
                bands[1].1,
                band(2),
                bands[2].1
            );
        }
    }
    Ok(())
}
