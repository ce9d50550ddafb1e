//! Helpers shared by the integration tests.

use ocm_npe::Surface;

/// An `nx` x `ny` grid of nodes `spacing_m` apart at height `z_m`, node (i, j) at index
/// j * nx + i, triangulated with one diagonal per cell (from (i, j) to (i + 1, j + 1)).
pub fn grid_surface(nx: usize, ny: usize, spacing_m: f64, z_m: f64) -> Surface {
    let id = |i: usize, j: usize| j * nx + i;
    let mut rest_m = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            rest_m.push([i as f64 * spacing_m, j as f64 * spacing_m, z_m]);
        }
    }
    let mut edges = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            if i + 1 < nx {
                edges.push([id(i, j), id(i + 1, j)]);
            }
            if j + 1 < ny {
                edges.push([id(i, j), id(i, j + 1)]);
            }
            if i + 1 < nx && j + 1 < ny {
                edges.push([id(i, j), id(i + 1, j + 1)]);
            }
        }
    }
    Surface { rest_m, edges }
}

/// An untrained engine of width 12 with `layers` GCN layers on `surface`, its configuration
/// adjusted by `set` before the weights are drawn from `seed`.
#[allow(dead_code)] // not every test binary builds engines
pub fn small_engine(
    surface: Surface,
    layers: usize,
    seed: u64,
    set: impl FnOnce(&mut ocm_npe::model::NpeConfig),
) -> ocm_npe::Npe {
    let centre = ocm_npe::data::Prepared::top_center(&surface.rest_m);
    let mut cfg = ocm_npe::model::NpeConfig::new(centre, 0.25e-3);
    cfg.layers = layers;
    cfg.width = 12;
    set(&mut cfg);
    let net = cfg.init(&ocm_learn::cpu(), seed).unwrap();
    ocm_npe::Npe::new(net, cfg, surface).unwrap()
}
