//! Operator inference on the bellows (`ocm_mor::opinf`): for each rank, the regularisation is
//! chosen on the last training sequences by the free-run TCP error, the map is refitted on every
//! training sequence, and the held-out TCP RMSE (overall, per sequence and in bands of the full
//! model's TCP speed), the free-run error on training sequences and the median step time are
//! measured against the full step timed in this process.
//! `cargo run --release -p ocm-mor --example opinf -- S ranks lambdas validation terms full_steps`
//! with S snapshots of `ocm mor snapshots`, lambdas a list of LINEAR[:NONLINEAR], terms letters:
//! q (quadratic state), b (pressure-state bilinear), f (force-state bilinear), w (quadratic
//! inputs), v (position-velocity), i (products in the new state, implicit), l (none of them).
//! Environment: OPINF_QMODES (coordinates of the quadratic and position-velocity products),
//! OPINF_BMODES (of the bilinear ones), OPINF_LAGS / OPINF_WLAGS (state / input lags),
//! OPINF_EXTRA=DIR[,DIR] (more training snapshots of other seeds), OPINF_FRESH=DIR (snapshots of
//! yet another seed, scored like the held-out ones).
use nalgebra::DMatrix;
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::drive::DriveConfig;
use ocm_mor::opinf::{self, OpInfTerms, Regularisation};
use ocm_mor::pod::{PodOptions, Truncation, pod};
use ocm_mor::run::{median, tcp_rmse_mm};
use ocm_mor::store::{self, ReducedProbe};
use ocm_mor::xs::XsProbe;
use ocm_mor::{MorError, full};
use std::path::PathBuf;

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(a.first().map_or("S", |s| s.as_str()));
    let list = |k: usize, d: &str| -> Vec<String> {
        a.get(k)
            .map_or(d, |s| s.as_str())
            .split(',')
            .map(str::to_string)
            .collect()
    };
    let ranks: Vec<usize> = list(1, "16,32")
        .iter()
        .filter_map(|t| t.parse().ok())
        .collect();
    // Each entry: lambda (both groups) or linear:nonlinear.
    let lambdas: Vec<Regularisation> = list(2, "1e-6:1e-4,1e-5:1e-3,1e-6:1e-2")
        .iter()
        .map(|t| Regularisation::parse(t))
        .collect::<ocm_mor::Result<_>>()?;
    let n_val: usize = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(8);
    // Terms: letters l (linear only), q (quadratic state; OPINF_QMODES=m: of the first m
    // coordinates), b (pressure-state bilinear), f (force-state bilinear), w (quadratic inputs),
    // e.g. "qbw".
    let tt = a.get(4).map_or("l", |s| s.as_str());
    let terms = OpInfTerms {
        quadratic_modes: std::env::var("OPINF_QMODES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(if tt.contains('q') { usize::MAX } else { 0 }),
        pressure_bilinear: tt.contains('b'),
        bilinear_modes: std::env::var("OPINF_BMODES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(usize::MAX),
        force_bilinear: tt.contains('f'),
        input_quadratic: tt.contains('w'),
        state_lags: std::env::var("OPINF_LAGS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(2),
        implicit: tt.contains('i'),
        velocity_bilinear: tt.contains('v'),
        input_lags: std::env::var("OPINF_WLAGS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1),
    };
    let full_steps: usize = a.get(5).and_then(|s| s.parse().ok()).unwrap_or(40);
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(&path, BellowsConfig::default())?;
    let s = store::load_snapshots(&dir, &store::model_hash(&b))?;
    let drive = DriveConfig {
        dt_s: s.rec.dt_s,
        ..DriveConfig::default()
    };
    let held = s.held_out(&drive);
    let Some(first) = held.first() else {
        return Err(MorError::Invalid("no held-out sequences in S".into()));
    };
    let full_steps = full_steps.clamp(1, first.1.len());
    let tr = full::simulate(&b, &first.1[..full_steps], drive.dt_s, false, |_| {})?;
    let full_sps = median(&tr.step_seconds);
    println!(
        "full step: median {:.2} ms over {full_steps} steps",
        full_sps * 1e3
    );
    let maxr = *ranks.iter().max().unwrap_or(&16);
    let train = s.matrix(0, s.train_rows());
    let p = pod(
        train.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(maxr),
            ..PodOptions::default()
        },
    )?;
    drop(train);
    let basis_all = DMatrix::from_fn(p.modes.nrows(), maxr, |i, j| p.modes[(i, j)]);
    // OPINF_EXTRA=DIR[,DIR]: more training sequences (snapshots of other seeds) projected on the
    // same basis; the validation and held-out sequences stay those of S.
    let extra: Vec<store::Snapshots> = std::env::var("OPINF_EXTRA")
        .ok()
        .map(|v| {
            v.split(',')
                .map(|d| store::load_snapshots(std::path::Path::new(d), &store::model_hash(&b)))
                .collect::<ocm_mor::Result<_>>()
        })
        .transpose()?
        .unwrap_or_default();
    let extra_refs: Vec<&store::Snapshots> = extra.iter().collect();
    let fresh = std::env::var("OPINF_FRESH")
        .ok()
        .map(|d| store::load_snapshots(std::path::Path::new(&d), &store::model_hash(&b)))
        .transpose()?;
    let probe = XsProbe::of_bellows(&b);
    let nseq = s.rec.sequences;
    for &r in &ranks {
        let v = basis_all.columns(0, r).into_owned();
        let rp = ReducedProbe::of_basis(probe.clone(), &v);
        let t0 = std::time::Instant::now();
        let fitted = opinf::fit_snapshots(
            &s,
            &extra_refs,
            &v,
            &probe,
            &opinf::FitOptions {
                terms,
                lambdas: lambdas.clone(),
                validation_sequences: n_val,
            },
        );
        let (m, rec) = match fitted {
            Ok(x) => x,
            Err(e) => {
                println!("rank {r}: {e}");
                continue;
            }
        };
        let fit_s = t0.elapsed().as_secs_f64();
        for pt in &rec.path {
            println!(
                "rank {r} lambda {:?}: fit residual {:.3e}, spectral radius {:.6}, validation TCP RMSE {:.3} mm",
                pt.lambda, pt.fit_residual, pt.spectral_radius, pt.validation_error
            );
        }
        let (mut sq, mut n, mut times) = (0.0, 0usize, vec![]);
        let mut per = vec![];
        let mut band = [(0.0, 0usize); 3];
        for (_, inputs, xs_full) in &held {
            match m.run(&rp, inputs) {
                Ok(run) => {
                    let e = tcp_rmse_mm(&run.xs, xs_full)?;
                    per.push(e);
                    for (x, y) in run.xs.iter().zip(xs_full) {
                        let sp = (y[8] * y[8] + y[9] * y[9] + y[10] * y[10]).sqrt() * 1e3;
                        let b = if sp < 30.0 {
                            0
                        } else if sp < 300.0 {
                            1
                        } else {
                            2
                        };
                        band[b].0 += (0..3).map(|c| (x[c] - y[c]).powi(2)).sum::<f64>() * 1e6;
                        band[b].1 += 1;
                    }
                    sq += e * e * run.xs.len() as f64;
                    n += run.xs.len();
                    times.extend(run.step_seconds);
                }
                Err(e) => {
                    println!("rank {r}: held-out run failed: {e}");
                    per.push(f64::NAN);
                }
            }
        }
        println!(
            "rank {r}: held-out TCP RMSE by full TCP speed: < 30 mm/s {:.3} mm ({}), 30-300 {:.3} ({}), > 300 {:.3} ({})",
            (band[0].0 / band[0].1.max(1) as f64).sqrt(),
            band[0].1,
            (band[1].0 / band[1].1.max(1) as f64).sqrt(),
            band[1].1,
            (band[2].0 / band[2].1.max(1) as f64).sqrt(),
            band[2].1
        );
        // OPINF_FRESH=DIR: every sequence of snapshots that played no part in fitting or in
        // choosing the terms (another seed).
        if let Some(f) = &fresh {
            let (e, _) =
                opinf::snapshot_tcp_rmse_mm(&m, &rp, f, 0..f.rec.sequences + f.rec.held_out)?;
            println!(
                "rank {r}: fresh sequences (seed {}, {}): TCP RMSE {e:.3} mm",
                f.rec.seed,
                f.rec.sequences + f.rec.held_out
            );
        }
        // Free-run error on the first training sequences: bias (model form) or variance?
        let (train_e, _) = opinf::snapshot_tcp_rmse_mm(&m, &rp, &s, 0..8.min(nseq))?;
        println!("rank {r}: free-run TCP RMSE on 8 training sequences {train_e:.3} mm");
        let sps = median(&times);
        println!(
            "RESULT rank {r} terms {terms:?} lambda {:?} rho {:.6}: held-out TCP RMSE {:.3} mm (per sequence {per:.3?}), step {:.2} us median, speed-up {:.0}x (fit {fit_s:.1} s, {} training sequences)",
            rec.lambda,
            rec.spectral_radius,
            (sq / n.max(1) as f64).sqrt(),
            sps * 1e6,
            full_sps / sps,
            rec.training_sequences
        );
    }
    Ok(())
}
