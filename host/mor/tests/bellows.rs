//! X_S on the real bellows: the compact state of a solved full state is the scene's Fig 4.3
//! state, and the reduced reader gives the same numbers from the basis rows alone.

use nalgebra::{DMatrix, DVector};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_fem::solve::statics::StaticSolver;
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::ReducedProbe;
use ocm_mor::xs::{XS_DIM, XsProbe};

#[test]
fn compact_state_of_a_solved_bellows_matches_the_scene_state() {
    let Some(path) = ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let b = Bellows::load(path, BellowsConfig::default()).unwrap();
    let mut solver = StaticSolver::new(&b.model).unwrap();
    let (s, _) = b.solve_kpa(&mut solver, &[15.0, 0.0, 5.0]).unwrap();
    let st = b.state_of(&s);
    let probe = XsProbe::of_bellows(&b);
    let xs = probe.of_full_state(&s);
    for k in 0..3 {
        assert!((xs[k] - st.tcp_m[k]).abs() < 1e-9, "tcp {k}");
        // The best-fit rotation of the rigid top frame is the body's rotation.
        assert!(
            (xs[5 + k] - st.plate_rotation_rad[k]).abs() < 1e-9,
            "rotation {k}"
        );
    }
    assert!((xs[3] - st.arc_length_m).abs() < 1e-12);
    assert!((xs[4] - st.curvature_per_m).abs() < 1e-9);
    assert!(st.curvature_per_m > 0.05, "the state is bent");
    // At rest (static) the rates vanish.
    assert!(xs[XS_DIM..].iter().all(|v| v.abs() < 1e-9));
    // The reduced reader on a one-mode basis that holds exactly this displacement agrees.
    let rest = b.model.rest_dofs();
    let u: Vec<f64> = s.x.iter().zip(&rest).map(|(x, r)| x - r).collect();
    let norm = u.iter().map(|v| v * v).sum::<f64>().sqrt();
    let basis =
        DMatrix::from_column_slice(u.len(), 1, &u.iter().map(|v| v / norm).collect::<Vec<_>>());
    let rom = ReducedModel::galerkin(&b.model, basis, &b.top_face).unwrap();
    let rp = ReducedProbe::new(probe, &rom);
    let xr = rp.compact_state(
        &DVector::from_element(1, norm),
        &DVector::from_element(1, 0.0),
    );
    for k in 0..XS_DIM {
        assert!(
            (xr[k] - xs[k]).abs() < 1e-9,
            "reduced X_S {k}: {} vs {}",
            xr[k],
            xs[k]
        );
    }
}
