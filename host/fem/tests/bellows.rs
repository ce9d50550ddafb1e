//! The real bellows manipulator: scene construction and one pressurised equilibrium.

use ocm_fem::bellows::{Bellows, BellowsConfig, Law, RigidMode};
use ocm_fem::solve::dynamics::{DynamicSolver, Integrator};
use ocm_fem::solve::statics::StaticSolver;
use std::path::PathBuf;

fn mesh_path() -> Option<PathBuf> {
    ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk")
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

/// Largest relative change of the pairwise distances of `nodes` from rest.
fn rigidity_error(b: &Bellows, s: &ocm_fem::model::State, nodes: &[usize]) -> f64 {
    let pos = s.positions();
    let rest = &b.model.rest;
    let mut worst: f64 = 0.0;
    for (k, &i) in nodes.iter().enumerate() {
        for &j in &nodes[k + 1..] {
            let d0 = (rest[i] - rest[j]).norm();
            worst = worst.max(((pos[i] - pos[j]).norm() - d0).abs() / d0);
        }
    }
    worst
}

/// True rigid bodies against the stiff penalty on the real mesh: with constraints the top frame
/// keeps its shape to round-off and the base does not move; the TCP stays close to the penalty
/// result (the penalty frame is 100x stiffer, not rigid); one implicit step also keeps it rigid.
#[test]
fn rigid_constraints_agree_with_the_penalty_model() {
    let Some(p) = mesh_path() else { return };
    let mk = |rigid| {
        Bellows::load(
            &p,
            BellowsConfig {
                law: Law::NeoHookeanBulk,
                rigid,
                ..BellowsConfig::default()
            },
        )
        .unwrap()
    };
    let (bc, bp) = (mk(RigidMode::Constraint), mk(RigidMode::Penalty));
    assert_eq!(bc.top_frame, bp.top_frame);
    let top = bc.top_body.expect("constraint mode has a top body");
    assert_eq!(bc.model.rigid_bodies[top].nodes, bc.top_frame);
    let base = bc.model.rigid_bodies[1 - top].nodes.clone();
    let (mut sc, mut sp) = (
        StaticSolver::new(&bc.model).unwrap(),
        StaticSolver::new(&bp.model).unwrap(),
    );
    assert_eq!(
        sc.pattern.clamped_bodies,
        vec![1 - top],
        "the base touches the clamp"
    );
    for p_kpa in [[10.0, 0.0, 0.0], [0.0, 25.0, 10.0]] {
        let (xc, rc) = bc.solve_kpa(&mut sc, &p_kpa).unwrap();
        let (xp, rp) = bp.solve_kpa(&mut sp, &p_kpa).unwrap();
        let (tc, tp) = (bc.state_of(&xc), bp.state_of(&xp));
        let d_tcp = (0..3)
            .map(|k| (tc.tcp_m[k] - tp.tcp_m[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let travel = (0..3)
            .map(|k| (tp.tcp_m[k] - [0.0, 0.0, 0.19][k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let (ec, ep) = (
            rigidity_error(&bc, &xc, &bc.top_frame),
            rigidity_error(&bp, &xp, &bp.top_frame),
        );
        eprintln!(
            "{p_kpa:?} kPa: TCP constraint {:?} vs penalty {:?} mm: |difference| {:.4} mm of {:.3} mm travel; \
             top-frame strain constraint {ec:.1e}, penalty {ep:.1e}; Newton iterations {} vs {}",
            tc.tcp_m.map(|v| v * 1e3),
            tp.tcp_m.map(|v| v * 1e3),
            d_tcp * 1e3,
            travel * 1e3,
            rc.iterations,
            rp.iterations
        );
        assert!(ec < 1e-12, "constrained top frame deformed by {ec:e}");
        assert!(
            ep > 1e3 * ec.max(1e-15),
            "the penalty frame is only nearly rigid"
        );
        for &i in &base {
            for d in 0..3 {
                assert_eq!(
                    xc.x[3 * i + d],
                    bc.model.rest[i][d],
                    "the clamped base moved"
                );
            }
        }
        // The penalty frame is stiff but not rigid, and its base connectors may flex: a few
        // percent of the travel.
        assert!(
            d_tcp < 0.05 * travel,
            "TCP differs by {d_tcp} m of {travel} m"
        );
        // Top-plate orientation from the body's R agrees with the penalty frame's Kabsch fit.
        let dr = (0..3)
            .map(|k| (tc.plate_rotation_rad[k] - tp.plate_rotation_rad[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let rot = tp
            .plate_rotation_rad
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        assert!(dr < 0.05 * rot, "plate rotation {dr} rad apart of {rot}");
    }
    let mut dyn_solver =
        DynamicSolver::new(&bc.model, Integrator::ImplicitEuler).expect("dynamic solver");
    let mut s = ocm_fem::model::State::at_rest(&bc.model);
    dyn_solver
        .step(&bc.model, &mut s, &bc.loads_kpa(&[20.0, 0.0, 0.0]), 0.01)
        .unwrap();
    assert!(rigidity_error(&bc, &s, &bc.top_frame) < 1e-12);
    assert!(s.bodies[top].velocity.norm() > 0.0, "the top plate moves");
}

#[test]
fn material_out_of_range_is_named_as_given() {
    BellowsConfig::default().validate().unwrap();
    for (cfg, want) in [
        (
            BellowsConfig {
                poisson: 0.5,
                ..BellowsConfig::default()
            },
            "Poisson's ratio must lie strictly between -1 and 0.5 (0.5 is incompressible), got 0.5",
        ),
        (
            BellowsConfig {
                young_pa: -1.0,
                ..BellowsConfig::default()
            },
            "Young's modulus must be a positive number, got -1 Pa",
        ),
        (
            BellowsConfig {
                poisson: f64::NAN,
                ..BellowsConfig::default()
            },
            "got NaN",
        ),
    ] {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
}
