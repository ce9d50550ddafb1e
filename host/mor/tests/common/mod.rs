//! A small clamped block with a pressurised face: a real FE model that solves in milliseconds.

use nalgebra::DMatrix;
use ocm_fem::material::Material;
use ocm_fem::mesh::generate;
use ocm_fem::model::Model;
use ocm_mor::drive::Input;

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
