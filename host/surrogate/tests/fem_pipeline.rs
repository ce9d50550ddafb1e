//! The pipeline on the real bellows FEM (a small pressure grid): layers and contact radii,
//! Algorithm 1 reproduces the FEM TCPs of the training samples, f_SP on held-out pressures,
//! saved files read back, malformed files rejected with the place named.

use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::fem_samples::{self, FemSamples};
use ocm_surrogate::force::JigHold;
use ocm_surrogate::mapping::MatchConfig;
use ocm_surrogate::model::SurrogateModel;
use ocm_surrogate::sim::SceneConfig;

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
    // A negative size or mass is named on reading, not met as a chain of negative length.
    for (field, edit) in [
        (
            "fem_mass_kg",
            (|b: &mut FemSamples| b.fem_mass_kg = -1.0) as fn(&mut FemSamples),
        ),
        ("base_radius_m", |b| b.base_radius_m = -0.01),
        ("tcp_offset_m", |b| b.tcp_offset_m = -0.01),
        ("samples[0]", |b| b.samples[0].arc_length_m = -0.1),
    ] {
        let mut bad = s.clone();
        edit(&mut bad);
        bad.write(&dir.join("negative.json")).unwrap();
        let e = FemSamples::read(&dir.join("negative.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("negative.json") && e.contains(field),
            "{field}: {e}"
        );
    }
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
            .contains("chamber 1 pressure = 50 kPa is outside the allowed range [-20, 35] kPa")
    );
    // Force calibration over the whole range: the eight corners of -20..35 kPa and four random
    // pressures to fit, four held out.
    let mut m = m;
    let fit = SurrogateModel::calibration_pressures(4, 2);
    let held = ocm_surrogate::force::nested_random_pressures(4, 3);
    let fs = m
        .calibrate_force(
            &b,
            &fit,
            &held,
            &SceneConfig::default(),
            JigHold::TcpPinned,
            |_| {},
        )
        .unwrap();
    let c = m.force_calibration.unwrap();
    assert_eq!((c.samples, c.held_out_samples, fs.fit), (12, 4, 12));
    // The line explains most of each component of the FEM's force, and predicts the held-out
    // FEM forces to within a sixth of the component's span over the range.
    for k in 0..3 {
        let (lo, hi) = fs.fem_n[..fs.fit]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), f| {
                (a.min(f[k]), b.max(f[k]))
            });
        assert!(c.r2[k] > 0.8, "component {k}: {c:?}");
        assert!(
            c.held_out_rmse_n[k] < (hi - lo) / 6.0,
            "component {k}: {c:?}"
        );
    }
    assert!(fit.contains(&[35.0; 3]) && fit.contains(&[-20.0; 3]));
    // The error is reported per nested range; the whole range holds every pair.
    let ranges: Vec<[f64; 2]> = c.by_range.iter().map(|r| r.range_kpa).collect();
    assert_eq!(ranges, ocm_surrogate::force::REPORT_RANGES_KPA);
    let whole = c.by_range[2];
    assert_eq!((whole.samples, whole.held_out_samples), (16, 4));
    for k in 0..3 {
        assert!((whole.held_out_rmse_n[k] - c.held_out_rmse_n[k]).abs() < 1e-12);
    }
    assert!(c.by_range[0].held_out_samples >= 2 && c.by_range[1].held_out_samples >= 3);
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
fn fem_jig_covers_the_whole_pressure_range_and_its_force_is_the_energy_gradient() {
    let Some(mesh) = ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    // The default (rigid-body) scene at the ends of the range: equal pressures push the clamp up
    // at 35 kPa and pull it down at -20 kPa; one chamber at 35 kPa pushes it sideways.
    let b = Bellows::load(&mesh, BellowsConfig::default()).unwrap();
    let p = [
        [35.0, 35.0, 35.0],
        [-20.0, -20.0, -20.0],
        [35.0, -20.0, -20.0],
    ];
    let f = ocm_surrogate::force::fem_clamped_jig_forces(&b, &p, |_| {}).unwrap();
    assert!(
        f[0].z > 10.0 && f[0].xy().norm() < 0.05 * f[0].z,
        "{:?}",
        f[0]
    );
    assert!(
        f[1].z < -5.0 && f[1].xy().norm() < 0.05 * f[1].z.abs(),
        "{:?}",
        f[1]
    );
    assert!(f[2].xy().norm() > 0.2, "{:?}", f[2]);
    // Independent check in the penalty scene, where the top frame's nodes can be moved: the
    // robot's force on the jig is minus the derivative of the total potential (strain energy
    // plus load potential, minimised over the free nodes) with respect to the jig position.
    let cfg = BellowsConfig {
        rigid: ocm_fem::bellows::RigidMode::Penalty,
        ..BellowsConfig::default()
    };
    let b = Bellows::load(&mesh, cfg).unwrap();
    let pk = [35.0, -20.0, -20.0];
    let f = ocm_surrogate::force::fem_clamped_jig_forces(&b, &[pk], |_| {}).unwrap()[0];
    let zt = b.config.rigid_top_above_mm * 1e-3;
    let potential = |axis: usize, shift: f64| {
        let mut m = b.model.clone();
        for i in 0..m.num_nodes() {
            if m.rest[i].z >= zt {
                for d in 0..3 {
                    m.prescribe(i, d, if d == axis { shift } else { 0.0 });
                }
            }
        }
        let mut solver = ocm_fem::solve::statics::StaticSolver::new(&m).unwrap();
        solver.load_steps = 4;
        let loads = b.loads_kpa(&pk);
        let (st, _) = solver.solve_from_rest(&m, &loads).unwrap();
        let ev = m
            .evaluate(&solver.pattern, &st.x, &loads, 1.0, false)
            .unwrap();
        ev.strain_energy + ev.load_potential
    };
    let h = 2e-5;
    for axis in [0, 2] {
        let d = (potential(axis, h) - potential(axis, -h)) / (2.0 * h);
        assert!(
            (d + f[axis]).abs() < 1e-4 * f.norm(),
            "axis {axis}: -dPi/dx {} N, reaction {} N",
            -d,
            f[axis]
        );
    }
}
