//! A small clamped block with a pressurised face: a real FE model that solves in milliseconds.

// Each test file compiles this module on its own and uses a part of it.
#![allow(dead_code)]

use faer::Mat;
use nalgebra::DMatrix;
use ocm_fem::material::Material;
use ocm_fem::mesh::generate;
use ocm_fem::model::Model;
use ocm_fem::model::{Loads, State};
use ocm_fem::solve::dynamics::{DynamicSolver, Integrator};
use ocm_mor::drive::Input;
use ocm_mor::full::tip_point_forces;
use ocm_mor::pod::{PodOptions, Truncation, pod};

/// The block model and its free-end nodes.
pub struct Block {
    /// The model.
    pub model: Model,
    /// Nodes of the free end (x = L): the "tip".
    pub tip: Vec<usize>,
}

/// A 0.1 m x 20 mm x 20 mm Neo-Hookean block clamped at x = 0, its top face pressurised.
pub fn block(alpha: f64, beta: f64) -> Block {
    let (l, h) = (0.1, 0.02);
    let mesh = generate::box_mesh([5, 2, 2], [l, h, h]);
    let mut model = Model::new(&mesh, Material::neo_hookean_bulk(2e5, 0.4), 1040.0).unwrap();
    model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
    model.rayleigh_alpha = alpha;
    model.rayleigh_beta = beta;
    // The top face (z = h) as a pressure surface: the tet faces whose nodes all lie on it.
    let on_top = |i: usize| (model.rest[i].z - h).abs() < 1e-12;
    let mut tris = vec![];
    for g in &model.elements {
        for skip in 0..4 {
            let f: Vec<usize> = (0..4).filter(|&k| k != skip).map(|k| g.nodes[k]).collect();
            if f.iter().all(|&i| on_top(i)) {
                tris.push([f[0], f[1], f[2]]);
            }
        }
    }
    assert!(!tris.is_empty());
    model.add_pressure_surface("top", tris).unwrap();
    let tip = (0..model.num_nodes())
        .filter(|&i| (model.rest[i].x - l).abs() < 1e-12)
        .collect();
    Block { model, tip }
}

/// Identity columns on the free DOFs: the "full" basis.
pub fn full_basis(model: &Model) -> DMatrix<f64> {
    let free: Vec<usize> = (0..model.fixed.len())
        .filter(|&d| !model.fixed[d])
        .collect();
    let mut v = DMatrix::zeros(model.fixed.len(), free.len());
    for (k, &d) in free.iter().enumerate() {
        v[(d, k)] = 1.0;
    }
    v
}

/// Inputs with the pressure on the one surface.
pub fn input(p_kpa: f64, f: [f64; 3]) -> Input {
    Input {
        pressure_kpa: [p_kpa, 0.0, 0.0],
        tip_force_n: f,
    }
}

/// Full backward-Euler steps of the block under `inputs` from rest, `h` seconds each, solved to
/// 1e-12; the displacements after each step.
pub fn full_run(b: &Block, h: f64, inputs: &[Input]) -> Vec<Vec<f64>> {
    let mut model = b.model.clone();
    let mut solver = DynamicSolver::new(&model, Integrator::ImplicitEuler).unwrap();
    solver.options.rtol = 1e-12;
    let mut s = State::at_rest(&model);
    let rest = model.rest_dofs();
    inputs
        .iter()
        .map(|inp| {
            model.point_forces = tip_point_forces(&b.tip, inp.tip_force_n);
            let loads = Loads {
                pressures_pa: vec![inp.pressure_kpa[0] * 1e3],
            };
            solver.step(&model, &mut s, &loads, h).unwrap();
            s.x.iter().zip(&rest).map(|(x, r)| x - r).collect()
        })
        .collect()
}

/// The rank-`r` POD basis of displacement snapshots (one per entry).
pub fn pod_basis(snaps: &[Vec<f64>], r: usize) -> DMatrix<f64> {
    let a = Mat::<f64>::from_fn(snaps[0].len(), snaps.len(), |i, j| snaps[j][i]);
    let p = pod(
        a.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(r),
            ..PodOptions::default()
        },
    )
    .unwrap();
    DMatrix::from_fn(p.modes.nrows(), r, |i, j| p.modes[(i, j)])
}
