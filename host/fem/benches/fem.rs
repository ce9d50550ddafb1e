//! Criterion benches: bellows static solve, one implicit dynamic step, DIGIT linear static solve.
// criterion_group! generates an undocumented public function.
#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use ocm_fem::bellows::{Bellows, BellowsConfig, Law, RigidMode};
use ocm_fem::material::Material;
use ocm_fem::mesh::vtk;
use ocm_fem::model::{Loads, Model, Pattern, State};
use ocm_fem::solve::dynamics::{DynamicSolver, Integrator};
use ocm_fem::solve::linear::SparseSolver;
use ocm_fem::solve::statics::StaticSolver;
use std::path::PathBuf;

fn data(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIP: {} not found", p.display());
        None
    }
}

fn bellows(c: &mut Criterion) {
    let Some(p) = data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let mut g = c.benchmark_group("bellows");
    g.sample_size(10);
    // Rigid parts as true rigid-body constraints (the default), and the stiff penalty for comparison.
    for (law, rigid, tag) in [
        (Law::NeoHookeanBulk, RigidMode::Constraint, ""),
        (Law::Corotational, RigidMode::Constraint, ""),
        (Law::NeoHookeanBulk, RigidMode::Penalty, "_penalty"),
    ] {
        let b = Bellows::load(
            &p,
            BellowsConfig {
                law,
                rigid,
                ..BellowsConfig::default()
            },
        )
        .expect("bellows mesh");
        let mut solver = StaticSolver::new(&b.model).expect("solver");
        g.bench_function(format!("static_20kpa_{law:?}{tag}"), |bn| {
            bn.iter(|| b.solve_kpa(&mut solver, &[20.0, 0.0, 10.0]).expect("solve"))
        });
    }
    // One implicit Euler step of 10 ms from a pressurised state with Rayleigh damping (App. E).
    for (rigid, tag) in [
        (RigidMode::Constraint, ""),
        (RigidMode::Penalty, "_penalty"),
    ] {
        let b = Bellows::load(
            &p,
            BellowsConfig {
                law: Law::NeoHookeanBulk,
                rigid,
                ..BellowsConfig::default()
            },
        )
        .expect("mesh");
        let mut dyn_solver =
            DynamicSolver::new(&b.model, Integrator::ImplicitEuler).expect("solver");
        let loads = b.loads_kpa(&[20.0, 0.0, 0.0]);
        let mut s = State::at_rest(&b.model);
        dyn_solver
            .step(&b.model, &mut s, &loads, 0.01)
            .expect("first step");
        g.bench_function(format!("implicit_euler_step_10ms{tag}"), |bn| {
            bn.iter_batched(
                || s.clone(),
                |mut st| {
                    dyn_solver
                        .step(&b.model, &mut st, &loads, 0.01)
                        .expect("step")
                },
                criterion::BatchSize::LargeInput,
            )
        });
    }
    g.finish();
}

fn digit(c: &mut Criterion) {
    let Some(p) = data("digit/DIGIT_v8.vtk") else {
        return;
    };
    let mut mesh = vtk::read_path(p).expect("digit mesh");
    mesh.remove_unused_points();
    let mut model = Model::new(&mesh, Material::corotational(1.5e5, 0.45), 1040.0).expect("model");
    // Base clamped (z <= 0.5 mm), gel pressed by a 1 N downward load spread over the top surface.
    model.fix_nodes(|x| x.z <= 0.5e-3);
    let top: Vec<usize> = (0..model.num_nodes())
        .filter(|&i| model.rest[i].z >= 1.99e-3)
        .collect();
    for &i in &top {
        model
            .point_forces
            .push((i, nalgebra::Vector3::new(0.0, 0.0, -1.0 / top.len() as f64)));
    }
    let pat = Pattern::new(&model).expect("pattern");
    let mut lin = SparseSolver::new(pat.num_free(), pat.col_ptr.clone(), pat.row_idx.clone());
    let x0 = model.rest_dofs();
    let mut g = c.benchmark_group("digit");
    g.sample_size(10);
    g.bench_function("linear_static_v8", |bn| {
        bn.iter(|| {
            // Assembly at rest, then K u = f: the linear static solution.
            let ev = model
                .evaluate(&pat, &x0, &Loads::default(), 1.0, true)
                .expect("assemble");
            let mut u: Vec<f64> = pat
                .dof_of
                .iter()
                .map(|&d| ev.f_ext[d] - ev.f_int[d])
                .collect();
            lin.solve(ev.tangent.as_ref().expect("tangent"), &mut u)
                .expect("solve");
            u
        })
    });
    g.finish();
}

criterion_group!(benches, bellows, digit);
criterion_main!(benches);
