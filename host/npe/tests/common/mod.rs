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
