//! Where the held-out TCP error of the reduced model comes from, per rank: the basis alone (the
//! full solution projected on V, the floor any reduced model on V has), plain Galerkin over every
//! straining element (projection of the dynamics, no hyper-reduction) and ECSW at each tolerance
//! (adds the hyper-reduction), each at the default Newton tolerance.
//! `cargo run --release -p ocm-mor --example error_budget -- DIR ranks tols every [galerkin 0|1]`
//! with DIR snapshots of `ocm mor snapshots` (or of the `figures` example). Environment:
//! MOR_RTOL (reduced Newton tolerance), MOR_AGE (damping tangent age), MOR_CA (extrapolating
//! predictor), MOR_STATIC (static pressure cases: full vs projected vs Galerkin, plate rigidity),
//! MOR_ENERGY (strain energy of projected held-out states), MOR_WEIGHT=k (stiffness-weighted POD
//! of every k-th training snapshot instead of the Euclidean one).
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
    let b = Bellows::load(path, BellowsConfig::default())?;
    let s = store::load_snapshots(&dir, &store::model_hash(&b))?;
    let drive = DriveConfig {
        dt_s: s.rec.dt_s,
        ..DriveConfig::default()
    };
    let held = s.held_out(&drive);
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
    drop(train);
    let probe = XsProbe::of_bellows(&b);
    println!(
        "rank,model,ecsw_tolerance,elements,tcp_rmse_mm,reduced_ms_median,iterations_per_step"
    );
    for &r in &ranks {
        let v = match &weighted {
            Some(w) => w.columns(0, r).into_owned(),
            None => DMatrix::from_fn(n, r, |i, j| p.modes[(i, j)]),
        };
        let gal = ReducedModel::galerkin(&b.model, v.clone(), &b.top_face)?;
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
                let (st, _) = b.solve_kpa(&mut solver, &p)?;
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
                let qg = gal.solve_static(&inp, 4)?;
                let xg = rp.compact_state(&qg, &DVector::zeros(r));
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
        let tq = s.training_q(&v, every);
        let mut models = vec![];
        if galerkin {
            models.push((0.0, gal.clone()));
        }
        for &t in &tols {
            models.push((t, gal.hyper_reduce(&tq, t)?.model));
        }
        let age: usize = std::env::var("MOR_AGE")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(ocm_mor::rom::DEFAULT_DAMPING_TANGENT_AGE);
        let rtol: f64 = std::env::var("MOR_RTOL")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(ocm_mor::rom::DEFAULT_RTOL);
        for (t, rom) in &mut models {
            rom.damping_tangent_age = age;
            rom.rtol = rtol;
            if std::env::var("MOR_CA").is_ok() {
                rom.predictor = ocm_mor::rom::Predictor::ConstantAcceleration;
            }
            let (mut sq, mut cnt, mut times, mut its) = (0.0, 0usize, vec![], 0usize);
            let (mut nr, mut nf) = (0.0, 0.0);
            for (_, inputs, xs_full) in &held {
                let run = simulate_reduced(rom, &rp, inputs, drive.dt_s)?;
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
            println!(
                "{r},{},{t:e},{},{:.4},{:.4},{:.3}",
                if *t == 0.0 { "galerkin" } else { "ecsw" },
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
        }
    }
    Ok(())
}
