//! Verification of the reduced model against the full FEM, conservation and finite differences.

mod common;

use common::{block, full_basis, input, pod_basis};
use nalgebra::DVector;
use ocm_fem::model::{Loads, State};
use ocm_fem::solve::dynamics::{DynamicSolver, Integrator};
use ocm_mor::full::tip_point_forces;
use ocm_mor::rom::ReducedModel;

/// Displacement snapshots of the full block under a pressure ramp and a tip force.
fn snapshots(b: &common::Block) -> Vec<Vec<f64>> {
    let mut model = b.model.clone();
    let mut solver = DynamicSolver::new(&model, Integrator::ImplicitEuler).unwrap();
    let mut s = State::at_rest(&model);
    let rest = model.rest_dofs();
    let mut out = vec![];
    for k in 0..40 {
        let p = 3.0 * (k as f64 / 20.0).min(1.0);
        let f = if k >= 20 { [0.0, 0.3, -0.2] } else { [0.0; 3] };
        model.point_forces = tip_point_forces(&b.tip, f);
        solver
            .step(
                &model,
                &mut s,
                &Loads {
                    pressures_pa: vec![p * 1e3],
                },
                0.01,
            )
            .unwrap();
        out.push(s.x.iter().zip(&rest).map(|(x, r)| x - r).collect());
    }
    out
}

#[test]
fn the_full_basis_reproduces_the_full_model() {
    let b = block(0.05, 0.005);
    let rom = ReducedModel::galerkin(&b.model, full_basis(&b.model), &b.tip).unwrap();
    let mut model = b.model.clone();
    let mut solver = DynamicSolver::new(&model, Integrator::ImplicitEuler).unwrap();
    solver.options.rtol = 1e-10;
    let mut s = State::at_rest(&model);
    let mut rs = rom.rest_state();
    let mut rom = rom;
    rom.rtol = 1e-10;
    let rest = model.rest_dofs();
    let mut worst: f64 = 0.0;
    let mut largest: f64 = 0.0;
    for k in 0..15 {
        let inp = input(
            if k < 8 { 1.0 } else { -0.5 },
            [0.0, 0.05 * (k % 3) as f64, -0.1],
        );
        model.point_forces = tip_point_forces(&b.tip, inp.tip_force_n);
        solver
            .step(
                &model,
                &mut s,
                &Loads {
                    pressures_pa: vec![inp.pressure_kpa[0] * 1e3],
                },
                0.01,
            )
            .unwrap();
        rom.step(&mut rs, &inp, 0.01, Integrator::ImplicitEuler)
            .unwrap();
        let u = rom.displacement(&rs.q);
        for d in 0..rest.len() {
            let uf = s.x[d] - rest[d];
            worst = worst.max((u[d] - uf).abs());
            largest = largest.max(uf.abs());
        }
    }
    assert!(largest > 1e-4, "the block must move: {largest}");
    assert!(
        worst <= 1e-7 * largest,
        "full basis differs by {worst:.3e} (largest {largest:.3e})"
    );
}

#[test]
fn reduced_tangent_matches_finite_differences() {
    let b = block(0.05, 0.005);
    let basis = pod_basis(&snapshots(&b), 6);
    let rom = ReducedModel::galerkin(&b.model, basis, &b.tip).unwrap();
    let inp = input(3.0, [0.1, 0.2, -0.4]);
    let q0 = rom.solve_static(&input(2.0, [0.0; 3]), 4).unwrap();
    let q = &q0 + DVector::from_fn(6, |i, _| 1e-4 * (i as f64 - 2.5));
    let (_, k) = rom.static_residual(&q, &inp).unwrap();
    let eps = 1e-7;
    let mut worst: f64 = 0.0;
    for j in 0..6 {
        let mut qp = q.clone();
        let mut qm = q.clone();
        qp[j] += eps;
        qm[j] -= eps;
        let fd = (rom.static_residual(&qp, &inp).unwrap().0
            - rom.static_residual(&qm, &inp).unwrap().0)
            / (2.0 * eps);
        worst = worst.max((fd - k.column(j)).norm() / k.norm());
    }
    assert!(worst < 1e-6, "tangent vs finite differences: {worst:.3e}");
    // The pressure part alone is exact: its tangent is not symmetric zero.
    assert!(k.norm() > 0.0);
}

/// Largest relative energy error of a free vibration released from a pressurised equilibrium over
/// `t_end` seconds with steps of `h`, and the largest kinetic energy reached.
fn free_vibration(rom: &ReducedModel, h: f64, t_end: f64) -> (f64, f64, f64) {
    let free = input(0.0, [0.0; 3]);
    let mut s = rom.rest_state();
    s.q = rom.solve_static(&input(1.0, [0.0; 3]), 2).unwrap();
    let e0 = rom.energy(&s).unwrap();
    let (mut drift, mut max_ke): (f64, f64) = (0.0, 0.0);
    for _ in 0..(t_end / h).round() as usize {
        rom.step(&mut s, &free, h, Integrator::AVERAGE_ACCELERATION)
            .unwrap();
        let e = rom.energy(&s).unwrap();
        drift = drift.max((e - e0).abs() / e0);
        max_ke = max_ke.max(0.5 * s.v.dot(&(&rom.mass * &s.v)));
    }
    (drift, max_ke / e0, rom.energy(&s).unwrap() / e0)
}

#[test]
fn the_undamped_reduced_model_conserves_energy() {
    let basis = pod_basis(&snapshots(&block(0.05, 0.005)), 6);
    let b = block(0.0, 0.0);
    let rom = ReducedModel::galerkin(&b.model, basis.clone(), &b.tip).unwrap();
    // The trapezoidal rule conserves energy exactly for linear systems; on this nonlinear one the
    // error is bounded and shrinks as h^2.
    let (d1, swing, _) = free_vibration(&rom, 1e-3, 0.3);
    let (d2, _, _) = free_vibration(&rom, 5e-4, 0.3);
    assert!(
        swing > 0.5,
        "the strain energy must swing into motion: {swing}"
    );
    assert!(d1 < 1e-3, "energy drift {d1:.3e}");
    assert!(d2 < 0.35 * d1, "second order: {d2:.3e} vs {d1:.3e}");
    // With Rayleigh damping the same motion loses energy: the test can tell.
    let b2 = block(0.05, 0.005);
    let damped = ReducedModel::galerkin(&b2.model, basis, &b2.tip).unwrap();
    let (_, _, end) = free_vibration(&damped, 1e-3, 0.3);
    assert!(end < 0.9, "damped energy ratio {end}");
}

#[test]
fn ecsw_weights_are_non_negative_and_reproduce_the_training_forces() {
    let b = block(0.05, 0.005);
    let snaps = snapshots(&b);
    let basis = pod_basis(&snaps, 6);
    let rom = ReducedModel::galerkin(&b.model, basis.clone(), &b.tip).unwrap();
    let training: Vec<DVector<f64>> = snaps
        .iter()
        .step_by(2)
        .map(|u| basis.transpose() * DVector::from_column_slice(u))
        .collect();
    // a tolerance outside [0, 1) is refused, naming it
    for bad in [f64::NAN, -1.0, 1.0] {
        let e = rom.hyper_reduce(&training, bad).err().unwrap().to_string();
        assert!(e.contains(&format!("ECSW tolerance {bad}")), "{e}");
    }
    let tol = 1e-3;
    let ecsw = rom.hyper_reduce(&training, tol).unwrap();
    assert!(ecsw.weights.iter().all(|&w| w >= 0.0));
    assert!(ecsw.relative_residual <= tol, "{}", ecsw.relative_residual);
    let kept = ecsw.model.elements.len();
    assert!(
        kept < rom.elements.len() / 2,
        "{kept} of {} elements kept",
        rom.elements.len()
    );
    for q in &training {
        let fg = rom.internal(q, false).unwrap().f_int;
        let fe = ecsw.model.internal(q, false).unwrap().f_int;
        assert!(
            (fe - &fg).norm() <= 20.0 * tol * fg.norm(),
            "training force not reproduced"
        );
    }
    // On held-out configurations (odd snapshots) the error stays of the same order.
    for u in snaps.iter().skip(1).step_by(2) {
        let q = basis.transpose() * DVector::from_column_slice(u);
        let fg = rom.internal(&q, false).unwrap().f_int;
        let fe = ecsw.model.internal(&q, false).unwrap().f_int;
        assert!((fe - &fg).norm() <= 0.05 * fg.norm());
    }
}
