//! The Petrov-Galerkin reduced model with the step-matrix test basis W = J0^-1 V against the full
//! FEM: exact with the full basis, and the Euclidean projection of the full step in the linear
//! range.

mod common;

use common::{block, full_basis, full_run, input, pod_basis};
use nalgebra::DVector;
use ocm_fem::solve::dynamics::Integrator;
use ocm_mor::modes::step_test_basis;
use ocm_mor::rom::ReducedModel;

const H: f64 = 0.01;

fn reduced_run(rom: &ReducedModel, inputs: &[ocm_mor::drive::Input]) -> Vec<DVector<f64>> {
    let mut rs = rom.rest_state();
    inputs
        .iter()
        .map(|inp| {
            rom.step(&mut rs, inp, H, Integrator::ImplicitEuler)
                .unwrap();
            rs.q.clone()
        })
        .collect()
}

#[test]
fn petrov_galerkin_with_the_full_basis_reproduces_the_full_model() {
    let b = block(0.05, 0.005);
    let v = full_basis(&b.model);
    let w = step_test_basis(&b.model, &v, H).unwrap();
    let mut rom = ReducedModel::petrov_galerkin(&b.model, v, w, &b.tip).unwrap();
    rom.rtol = 1e-11;
    rom.damping_tangent_age = 1;
    // Loads for which the reduced Newton converges without cutting a step (under the larger
    // loads of the Galerkin test, 1 / -0.5 kPa with a 3 cm tip motion, it cuts the step at the
    // pressure reversal and then solves two half steps: another discrete solution).
    let inputs: Vec<_> = (0..15)
        .map(|k| {
            input(
                if k < 8 { 0.3 } else { -0.15 },
                [0.0, 0.02 * (k % 3) as f64, -0.03],
            )
        })
        .collect();
    let full = full_run(&b, H, &inputs);
    let red = reduced_run(&rom, &inputs);
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for (uf, q) in full.iter().zip(&red) {
        let u = rom.displacement(q);
        for d in 0..uf.len() {
            worst = worst.max((u[d] - uf[d]).abs());
            largest = largest.max(uf[d].abs());
        }
    }
    assert!(largest > 1e-4, "the block must move: {largest}");
    assert!(
        worst <= 1e-7 * largest,
        "full basis differs by {worst:.3e} (largest {largest:.3e})"
    );
}

/// In the linear range (tiny loads) one reduced step from rest returns V^T of the full step:
/// W^T J0 V = V^T V and W^T J0 u = V^T u. Galerkin returns the J0-orthogonal projection instead,
/// which differs by far more on a basis that misses part of the response.
#[test]
fn petrov_galerkin_step_is_the_projection_of_the_full_step_in_the_linear_range() {
    let b = block(0.05, 0.005);
    // A basis of snapshots under other loads (so the step below is not in its span).
    let train: Vec<_> = (0..20)
        .map(|k| input(2.0 * (k as f64 / 10.0).min(1.0), [0.0, 0.2, 0.0]))
        .collect();
    let snaps = full_run(&b, H, &train);
    let v = pod_basis(&snaps, 3);
    let w = step_test_basis(&b.model, &v, H).unwrap();
    let mut pg = ReducedModel::petrov_galerkin(&b.model, v.clone(), w, &b.tip).unwrap();
    let mut gal = ReducedModel::galerkin(&b.model, v.clone(), &b.tip).unwrap();
    for m in [&mut pg, &mut gal] {
        m.rtol = 1e-12;
        m.damping_tangent_age = 1;
    }
    let step = [input(1e-4, [0.0, 0.0, -1e-4])];
    let uf = DVector::from_vec(full_run(&b, H, &step).remove(0));
    let qp = v.transpose() * &uf;
    let e_pg = (&reduced_run(&pg, &step)[0] - &qp).norm() / qp.norm();
    let e_gal = (&reduced_run(&gal, &step)[0] - &qp).norm() / qp.norm();
    assert!(uf.norm() > 0.0 && (&uf - &v * &qp).norm() > 1e-2 * uf.norm());
    assert!(
        e_pg < 1e-4,
        "Petrov-Galerkin misses the projection by {e_pg:.3e}"
    );
    assert!(
        e_gal > 100.0 * e_pg,
        "Galerkin {e_gal:.3e}, Petrov-Galerkin {e_pg:.3e}"
    );
}
