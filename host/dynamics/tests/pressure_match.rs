//! The f_RS matcher (`pressure_match`) on the real bellows with a small reduced model (a basis of
//! four full static solutions): it recovers pressures whose reduced static TCP is known by
//! construction, it matches a full-FEM static TCP (computed independently by the full solver)
//! closer than the same pressures do, it never leaves the pressure range, and it refuses a
//! non-finite target.

use nalgebra::{DMatrix, DVector, Vector3};
use ocm_dynamics::DynamicsError;
use ocm_dynamics::pressure_match::{
    PRESSURE_RANGE_KPA, PressureMatchConfig, match_pressures, match_samples, reduced_static_tcp,
};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_fem::solve::statics::StaticSolver;
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::ReducedProbe;
use ocm_mor::xs::XsProbe;

#[test]
fn matcher_recovers_known_pressures_and_matches_the_full_fem() {
    let Some(path) = ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let clock = std::time::Instant::now();
    let b = Bellows::load(path, BellowsConfig::default()).unwrap();
    let mut solver = StaticSolver::new(&b.model).unwrap();
    let rest = b.model.rest_dofs();
    let full_tcp = |solver: &mut StaticSolver, p: &[f64; 3]| {
        let (s, _) = b.solve_kpa(solver, p).unwrap();
        (s.x.clone(), Vector3::from(b.state_of(&s).tcp_m))
    };
    // Orthonormal basis of four full static displacements (modified Gram-Schmidt).
    let mut basis = DMatrix::<f64>::zeros(rest.len(), 4);
    for (k, p) in [
        [20.0, 0.0, 0.0],
        [0.0, 20.0, 0.0],
        [0.0, 0.0, 20.0],
        [10.0, 10.0, 10.0],
    ]
    .iter()
    .enumerate()
    {
        let (x, _) = full_tcp(&mut solver, p);
        let mut v = DVector::from_iterator(rest.len(), x.iter().zip(&rest).map(|(x, r)| x - r));
        for j in 0..k {
            let bj = basis.column(j).into_owned();
            v -= &bj * bj.dot(&v);
        }
        basis.set_column(k, &v.normalize());
    }
    let rom = ReducedModel::galerkin(&b.model, basis, &b.top_face).unwrap();
    let probe = ReducedProbe::new(XsProbe::of_bellows(&b), &rom);
    let cfg = PressureMatchConfig::default();
    eprintln!(
        "reduced model built after {:.1} s",
        clock.elapsed().as_secs_f64()
    );

    // 1. A target that the reduced model reaches at known pressures: the match from 10 kPa away
    //    returns them.
    let truth = [14.0, 4.0, 9.0];
    let target = reduced_static_tcp(&rom, &probe, &truth, cfg.load_steps).unwrap();
    let start = [4.0, 12.0, 1.0];
    let start_dist =
        (reduced_static_tcp(&rom, &probe, &start, cfg.load_steps).unwrap() - target).norm();
    let (p, e) = match_pressures(&rom, &probe, &target, &start, &cfg).unwrap();
    let p_err = (0..3).map(|k| (p[k] - truth[k]).abs()).fold(0.0, f64::max);
    eprintln!(
        "known pressures: got {p:?} ({p_err:.2e} kPa off), TCP {e:.2e} m from {start_dist:.2e}"
    );
    eprintln!("matched after {:.1} s", clock.elapsed().as_secs_f64());
    assert!(
        start_dist > 1e-3,
        "the start is {start_dist} m away: no test"
    );
    assert!(e < 1e-5, "remaining TCP distance {e} m");
    assert!(p_err < 0.05, "pressures {p:?} vs {truth:?}");
    // The distance it reports is the distance at the pressures it returns.
    let check = (reduced_static_tcp(&rom, &probe, &p, cfg.load_steps).unwrap() - target).norm();
    assert!((check - e).abs() < 1e-9, "reported {e}, recomputed {check}");

    // 2. A full-FEM static sample (the stand-in for the robot): the reduced TCP at the same
    //    pressures misses it by the reduction error; at the matched pressures it is far closer.
    let p_r = [22.0, 6.0, 2.0];
    let (_, tcp_r) = full_tcp(&mut solver, &p_r);
    let same = (reduced_static_tcp(&rom, &probe, &p_r, cfg.load_steps).unwrap() - tcp_r).norm();
    let (pairs, failed) =
        match_samples(&rom, &probe, &[(p_r, tcp_r.into())], &cfg, |_| {}).unwrap();
    assert!(failed.is_empty());
    let pair = pairs[0];
    let matched =
        (reduced_static_tcp(&rom, &probe, &pair.sim_kpa, cfg.load_steps).unwrap() - tcp_r).norm();
    eprintln!(
        "full FEM at {p_r:?}: reduced TCP {:.3} mm off at the same pressures, {:.3} mm at {:?}",
        1e3 * same,
        1e3 * matched,
        pair.sim_kpa
    );
    assert_eq!(pair.real_kpa, p_r);
    assert!((matched - pair.tcp_error_m).abs() < 1e-9);
    assert!(
        same > 2e-4,
        "the reduction error {same} m is too small to test"
    );
    assert!(matched < 0.2 * same, "matched {matched} m vs {same} m");

    // 3. An unreachable target (half a metre off): the best iterate, in range, no worse than
    //    the start; a start outside the range is clamped first.
    let far = target + Vector3::new(0.5, 0.0, 0.0);
    let wild = [50.0, 5.0, 10.0];
    let clamped = [PRESSURE_RANGE_KPA.1, 5.0, 10.0];
    let from = (reduced_static_tcp(&rom, &probe, &clamped, cfg.load_steps).unwrap() - far).norm();
    let few = PressureMatchConfig {
        max_iterations: 3,
        ..cfg
    };
    let (p, e) = match_pressures(&rom, &probe, &far, &wild, &few).unwrap();
    assert!(
        p.iter()
            .all(|v| (PRESSURE_RANGE_KPA.0..=PRESSURE_RANGE_KPA.1).contains(v)),
        "{p:?} out of range"
    );
    assert!(e <= from && e > 0.4, "best {e} m, start {from} m");

    // 4. A non-finite target is refused by name.
    let nan = Vector3::new(f64::NAN, 0.0, 0.1);
    match match_pressures(&rom, &probe, &nan, &truth, &cfg) {
        Err(DynamicsError::Data(m)) => assert!(m.contains("not finite"), "{m}"),
        other => panic!("expected a data error, got {other:?}"),
    }
}
