//! Measures the reduction figures on the real bellows with the library calls `ocm mor` makes:
//! full-FEM snapshots, POD, Galerkin + ECSW, held-out TCP error and speed-up, and the time of
//! reduced dataset samples.
//! `cargo run --release -p ocm-mor --example figures -- [train_seq] [held_seq] [steps] [rank] [tol]`
use nalgebra::{DMatrix, DVector};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::drive::{self, DriveConfig};
use ocm_mor::pod::{PodOptions, Truncation, pod};
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::ReducedProbe;
use ocm_mor::xs::XsProbe;
use ocm_mor::{full, run};

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let arg = |k: usize, d: f64| a.get(k).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (ntrain, nheld, steps) = (
        arg(0, 6.0) as usize,
        arg(1, 2.0) as usize,
        arg(2, 60.0) as usize,
    );
    let ranks: Vec<usize> = a.get(3).map_or(vec![8, 16, 24], |s| {
        s.split(',').filter_map(|t| t.parse().ok()).collect()
    });
    let tols: Vec<f64> = a.get(4).map_or(vec![1e-2, 1e-3], |s| {
        s.split(',').filter_map(|t| t.parse().ok()).collect()
    });
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| ocm_mor::MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(path, BellowsConfig::default())?;
    let cfg = DriveConfig::default();
    let n3 = 3 * b.model.num_nodes();
    println!(
        "bellows: {} nodes, {} DOFs, {} elements ({} straining)",
        b.model.num_nodes(),
        n3,
        b.model.elements.len(),
        ocm_mor::rom::straining_elements(&b.model).len()
    );
    let (mut train, mut held, mut full_secs, mut full_steps) = (vec![], vec![], 0.0, 0);
    for k in 0..ntrain + nheld {
        let inputs = drive::sequence(&cfg, 1, k as u64, steps);
        let tr = full::simulate(&b, &inputs, cfg.dt_s, true, |_| {})?;
        full_secs += tr.seconds;
        full_steps += steps;
        if k < ntrain {
            train.extend(tr.displacements);
        } else {
            held.push((inputs, tr.xs, tr.displacements));
        }
        eprintln!(
            "sequence {k}: full FEM {:.1} ms/step",
            tr.seconds / steps as f64 * 1e3
        );
    }
    let full_sps = full_secs / full_steps as f64;
    println!(
        "full FEM: {:.1} ms per implicit step ({full_steps} steps)",
        full_sps * 1e3
    );
    let am = faer::Mat::<f64>::from_fn(n3, train.len(), |i, j| train[j][i]);
    let maxr = *ranks.iter().max().unwrap_or(&8);
    let t0 = std::time::Instant::now();
    let p = pod(
        am.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(maxr),
            ..PodOptions::default()
        },
    )?;
    let held_cols: Vec<&Vec<f64>> = held.iter().flat_map(|h| h.2.iter()).collect();
    let hm = faer::Mat::<f64>::from_fn(n3, held_cols.len(), |i, j| held_cols[j][i]);
    println!(
        "POD of {} x {} to rank {maxr}: {:.2} s",
        n3,
        train.len(),
        t0.elapsed().as_secs_f64()
    );
    let sv: Vec<String> = p
        .singular_values
        .iter()
        .take(maxr)
        .map(|v| format!("{v:.3e}"))
        .collect();
    println!("singular values: {}", sv.join(" "));
    let basis_all = DMatrix::from_fn(n3, maxr, |i, j| p.modes[(i, j)]);
    println!(
        "rank,captured_energy,held_out_projection_error,ecsw_tolerance,elements,tcp_rmse_mm,reduced_ms_per_step,speedup"
    );
    for &r in &ranks {
        let v = basis_all.columns(0, r).into_owned();
        let energy: f64 =
            p.singular_values[..r].iter().map(|s| s * s).sum::<f64>() / p.total_energy;
        let perr = ocm_mor::pod::projection_error(p.modes.as_ref().get(.., ..r), hm.as_ref());
        let gal = ReducedModel::galerkin(&b.model, v.clone(), &b.top_face)?;
        let tq: Vec<DVector<f64>> = train
            .iter()
            .step_by(10)
            .map(|u| v.transpose() * DVector::from_column_slice(u))
            .collect();
        for &tol in &tols {
            let t1 = std::time::Instant::now();
            let rom = if tol > 0.0 {
                gal.hyper_reduce(&tq, tol)?.model
            } else {
                gal.clone()
            };
            let ecsw_s = t1.elapsed().as_secs_f64();
            let probe = ReducedProbe::new(XsProbe::of_bellows(&b), &rom);
            let (mut sq, mut n, mut secs) = (0.0, 0, 0.0);
            let mut failed = false;
            for (inputs, xs_full, _) in &held {
                match run::simulate_reduced(&rom, &probe, inputs, cfg.dt_s) {
                    Ok((xs, t)) => {
                        let e = run::tcp_rmse_mm(&xs, xs_full)?;
                        sq += e * e * xs.len() as f64;
                        n += xs.len();
                        secs += t;
                    }
                    Err(e) => {
                        eprintln!("rank {r} tol {tol}: {e}");
                        failed = true;
                    }
                }
            }
            if failed || n == 0 {
                println!(
                    "{r},{energy:.8},{perr:.4e},{tol:e},{},failed,,",
                    rom.elements.len()
                );
                continue;
            }
            let sps = secs / n as f64;
            println!(
                "{r},{energy:.8},{perr:.4e},{tol:e},{},{:.4},{:.4},{:.1}   (ECSW {ecsw_s:.1} s)",
                rom.elements.len(),
                (sq / n as f64).sqrt(),
                sps * 1e3,
                full_sps / sps
            );
        }
    }
    Ok(())
}
