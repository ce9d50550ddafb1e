//! LSPG (Gauss-Newton on the full step residual) against the full FEM and against its own
//! definition: exact with the full basis; at a converged step the residual's gradient vanishes
//! (central differences), the Jacobian is the residual's derivative, and no other q (Galerkin's
//! step included) has a smaller residual nearby.

mod common;

use common::{block, full_basis, full_run, input, pod_basis};
use nalgebra::DVector;
use ocm_fem::solve::dynamics::Integrator;
use ocm_mor::lspg::{Lspg, LspgOptions};
use ocm_mor::rom::ReducedModel;

const H: f64 = 0.01;

#[test]
fn lspg_with_the_full_basis_reproduces_the_full_model() {
    let b = block(0.05, 0.005);
    let v = full_basis(&b.model);
    let mut m = Lspg::new(&b.model, v.clone(), &b.tip).unwrap();
    m.options = LspgOptions {
        rtol: 1e-12,
        xtol: 1e-12,
        ..LspgOptions::default()
    };
    // The Galerkin test's loads: a pressure reversal and a tip force, 3 cm of tip motion.
    let inputs: Vec<_> = (0..15)
        .map(|k| {
            input(
                if k < 8 { 1.0 } else { -0.5 },
                [0.0, 0.2 * (k % 3) as f64, -0.3],
            )
        })
        .collect();
    let full = full_run(&b, H, &inputs);
    let mut s = m.rest_state();
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for (uf, inp) in full.iter().zip(&inputs) {
        m.step(&mut s, inp, H).unwrap();
        let u = &v * &s.q;
        for d in 0..uf.len() {
            worst = worst.max((u[d] - uf[d]).abs());
            largest = largest.max(uf[d].abs());
        }
    }
    assert!(largest > 1e-3, "the block must move: {largest}");
    assert!(
        worst <= 1e-7 * largest,
        "full basis differs by {worst:.3e} (largest {largest:.3e})"
    );
}

#[test]
fn converged_lspg_step_is_a_stationary_point_of_the_residual_norm() {
    let b = block(0.05, 0.005);
    // A rank-3 basis of snapshots under other loads: the steps below are not in its span, so the
    // residual stays non-zero and LSPG differs from Galerkin.
    let train: Vec<_> = (0..20)
        .map(|k| input(2.0 * (k as f64 / 10.0).min(1.0), [0.0, 0.2, 0.0]))
        .collect();
    let snaps = full_run(&b, H, &train);
    let v = pod_basis(&snaps, 3);
    let mut m = Lspg::new(&b.model, v.clone(), &b.tip).unwrap();
    m.options.gtol = 1e-10;
    m.options.xtol = 1e-12;
    let mut s = m.rest_state();
    for _ in 0..4 {
        m.step(&mut s, &input(1.5, [0.0, 0.3, -0.2]), H).unwrap();
    }
    let start = s.clone();
    // A jump of the inputs, as after a pressure step.
    let inp = input(-0.8, [0.0, -0.3, 0.2]);
    m.step(&mut s, &inp, H).unwrap();
    let q = s.q.clone();
    assert!(
        (&q - &start.q).norm() > 1e-3 * q.norm(),
        "the step must move"
    );
    let (r0, j0) = m.residual(&start, &inp, H, &q).unwrap();
    assert!(
        r0.norm() > 1e-6,
        "the residual must not vanish: {}",
        r0.norm()
    );
    let scale = j0.norm() * r0.norm();
    // Jacobian and gradient by central differences.
    let phi = |m: &mut Lspg, q: &DVector<f64>| {
        0.5 * m.residual(&start, &inp, H, q).unwrap().0.norm_squared()
    };
    let fd_grad = |m: &mut Lspg, q: &DVector<f64>| {
        DVector::from_iterator(
            3,
            (0..3).map(|k| {
                let e = 1e-6 * q.norm();
                let mut qp = q.clone();
                qp[k] += e;
                let mut qm = q.clone();
                qm[k] -= e;
                (phi(m, &qp) - phi(m, &qm)) / (2.0 * e)
            }),
        )
    };
    for k in 0..3 {
        let e = 1e-6 * q.norm();
        let mut qp = q.clone();
        qp[k] += e;
        let mut qm = q.clone();
        qm[k] -= e;
        let d = (m.residual(&start, &inp, H, &qp).unwrap().0
            - m.residual(&start, &inp, H, &qm).unwrap().0)
            / (2.0 * e);
        let err = (&d - j0.column(k)).norm() / j0.column(k).norm();
        assert!(err < 1e-5, "Jacobian column {k} off by {err:.3e}");
    }
    let g = fd_grad(&mut m, &q);
    assert!(
        g.norm() <= 1e-6 * scale,
        "gradient at the LSPG step {:.3e} (scale {scale:.3e})",
        g.norm()
    );
    assert!((j0.tr_mul(&r0)).norm() <= 1e-8 * scale);
    // Away from it the same test fails: it can tell.
    let off = &q + DVector::from_element(3, 1e-3 * q.norm());
    let g_off = fd_grad(&mut m, &off);
    assert!(
        g_off.norm() > 1e-3 * scale,
        "gradient off the step {:.3e}",
        g_off.norm()
    );
    // Galerkin's step from the same start has the larger step residual.
    let mut gal = ReducedModel::galerkin(&b.model, v, &b.tip).unwrap();
    gal.rtol = 1e-12;
    gal.damping_tangent_age = 1;
    let mut sg = start.clone();
    gal.step(&mut sg, &inp, H, Integrator::ImplicitEuler)
        .unwrap();
    let rg = m.residual(&start, &inp, H, &sg.q).unwrap().0.norm();
    assert!(
        rg > r0.norm() * (1.0 + 1e-6),
        "Galerkin residual {rg:.6e}, LSPG {:.6e}",
        r0.norm()
    );
}

#[test]
fn lspg_rejects_a_basis_that_moves_fixed_dofs() {
    let b = block(0.05, 0.005);
    let mut v = full_basis(&b.model);
    let d = (0..b.model.fixed.len())
        .find(|&d| b.model.fixed[d])
        .unwrap();
    v[(d, 0)] = 0.5;
    let e = Lspg::new(&b.model, v, &b.tip).err().unwrap().to_string();
    assert!(e.contains(&format!("fixed DOF {d}")), "{e}");
}

/// Weighted by the inverse step matrix at rest, an LSPG step in the linear range (tiny loads,
/// J = J0) minimises ||V q - u|| for the full step u: it returns V^T u. Plain LSPG minimises
/// ||J0 (V q - u)|| instead and misses it by far more.
#[test]
fn weighted_lspg_step_is_the_projection_of_the_full_step_in_the_linear_range() {
    let b = block(0.05, 0.005);
    let train: Vec<_> = (0..20)
        .map(|k| input(2.0 * (k as f64 / 10.0).min(1.0), [0.0, 0.2, 0.0]))
        .collect();
    let snaps = full_run(&b, H, &train);
    let v = pod_basis(&snaps, 3);
    let step = input(1e-4, [0.0, 0.0, -1e-4]);
    let uf = DVector::from_vec(full_run(&b, H, &[step]).remove(0));
    let qp = v.transpose() * &uf;
    assert!((&uf - &v * &qp).norm() > 1e-2 * uf.norm());
    let mut err = vec![];
    for weighted in [true, false] {
        let mut m = Lspg::new(&b.model, v.clone(), &b.tip).unwrap();
        if weighted {
            m.weight_by_rest_step_matrix(H).unwrap();
        }
        m.options.gtol = 1e-12;
        m.options.xtol = 1e-12;
        let mut s = m.rest_state();
        m.step(&mut s, &step, H).unwrap();
        err.push((&s.q - &qp).norm() / qp.norm());
    }
    assert!(
        err[0] < 1e-4,
        "weighted LSPG misses the projection by {:.3e}",
        err[0]
    );
    assert!(
        err[1] > 100.0 * err[0],
        "plain {:.3e}, weighted {:.3e}",
        err[1],
        err[0]
    );
}
