//! Measures the figures stored in `calibration/bellows_material.toml`: the default 64-state sweep
//! of the calibrated material against `Pressure_vs_Pos.csv` (raw and frame-aligned TCP RMSE), and
//! with `grid` the (E, nu) grid search of `ocm fem calibrate grid` with its default states.
//! `cargo run --release -p ocm-fem --example calibration_figures [grid]` (data in ../shared/data).
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_fem::{calibrate, sweep};

fn main() {
    let dir = std::path::Path::new("../shared/data/bellows-manipulator");
    let mesh = dir.join("ManipulatorWhole25.vtk");
    let refs = sweep::read_reference(dir.join("Pressure_vs_Pos.csv")).expect("reference table");
    let cfg = BellowsConfig::default();
    let b = Bellows::load(&mesh, cfg.clone()).expect("mesh");
    let t = std::time::Instant::now();
    let pts = sweep::run(&b, &sweep::grid(&[-20.0, 0.0, 20.0, 35.0]), |_, _, _| {}).expect("sweep");
    let c = sweep::compare(&pts, &refs).expect("compare");
    println!(
        "sweep {:?} E={} nu={}: {} states ({:.1} s), matched {}, raw RMSE {:.3} mm, rotation {:.2} deg, aligned RMSE {:.3} mm, lateral gain {:.3}",
        cfg.law,
        cfg.young_pa,
        cfg.poisson,
        pts.len(),
        t.elapsed().as_secs_f64(),
        c.matched,
        c.rmse_m * 1e3,
        c.frame_rotation_deg,
        c.rmse_aligned_m * 1e3,
        c.lateral_gain
    );
    if std::env::args().nth(1).as_deref() == Some("grid") {
        let states = [
            [20.0, 0.0, 0.0],
            [0.0, 20.0, 0.0],
            [0.0, 0.0, 20.0],
            [10.0, 10.0, 0.0],
            [-20.0, -20.0, -20.0],
            [30.0, 0.0, 10.0],
        ];
        let mut raw = vec![];
        let (cells, best) = calibrate::grid_search(
            &[2e5, 3e5, 4e5, 6e5, 9e5, 1.2e6],
            &[0.3, 0.4, 0.45, 0.49],
            |e, nu| {
                let b = Bellows::load(
                    &mesh,
                    BellowsConfig {
                        young_pa: e,
                        poisson: nu,
                        ..cfg.clone()
                    },
                )?;
                let c = sweep::compare(&sweep::run(&b, &states, |_, _, _| {})?, &refs)?;
                raw.push((e, nu, c.rmse_m));
                println!(
                    "E={e} nu={nu}: aligned {:.3} mm raw {:.3} mm",
                    c.rmse_aligned_m * 1e3,
                    c.rmse_m * 1e3
                );
                Ok(c.rmse_aligned_m)
            },
        )
        .expect("grid");
        let r = raw
            .iter()
            .find(|x| x.0 == best.young_pa && x.1 == best.poisson)
            .map_or(f64::NAN, |x| x.2);
        println!(
            "grid: {} cells, best E={} nu={} aligned {:.3} mm raw {:.3} mm",
            cells.len(),
            best.young_pa,
            best.poisson,
            best.error * 1e3,
            r * 1e3
        );
    }
}
