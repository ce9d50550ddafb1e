//! The real bellows manipulator: scene construction and one pressurised equilibrium.

use ocm_fem::bellows::{Bellows, BellowsConfig, Law};
use ocm_fem::solve::statics::StaticSolver;
use std::path::PathBuf;

fn mesh_path() -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/bellows-manipulator/ManipulatorWhole25.vtk");
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "SKIP: {} not found (shared data folder absent)",
            p.display()
        );
        None
    }
}

#[test]
fn scene_and_one_pressure_state() {
    let Some(p) = mesh_path() else { return };
    let cfg = BellowsConfig {
        law: Law::NeoHookeanBulk,
        ..BellowsConfig::default()
    };
    let b = Bellows::load(p, cfg).unwrap();
    assert_eq!(b.model.cavities.len(), 3);
    // Chambers sit 120 degrees apart on the 50 mm pitch circle.
    for (k, a) in b.chamber_angles_deg.iter().enumerate() {
        assert!(
            (a - (30.0 + 120.0 * k as f64)).abs() < 1.0,
            "{:?}",
            b.chamber_angles_deg
        );
    }
    let rest = b.state_of(&ocm_fem::model::State::at_rest(&b.model));
    assert!(
        (rest.tcp_m[2] - 0.190).abs() < 1e-6,
        "TCP 190 mm above the base at rest (as Pressure_vs_Pos.csv)"
    );
    assert!(rest.tcp_m[0].abs() < 1e-5 && rest.tcp_m[1].abs() < 1e-5);
    // Removing the fill leaves the solid volume: total minus three cavities (mm^3 -> m^3).
    let solid: f64 = b.model.elements.iter().map(|g| g.volume).sum();
    let cav: f64 = rest.cavity_volumes_m3.iter().sum();
    assert!(
        (solid + cav - 680_455.6e-9).abs() / 680_455.6e-9 < 0.01,
        "solid {solid} + cavities {cav}"
    );

    let mut solver = StaticSolver::new(&b.model).unwrap();
    let (s, rep) = b.solve_kpa(&mut solver, &[10.0, 0.0, 0.0]).unwrap();
    let st = b.state_of(&s);
    eprintln!("{rep:?}\n{st:?}");
    // Inflating chamber 1 (at 30 deg) grows its volume and bends the robot away from it, to about 210 deg.
    assert!(st.cavity_volumes_m3[0] > 1.02 * rest.cavity_volumes_m3[0]);
    let dir = st.bending_direction_deg.rem_euclid(360.0);
    assert!((dir - 210.0).abs() < 10.0, "bending direction {dir}");
    assert!(st.tcp_m[2] > rest.tcp_m[2], "the inflated side lengthens");
    assert!(st.curvature_per_m > 0.05);
    assert!(rep.min_jacobian > 0.5);
}

#[test]
fn out_of_range_pressure_is_rejected() {
    assert!(ocm_fem::bellows::check_pressures(&[40.0, 0.0, 0.0]).is_err());
    assert!(ocm_fem::bellows::check_pressures(&[f64::NAN]).is_err());
    assert!(ocm_fem::bellows::check_pressures(&[-20.0, 35.0, 0.0]).is_ok());
}
