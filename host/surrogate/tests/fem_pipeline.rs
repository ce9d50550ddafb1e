//! The pipeline on the real bellows FEM (a small pressure grid): layers and contact radii,
//! Algorithm 1 reproduces the FEM TCPs of the training samples, f_SP on held-out pressures,
//! saved files read back, malformed files rejected with the place named.

use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::fem_samples::{self, FemSamples};
use ocm_surrogate::mapping::MatchConfig;
use ocm_surrogate::model::SurrogateModel;

#[test]
fn surrogate_from_a_small_fem_sweep() {
    let Some(mesh) = ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let b = Bellows::load(mesh, BellowsConfig::default()).unwrap();
    let grid = fem_samples::pressure_grid(3);
    let held = fem_samples::random_pressures(3, 4);
    let s = fem_samples::collect(&b, &grid, &held, |_| {}).unwrap();
    assert_eq!(s.layers.nodes.len(), 6, "six bellows layers");
    let m = SurrogateModel::build(&s, Limits::default(), MatchConfig::default(), |_| {}).unwrap();
    let g = &m.geometry;
    // The ridges are about 74 mm from the axis in the mesh; the radius is a projected hexagon's.
    assert!(g.r_min_m > 0.06 && g.r_min_m < 0.08, "R_min {}", g.r_min_m);
    for l in &g.layers {
        assert!(l.radius_mean_m >= g.r_min_m);
        assert!(l.plane_rms_m < 5e-3);
    }
    // Algorithm 1 matches every training TCP of this grid to well under a millimetre.
    assert!(
        m.training.optimised_tcp_rmse_m < 5e-4,
        "training RMSE {}",
        m.training.optimised_tcp_rmse_m
    );
    // f_SP interpolates the training postures exactly and stays feasible.
    for (smp, q) in s.samples.iter().zip(&m.training_postures) {
        let p = m.map.posture(&smp.pressures_kpa).unwrap();
        m.limits.check(&p).unwrap();
        for j in 0..p.len() {
            assert!((p[j] - q[j]).abs() < 1e-9);
        }
    }
    // Held-out pressures with a 3-level grid: a coarse but sane map.
    assert!(m.held_out.mapped_tcp_rmse_m < 5e-3, "{:?}", m.held_out);
    // Files round-trip; out-of-range pressures are refused.
    let dir = std::env::temp_dir().join(format!("ocm-surrogate-fem-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    s.write(&dir.join("samples.json")).unwrap();
    let s2 = FemSamples::read(&dir.join("samples.json")).unwrap();
    assert_eq!(s2.layers.nodes, s.layers.nodes);
    assert_eq!(s2.samples.len(), s.samples.len());
    for (a, b) in s2.samples.iter().zip(&s.samples) {
        for k in 0..3 {
            assert!((a.tcp_m[k] - b.tcp_m[k]).abs() < 1e-15 * (1.0 + b.tcp_m[k].abs()));
        }
    }
    m.write(&dir.join("model.json")).unwrap();
    let m2 = SurrogateModel::read(&dir.join("model.json")).unwrap();
    for p in [[0.0, 10.0, -5.0], [30.0, -20.0, 1.0]] {
        let (a, b) = (m.map.posture(&p).unwrap(), m2.map.posture(&p).unwrap());
        for j in 0..a.len() {
            assert!((a[j] - b[j]).abs() < 1e-12);
        }
    }
    assert!(
        m.map
            .posture(&[50.0, 0.0, 0.0])
            .unwrap_err()
            .to_string()
            .contains("outside -20..35 kPa")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_files_are_rejected_naming_the_place() {
    let dir = std::env::temp_dir().join(format!("ocm-surrogate-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("bad.json");
    std::fs::write(
        &p,
        "{\"format\": \"ocm-surrogate-fem-samples/1\", \"layers\": 3",
    )
    .unwrap();
    let e = FemSamples::read(&p).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("line 1"), "{e}");
    std::fs::write(&p, "{\"format\": \"something-else/9\"}").unwrap();
    let e = SurrogateModel::read(&p).unwrap_err().to_string();
    assert!(e.contains("bad.json"), "{e}");
    let e = FemSamples::read(&dir.join("missing.json"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.json"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fem_jig_holds_the_tcp_and_pushes_where_the_robot_would_go() {
    let Some(mesh) = ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let b = Bellows::load(mesh, BellowsConfig::default()).unwrap();
    let rest = ocm_fem::model::State::at_rest(&b.model);
    let x0 = nalgebra::Vector3::from(b.state_of(&rest).tcp_m);
    let p = [6.0, -4.0, -4.0];
    let mut solver = ocm_fem::solve::statics::StaticSolver::new(&b.model).unwrap();
    let (free, _) = b.solve_kpa(&mut solver, &p).unwrap();
    let moved = nalgebra::Vector3::from(b.state_of(&free).tcp_m) - x0;
    // fem_jig_force errors unless the TCP is back within 1 um of x0.
    let f = ocm_surrogate::force::fem_jig_force(&b, &p, &x0).unwrap();
    assert!(f.norm() > 0.05, "{f:?}");
    assert!(
        f.dot(&moved) > 0.0,
        "robot force {f:?}, free motion {moved:?}"
    );
}
