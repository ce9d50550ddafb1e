//! Rigid bodies by master-slave elimination: exact rigidity, agreement with a stiff penalty, the
//! reduced tangent against finite differences, energy conservation and rigid-body dynamics against
//! an independent integrator of Euler's equations.
#![allow(clippy::needless_range_loop)]

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use ocm_fem::material::Material;
use ocm_fem::mesh::{generate, surface};
use ocm_fem::model::{Loads, MassKind, Model, Pattern, State};
use ocm_fem::solve::dynamics::{DynamicSolver, Integrator};
use ocm_fem::solve::statics::StaticSolver;

/// Largest relative change of the pairwise distances of `nodes` from rest.
fn rigidity_error(model: &Model, s: &State, nodes: &[usize]) -> f64 {
    let pos = s.positions();
    let mut worst: f64 = 0.0;
    for (k, &i) in nodes.iter().enumerate() {
        for &j in &nodes[k + 1..] {
            let d0 = (model.rest[i] - model.rest[j]).norm();
            let d = (pos[i] - pos[j]).norm();
            worst = worst.max((d - d0).abs() / d0);
        }
    }
    worst
}

/// A free-floating bar with a rigid end block, spun by a force pair (zero net force): the block's
/// nodes keep their distances, linear momentum stays zero, and the block really turns.
#[test]
fn free_bar_under_a_force_pair_keeps_its_block_rigid() {
    let mesh = generate::box_mesh([6, 1, 1], [0.6, 0.1, 0.1]);
    let mut model = Model::new(&mesh, Material::neo_hookean(2e5, 0.3), 1000.0).unwrap();
    let b = model.add_rigid_body("block", |p| p.x >= 0.39).unwrap();
    let nodes = model.rigid_bodies[b].nodes.clone();
    assert_eq!(nodes.len(), 3 * 4);
    // +z on the free end, -z on the block's far end: a couple about y, plus an axial pull pair.
    let ends = |x: f64| -> Vec<usize> {
        (0..model.num_nodes())
            .filter(|&i| (model.rest[i].x - x).abs() < 1e-9)
            .collect()
    };
    let (left, right) = (ends(0.0), ends(0.6));
    for &i in &left {
        model
            .point_forces
            .push((i, Vector3::new(-2.0, 0.0, 5.0) / left.len() as f64));
    }
    for &i in &right {
        model
            .point_forces
            .push((i, Vector3::new(2.0, 0.0, -5.0) / right.len() as f64));
    }
    for integrator in [Integrator::ImplicitEuler, Integrator::AVERAGE_ACCELERATION] {
        let mut solver = DynamicSolver::new(&model, integrator).unwrap();
        let mut s = State::at_rest(&model);
        let mut max_speed: f64 = 0.0;
        for _ in 0..40 {
            solver
                .step(&model, &mut s, &Loads::default(), 0.01)
                .unwrap();
            assert!(
                rigidity_error(&model, &s, &nodes) < 1e-10,
                "{integrator:?}: block deformed by {:e}",
                rigidity_error(&model, &s, &nodes)
            );
            let p: Vector3<f64> = model
                .mass_times(&s.v)
                .chunks_exact(3)
                .map(|c| Vector3::new(c[0], c[1], c[2]))
                .sum();
            max_speed = max_speed.max(s.v.iter().fold(0.0f64, |a, v| a.max(v.abs())));
            assert!(
                p.norm() <= 1e-6 * model.total_mass() * max_speed,
                "{integrator:?}: momentum {p} with no net force"
            );
        }
        let angle = s.bodies[b].rotation.angle();
        assert!(
            angle > 0.3,
            "{integrator:?}: the couple must turn the block ({angle} rad)"
        );
        // The stored rotation is the one the slaves show (Kabsch fit of the block's nodes).
        let pos = s.positions();
        let c1: Vector3<f64> =
            nodes.iter().map(|&i| pos[i]).sum::<Vector3<f64>>() / nodes.len() as f64;
        let c0: Vector3<f64> =
            nodes.iter().map(|&i| model.rest[i]).sum::<Vector3<f64>>() / nodes.len() as f64;
        let mut h = Matrix3::zeros();
        for &i in &nodes {
            h += (pos[i] - c1) * (model.rest[i] - c0).transpose();
        }
        let fit = ocm_fem::element::polar_rotation(&h);
        assert!((fit - s.bodies[b].rotation_matrix()).norm() < 1e-10);
    }
}

/// Tip deflection of a cantilever with a rigid end block (constraint), or the same block made
/// `factor` times stiffer (penalty). Neo-Hookean, whose exact tangent keeps Newton converging on
/// a 1e6 penalty (the corotational law's approximate tangent stalls there).
fn cantilever_with_block(n: [usize; 2], rigid: Option<f64>) -> f64 {
    let (l, h, e, load) = (10.0, 1.0, 1e6, 1.0);
    let mesh = generate::box_mesh([n[0], n[1], n[1]], [l, h, h]);
    let mut model = Model::new(&mesh, Material::neo_hookean(e, 0.0), 1000.0).unwrap();
    model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
    match rigid {
        Some(factor) => {
            model.make_rigid(|p| p.x >= 9.0 - 1e-9, factor);
        }
        None => {
            model.add_rigid_body("tip", |p| p.x >= 9.0 - 1e-9).unwrap();
        }
    }
    let tip: Vec<usize> = (0..model.num_nodes())
        .filter(|&i| (model.rest[i][0] - l).abs() < 1e-9)
        .collect();
    for &i in &tip {
        model
            .point_forces
            .push((i, Vector3::new(0.0, 0.0, -load / tip.len() as f64)));
    }
    let mut solver = StaticSolver::new(&model).unwrap();
    let (state, _) = solver.solve_from_rest(&model, &Loads::default()).unwrap();
    -tip.iter()
        .map(|&i| state.x[3 * i + 2] - model.rest[i][2])
        .sum::<f64>()
        / tip.len() as f64
}

/// The constrained block agrees with a very stiff penalty block and converges under refinement
/// to Timoshenko beam theory for an elastic span a with a rigid end piece b.
#[test]
fn rigid_tip_block_matches_stiff_penalty_and_beam_theory() {
    for n in [[10, 1], [20, 2]] {
        let c = cantilever_with_block(n, None);
        let p = cantilever_with_block(n, Some(1e6));
        eprintln!(
            "mesh {n:?}: constraint {c:.9e}, penalty 1e6 {p:.9e}, relative difference {:.2e}",
            (c - p).abs() / c
        );
        assert!(
            (c - p).abs() < 1e-6 * c,
            "mesh {n:?}: constraint {c} vs penalty {p}"
        );
    }
    let (a, b, e, g, area, inertia): (f64, f64, f64, f64, f64, f64) =
        (9.0, 1.0, 1e6, 0.5e6, 1.0, 1.0 / 12.0);
    let rot = a * a / (2.0 * e * inertia) + b * a / (e * inertia);
    let exact = a.powi(3) / (3.0 * e * inertia)
        + b * a * a / (2.0 * e * inertia)
        + a / (5.0 / 6.0 * g * area)
        + b * rot;
    let d: Vec<f64> = [[10, 1], [20, 2], [40, 4], [80, 8]]
        .into_iter()
        .map(|n| cantilever_with_block(n, None))
        .collect();
    let errors: Vec<f64> = d.iter().map(|x| (x - exact).abs() / exact).collect();
    let rate = ((d[2] - d[1]) / (d[3] - d[2])).log2();
    let limit = d[3] + (d[3] - d[2]) / (2f64.powf(rate) - 1.0);
    eprintln!("errors {errors:?}, order {rate:.2}, extrapolated {limit:.5} vs beam {exact:.5}");
    assert!(errors.windows(2).all(|w| w[0] > w[1]), "{errors:?}");
    assert!(rate > 0.5, "order {rate}");
    // Linear tets lock in bending: the same pre-asymptotic 5 % as the all-elastic cantilever.
    assert!(errors[3] < 0.06, "{errors:?}");
}

/// A block clamped at x = 0 with a rigid root slab (clamped whole, it touches the clamp), a free
/// rigid tip slab, pressure on its closed skin and its top face, gravity and a point force.
fn two_body_block() -> (Model, usize) {
    let mesh = generate::box_mesh([5, 2, 2], [1.0, 0.8, 0.6]);
    let boundary = surface::boundary_faces(&mesh.points, &mesh.tets);
    let mut model = Model::new(&mesh, Material::neo_hookean_bulk(1e3, 0.4), 1000.0).unwrap();
    model.gravity = Vector3::new(0.0, 0.0, -9.81);
    model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
    model.add_rigid_body("root", |p| p.x <= 0.21).unwrap();
    let tip = model.add_rigid_body("tip", |p| p.x >= 0.79).unwrap();
    model.add_cavity("skin", boundary.clone()).unwrap();
    let top: Vec<[usize; 3]> = boundary
        .iter()
        .copied()
        .filter(|t| t.iter().all(|&i| (mesh.points[i][2] - 0.6).abs() < 1e-9))
        .collect();
    model.add_pressure_surface("top", top).unwrap();
    let last = model.num_nodes() - 1;
    model
        .point_forces
        .push((last, Vector3::new(3.0, -2.0, 1.0)));
    (model, tip)
}

/// A deformed configuration: free nodes displaced, the tip body shifted and turned by 0.4 rad.
fn deformed(model: &Model, pat: &Pattern, tip: usize) -> State {
    let mut s = State::at_rest(model);
    for (j, &d) in pat.dof_of.iter().enumerate() {
        s.x[d] += 0.04 * ((j as f64) * 1.7).sin();
    }
    s.bodies[tip] = s.bodies[tip].moved(
        Vector3::new(0.03, -0.02, 0.05),
        Vector3::new(0.2, -0.3, 0.15),
    );
    model.place_bodies(&mut s).unwrap();
    s
}

/// Moves `s` by the unit reduced increment `h e_j` (translation or rotation for body DOFs).
fn perturbed(model: &Model, pat: &Pattern, s: &State, j: usize, h: f64) -> State {
    let mut t = s.clone();
    if j < pat.dof_of.len() {
        t.x[pat.dof_of[j]] += h;
    } else {
        let b = &pat.bodies[(j - pat.dof_of.len()) / 6];
        let k = j - b.first;
        let mut v = Vector3::zeros();
        v[k % 3] = h;
        t.bodies[b.body] = if k < 3 {
            t.bodies[b.body].moved(v, Vector3::zeros())
        } else {
            t.bodies[b.body].moved(Vector3::zeros(), v)
        };
        model.place_bodies(&mut t).unwrap();
    }
    t
}

/// The reduced tangent (translations and rotation increments R <- exp(dtheta) R) against central
/// differences of the reduced residual: equal up to the known skew part -[m]x/2 of the rotation
/// block (m the body's residual moment), which vanishes at equilibrium.
#[test]
fn reduced_tangent_matches_finite_differences() {
    let (model, tip) = two_body_block();
    let pat = Pattern::new(&model).unwrap();
    assert_eq!(pat.bodies.len(), 1, "the root body is clamped");
    assert_eq!(pat.clamped_bodies, vec![0]);
    let loads = Loads {
        pressures_pa: vec![150.0, -80.0],
    };
    let s = deformed(&model, &pat, tip);
    let ev = model.evaluate(&pat, &s.x, &loads, 1.0, true).unwrap();
    let k = ev.tangent.unwrap();
    let nf = pat.num_free();
    let mut dense = vec![vec![0.0; nf]; nf];
    for j in 0..nf {
        for kk in pat.col_ptr[j]..pat.col_ptr[j + 1] {
            dense[pat.row_idx[kk]][j] = k[kk];
        }
    }
    let f = pat.bodies[0].first;
    let m = Vector3::new(ev.residual[f + 3], ev.residual[f + 4], ev.residual[f + 5]);
    assert!(m.norm() > 1e-3, "the test point must be off equilibrium");
    let skew_m = ocm_fem::model::skew(&m);
    for i in 0..3 {
        for kk in 0..3 {
            dense[f + 3 + i][f + 3 + kk] -= 0.5 * skew_m[(i, kk)];
        }
    }
    let scale = dense.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    let mut worst_body: f64 = 0.0;
    for j in 0..nf {
        let rp = model
            .evaluate(
                &pat,
                &perturbed(&model, &pat, &s, j, h).x,
                &loads,
                1.0,
                false,
            )
            .unwrap()
            .residual;
        let rm = model
            .evaluate(
                &pat,
                &perturbed(&model, &pat, &s, j, -h).x,
                &loads,
                1.0,
                false,
            )
            .unwrap()
            .residual;
        for i in 0..nf {
            let err = ((rp[i] - rm[i]) / (2.0 * h) - dense[i][j]).abs();
            worst = worst.max(err);
            if i >= f || j >= f {
                worst_body = worst_body.max(err);
            }
        }
    }
    eprintln!("tangent error {worst:e} (body rows/columns {worst_body:e}) vs scale {scale:e}");
    assert!(worst < 1e-6 * scale, "tangent error {worst:e} vs {scale:e}");
}

/// With conservative loads (closed-cavity pressure, gravity, point forces) the reduced residual
/// is the gradient of the total potential, rotations included.
#[test]
fn reduced_residual_is_the_gradient_of_the_potential() {
    let (model, tip) = two_body_block();
    let pat = Pattern::new(&model).unwrap();
    let loads = Loads {
        pressures_pa: vec![150.0, 0.0],
    };
    let s = deformed(&model, &pat, tip);
    let ev = model.evaluate(&pat, &s.x, &loads, 1.0, false).unwrap();
    let potential = |st: &State| {
        let e = model.evaluate(&pat, &st.x, &loads, 1.0, false).unwrap();
        e.strain_energy + e.load_potential
    };
    let h = 1e-6;
    let scale = ev.residual.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    for j in 0..pat.num_free() {
        let fd = (potential(&perturbed(&model, &pat, &s, j, h))
            - potential(&perturbed(&model, &pat, &s, j, -h)))
            / (2.0 * h);
        assert!(
            (fd - ev.residual[j]).abs() < 1e-6 * scale,
            "reduced DOF {j}: dPi {fd} vs residual {}",
            ev.residual[j]
        );
    }
}

/// The reduced mass T^T M T at a turned configuration gives the kinetic energy of the slave
/// velocities v_i = v_c + w x r_i computed with the full mass matrix (lumped and consistent).
#[test]
fn reduced_mass_gives_the_kinetic_energy() {
    let (mut model, tip) = two_body_block();
    for kind in [MassKind::Lumped, MassKind::Consistent] {
        model.mass_kind = kind;
        let pat = Pattern::new(&model).unwrap();
        let mut s = deformed(&model, &pat, tip);
        let qdot: Vec<f64> = (0..pat.num_free())
            .map(|j| ((j as f64) * 0.73).cos())
            .collect();
        for (j, &d) in pat.dof_of.iter().enumerate() {
            s.v[d] = qdot[j];
        }
        let f = pat.bodies[0].first;
        s.bodies[tip].velocity = Vector3::new(qdot[f], qdot[f + 1], qdot[f + 2]);
        s.bodies[tip].angular_velocity = Vector3::new(qdot[f + 3], qdot[f + 4], qdot[f + 5]);
        model.place_bodies(&mut s).unwrap();
        let full = 2.0 * DynamicSolver::kinetic_energy(&model, &s);
        let m = model.mass_values_at(&pat, &s.x);
        let mq = ocm_fem::solve::spmv(&pat, &m, &qdot);
        let reduced: f64 = mq.iter().zip(&qdot).map(|(a, b)| a * b).sum();
        assert!(
            (full - reduced).abs() < 1e-12 * full,
            "{kind:?}: v^T M v {full} vs qdot^T M_r qdot {reduced}"
        );
    }
}

/// Undamped average-acceleration Newmark with a rigid end block conserves kinetic + strain energy
/// of a free vibration (lumped and consistent mass).
#[test]
fn newmark_with_a_rigid_block_conserves_energy() {
    let mesh = generate::box_mesh([4, 1, 1], [4.0, 1.0, 1.0]);
    for mass in [MassKind::Lumped, MassKind::Consistent] {
        let mut model = Model::new(&mesh, Material::neo_hookean(1e4, 0.3), 100.0).unwrap();
        model.mass_kind = mass;
        model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
        let b = model
            .add_rigid_body("block", |p| p.x >= 3.0 - 1e-9)
            .unwrap();
        let mut state = State::at_rest(&model);
        // Velocity field v = (0, x/8, x/2): on the block the rigid motion v_c + w x r with
        // w = (0, -1/2, 1/8) about its centre.
        for i in 0..model.num_nodes() {
            let x = model.rest[i].x;
            state.v[3 * i + 2] = 2.0 * x / 4.0;
            state.v[3 * i + 1] = 0.5 * x / 4.0;
        }
        let c = model.rigid_bodies[b].center0;
        state.bodies[b].velocity = Vector3::new(0.0, 0.125 * c.x, 0.5 * c.x);
        state.bodies[b].angular_velocity = Vector3::new(0.0, -0.5, 0.125);
        model.place_bodies(&mut state).unwrap();
        let mut solver = DynamicSolver::new(&model, Integrator::AVERAGE_ACCELERATION).unwrap();
        let pat = Pattern::new(&model).unwrap();
        let energy = |s: &State| {
            DynamicSolver::kinetic_energy(&model, s)
                + model
                    .evaluate(&pat, &s.x, &Loads::default(), 1.0, false)
                    .unwrap()
                    .strain_energy
        };
        let e0 = energy(&state);
        let (mut worst, mut max_strain): (f64, f64) = (0.0, 0.0);
        for _ in 0..60 {
            solver
                .step(&model, &mut state, &Loads::default(), 0.01)
                .unwrap();
            worst = worst.max((energy(&state) - e0).abs() / e0);
            max_strain =
                max_strain.max(energy(&state) - DynamicSolver::kinetic_energy(&model, &state));
        }
        eprintln!("{mass:?}: energy drift {worst:e}, peak strain energy {max_strain:e} of {e0:e}");
        assert!(
            max_strain > 0.3 * e0,
            "the motion must exchange energy ({max_strain} of {e0})"
        );
        assert!(worst < 2e-3, "{mass:?}: energy drift {worst:e}");
    }
}

/// Torque-free motion of an asymmetric rigid block (every node on one body): Newmark on the
/// rotation group against an RK4 integration of Euler's equations in the body frame.
#[test]
fn free_rigid_body_follows_eulers_equations() {
    let mesh = generate::box_mesh([1, 1, 1], [0.3, 0.2, 0.1]);
    let mut model = Model::new(&mesh, Material::neo_hookean(1e5, 0.3), 1000.0).unwrap();
    let b = model.add_rigid_body("all", |_| true).unwrap();
    let masses = model.nodal_masses().to_vec();
    let body = model.rigid_bodies[b].clone();
    let inertia: Matrix3<f64> = body
        .nodes
        .iter()
        .zip(&body.offsets)
        .map(|(&i, r)| (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * masses[i])
        .sum();
    let inv = inertia.try_inverse().unwrap();
    let w0 = Vector3::new(1.0, 4.0, 0.5);
    let t_end = 1.0;
    // Reference: body-frame angular velocity W and orientation q, RK4 with a fine step.
    let deriv = |q: &Quaternion<f64>, w: &Vector3<f64>| {
        let dw = inv * (-w.cross(&(inertia * w)));
        let dq = q * Quaternion::from_imag(*w) * 0.5;
        (dq, dw)
    };
    let (mut q, mut w) = (Quaternion::identity(), w0);
    let n_ref = 20_000;
    let dt = t_end / n_ref as f64;
    for _ in 0..n_ref {
        let (k1q, k1w) = deriv(&q, &w);
        let (k2q, k2w) = deriv(&(q + k1q * (dt / 2.0)), &(w + k1w * (dt / 2.0)));
        let (k3q, k3w) = deriv(&(q + k2q * (dt / 2.0)), &(w + k2w * (dt / 2.0)));
        let (k4q, k4w) = deriv(&(q + k3q * dt), &(w + k3w * dt));
        q += (k1q + k2q * 2.0 + k3q * 2.0 + k4q) * (dt / 6.0);
        w += (k1w + k2w * 2.0 + k3w * 2.0 + k4w) * (dt / 6.0);
    }
    let q_ref = UnitQuaternion::from_quaternion(q);
    let omega_ref = q_ref * w;
    let mut errors = vec![];
    for steps in [50, 100, 200] {
        let mut s = State::at_rest(&model);
        s.bodies[b].angular_velocity = w0;
        let mut solver = DynamicSolver::new(&model, Integrator::AVERAGE_ACCELERATION).unwrap();
        let e0 = {
            model.place_bodies(&mut s).unwrap();
            DynamicSolver::kinetic_energy(&model, &s)
        };
        for _ in 0..steps {
            solver
                .step(&model, &mut s, &Loads::default(), t_end / steps as f64)
                .unwrap();
        }
        let bs = s.bodies[b];
        let err =
            bs.rotation.angle_to(&q_ref) + (bs.angular_velocity - omega_ref).norm() / w0.norm();
        let drift = (DynamicSolver::kinetic_energy(&model, &s) - e0).abs() / e0;
        let l =
            bs.rotation_matrix() * inertia * bs.rotation_matrix().transpose() * bs.angular_velocity;
        let l0 = inertia * w0;
        eprintln!(
            "{steps} steps: orientation+rate error {err:e}, energy drift {drift:e}, momentum drift {:e}",
            (l - l0).norm() / l0.norm()
        );
        assert!(
            (bs.center - body.center0).norm() < 1e-12,
            "no net force: the centre stays"
        );
        errors.push(err);
    }
    let order = (errors[1] / errors[2]).log2();
    assert!(order > 1.8, "second order expected: {errors:?}");
    assert!(errors[2] < 0.02, "{errors:?}");
}

/// Bad rigid-body input is rejected with a clear error.
#[test]
fn rigid_body_errors_are_clear() {
    let mesh = generate::box_mesh([2, 1, 1], [1.0, 0.5, 0.5]);
    let mut model = Model::new(&mesh, Material::neo_hookean(1e3, 0.3), 1000.0).unwrap();
    let e = model.add_rigid_body("none", |p| p.x > 5.0).unwrap_err();
    assert!(e.to_string().contains("no node"), "{e}");
    let e = model
        .add_rigid_body("edge", |p| p.y < 1e-9 && p.z < 1e-9)
        .unwrap_err();
    assert!(e.to_string().contains("line"), "{e}");
    model.add_rigid_body("end", |p| p.x > 0.9).unwrap();
    let e = model.add_rigid_body("overlap", |p| p.x > 0.4).unwrap_err();
    assert!(e.to_string().contains("already belongs"), "{e}");
    model.prescribe(model.num_nodes() - 1, 0, 0.1);
    let e = Pattern::new(&model).unwrap_err();
    assert!(e.to_string().contains("prescribed"), "{e}");
    // A state built before the body was added does not fit.
    let mut other = Model::new(&mesh, Material::neo_hookean(1e3, 0.3), 1000.0).unwrap();
    let s = State::at_rest(&other);
    other.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
    other.add_rigid_body("end", |p| p.x > 0.9).unwrap();
    let mut solver = StaticSolver::new(&other).unwrap();
    let e = solver
        .continue_to(&other, &mut s.clone(), &Loads::default(), &Loads::default())
        .unwrap_err();
    assert!(e.to_string().contains("rigid-body states"), "{e}");
}
