//! Measures the reduction figures on the real bellows with the library calls of `ocm mor
//! snapshots` and `ocm mor curve`: full-FEM snapshots (made once and stored in DIR in the format
//! of `ocm mor snapshots`), POD, Galerkin + ECSW, held-out TCP error and the speed-up per step
//! against full steps timed in the same run (medians).
//! `cargo run --release -p ocm-mor --example figures -- DIR [train_seq] [held_seq] [steps] [ranks] [tols] [every]`
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_mor::curve::{CurveOptions, sweep};
use ocm_mor::drive::DriveConfig;
use ocm_mor::{full, store};
use std::path::PathBuf;

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(a.first().map_or("target/mor-figures", |s| s.as_str()));
    let arg = |k: usize, d: usize| a.get(k).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (ntrain, nheld, steps) = (arg(1, 12), arg(2, 3), arg(3, 150));
    let list = |k: usize, d: &str| -> Vec<String> {
        a.get(k)
            .map_or(d, |s| s.as_str())
            .split(',')
            .map(str::to_string)
            .collect()
    };
    let ranks: Vec<usize> = list(4, "16,24,32")
        .iter()
        .filter_map(|t| t.parse().ok())
        .collect();
    let tols: Vec<f64> = list(5, "1e-2,1e-3")
        .iter()
        .filter_map(|t| t.parse().ok())
        .collect();
    let every = arg(6, 5);
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| ocm_mor::MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(path, BellowsConfig::default())?;
    println!(
        "bellows: {} nodes, {} DOFs, {} elements ({} straining)",
        b.model.num_nodes(),
        3 * b.model.num_nodes(),
        b.model.elements.len(),
        ocm_mor::rom::straining_elements(&b.model).len()
    );
    let hash = store::model_hash(&b);
    if !dir.join("snapshots.json").exists() {
        let total = (ntrain + nheld) * steps;
        let t0 = std::time::Instant::now();
        let (rec, disp, xs) =
            full::record_snapshots(&b, &DriveConfig::default(), 1, ntrain, nheld, steps, |k| {
                if k % 50 == 0 {
                    eprintln!(
                        "snapshots: {k}/{total} full steps, {:.0} s",
                        t0.elapsed().as_secs_f64()
                    );
                }
            })?;
        store::save_snapshots(&dir, &rec, &disp, &xs)?;
    }
    let s = store::load_snapshots(&dir, &hash)?;
    println!(
        "snapshots: {} training + {} held-out sequences of {} steps, full FEM {:.1} ms/step (mean, when recorded)",
        s.rec.sequences,
        s.rec.held_out,
        s.rec.steps,
        s.rec.seconds_per_step * 1e3
    );
    let c = sweep(
        &b,
        &s,
        &CurveOptions {
            ranks,
            tolerances: tols,
            every,
            full_timing_steps: 0,
            opinf: None,
            opinf_extra: vec![],
        },
        &mut |line| eprintln!("{line}"),
    )?;
    let sv: Vec<String> = c
        .singular_values
        .iter()
        .map(|v| format!("{v:.3e}"))
        .collect();
    println!(
        "POD {:.2} s; singular values: {}",
        c.pod_seconds,
        sv.join(" ")
    );
    println!(
        "full FEM: median {:.1} ms per step over {} steps (re-run vs stored TCP {:.2e} mm)",
        c.full_ms_per_step, c.full_steps_timed, c.full_rerun_tcp_rmse_mm
    );
    print!("{}", c.csv());
    Ok(())
}
