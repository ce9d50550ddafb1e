//! The sparse structure of the reduced system: free node DOFs, then six per unclamped rigid body.
//!
//! Element matrices of elements away from rigid bodies scatter through fixed slot maps. An element
//! or pressure triangle touching a body is reduced with T^T K T, where T maps its generalised DOFs
//! (three per free node, six per body) to the node displacements: du_i = dc + dtheta x (x_i - c)
//! for a slave. Elements entirely inside one body carry no strain and are skipped, except for mass.

use super::description::Model;
use super::state::State;
use crate::{FemError, Result};
use nalgebra::Vector3;

pub(crate) const NONE: u32 = u32::MAX;

/// An unclamped rigid body's place in the reduced system.
#[derive(Debug, Clone)]
pub struct BodyDofs {
    /// Index in [`Model::rigid_bodies`].
    pub body: usize,
    /// First of its six reduced indices: translation of the reference point, then rotation vector.
    pub first: usize,
    /// Its nodes.
    pub(crate) nodes: Vec<usize>,
    /// Lumped mass fractions of its nodes (they sum to 1).
    pub(crate) weights: Vec<f64>,
    /// Slots of its 6x6 diagonal block, row-major.
    pub(crate) block: [u32; 36],
    /// Mass-weighted radius of gyration about the reference point, m.
    pub radius_m: f64,
}

/// How an element enters the reduced system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ElemKind {
    /// No node on an unclamped body: the 144-slot map.
    Plain,
    /// Touches an unclamped body: reduced through the coupling with this index.
    Coupled(u32),
    /// All nodes in one body: no strain; the coupling (unclamped body) places its mass.
    Inside(u32),
}

/// Generalised DOFs of one element or triangle touching a rigid body.
#[derive(Debug, Clone)]
pub(crate) struct Coupling {
    /// Per local node: offset of its unit in the generalised vector, and its body (index into
    /// [`Pattern::bodies`]) or NONE for a free node.
    pub local: [(u8, u32); 4],
    /// Number of local nodes.
    pub n: u8,
    /// Reduced index per generalised DOF (NONE where constrained).
    pub gdof: Vec<u32>,
    /// Value slots of the generalised matrix, row-major.
    pub slots: Vec<u32>,
}

/// Sparse structure over the reduced DOFs with element-to-value maps.
#[derive(Debug, Clone)]
pub struct Pattern {
    /// DOF -> reduced index, or usize::MAX when constrained or on a rigid body.
    pub free_of: Vec<usize>,
    /// Reduced index -> DOF for the free node DOFs (the first `dof_of.len()` reduced indices).
    pub dof_of: Vec<usize>,
    /// Unclamped rigid bodies, six reduced indices each after the node DOFs.
    pub bodies: Vec<BodyDofs>,
    /// Rigid bodies clamped because one of their nodes has a fixed DOF (indices into the model's).
    pub clamped_bodies: Vec<usize>,
    /// CSC column pointers (full symmetric pattern).
    pub col_ptr: Vec<usize>,
    /// CSC row indices.
    pub row_idx: Vec<usize>,
    pub(crate) elem_map: Vec<[u32; 144]>,
    pub(crate) elem_kind: Vec<ElemKind>,
    pub(crate) tri_maps: Vec<Vec<[u32; 81]>>,
    /// Per cavity triangle: coupling index or NONE.
    pub(crate) tri_coupled: Vec<Vec<u32>>,
    pub(crate) couplings: Vec<Coupling>,
    pub(crate) diag: Vec<usize>,
    /// Per node: index into `bodies`, or NONE.
    pub(crate) node_body: Vec<u32>,
}

impl Pattern {
    /// Builds the structure for `model`.
    ///
    /// A rigid body with a fixed DOF on any node is clamped whole at rest; a prescribed non-zero
    /// displacement on a body node is an error (a rigid body cannot follow arbitrary nodal values).
    pub fn new(model: &Model) -> Result<Self> {
        let nn = model.num_nodes();
        let ndof = 3 * nn;
        let mut on_body = vec![NONE; nn];
        let mut clamped_bodies = vec![];
        let mut active = vec![];
        for (b, body) in model.rigid_bodies.iter().enumerate() {
            let mut clamped = false;
            for &i in &body.nodes {
                if on_body[i] != NONE {
                    return Err(FemError::Model(format!(
                        "node {i} belongs to rigid bodies '{}' and '{}'",
                        model.rigid_bodies[on_body[i] as usize].name, body.name
                    )));
                }
                on_body[i] = b as u32;
                for d in 0..3 {
                    if model.fixed[3 * i + d] {
                        clamped = true;
                        if model.prescribed[3 * i + d] != 0.0 {
                            return Err(FemError::Model(format!(
                                "rigid body '{}': node {i} has a prescribed non-zero displacement; \
                                 a rigid body can only be clamped whole",
                                body.name
                            )));
                        }
                    }
                }
            }
            if clamped {
                clamped_bodies.push(b);
            } else {
                active.push(b);
            }
        }
        let mut free_of = vec![usize::MAX; ndof];
        let mut dof_of = vec![];
        for d in 0..ndof {
            if !model.fixed[d] && on_body[d / 3] == NONE {
                free_of[d] = dof_of.len();
                dof_of.push(d);
            }
        }
        let nfn = dof_of.len();
        let mut node_body = vec![NONE; nn];
        let lumped = model.nodal_masses();
        let mut bodies: Vec<BodyDofs> = active
            .iter()
            .enumerate()
            .map(|(k, &b)| {
                let body = &model.rigid_bodies[b];
                for &i in &body.nodes {
                    node_body[i] = k as u32;
                }
                let total: f64 = body.nodes.iter().map(|&i| lumped[i]).sum();
                BodyDofs {
                    body: b,
                    first: nfn + 6 * k,
                    nodes: body.nodes.clone(),
                    weights: body.nodes.iter().map(|&i| lumped[i] / total).collect(),
                    block: [NONE; 36],
                    radius_m: body
                        .nodes
                        .iter()
                        .zip(&body.offsets)
                        .map(|(&i, o)| lumped[i] / total * o.norm_squared())
                        .sum::<f64>()
                        .sqrt(),
                }
            })
            .collect();
        let nf = nfn + 6 * bodies.len();
        let body_first: Vec<usize> = bodies.iter().map(|b| b.first).collect();
        let make_coupling = |nodes: &[usize]| -> Coupling {
            let mut c = Coupling {
                local: [(0, NONE); 4],
                n: nodes.len() as u8,
                gdof: vec![],
                slots: vec![],
            };
            for (a, &i) in nodes.iter().enumerate() {
                let b = node_body[i];
                if b != NONE {
                    if let Some(prev) = (0..a).find(|&p| c.local[p].1 == b) {
                        c.local[a] = c.local[prev];
                    } else {
                        c.local[a] = (c.gdof.len() as u8, b);
                        c.gdof
                            .extend((0..6).map(|k| (body_first[b as usize] + k) as u32));
                    }
                } else {
                    c.local[a] = (c.gdof.len() as u8, NONE);
                    c.gdof.extend((0..3).map(|d| {
                        let f = free_of[3 * i + d];
                        if f == usize::MAX { NONE } else { f as u32 }
                    }));
                }
            }
            c
        };
        let mut couplings = vec![];
        let mut elem_kind = Vec::with_capacity(model.elements.len());
        for g in &model.elements {
            let b0 = on_body[g.nodes[0]];
            let inside = b0 != NONE && g.nodes.iter().all(|&i| on_body[i] == b0);
            let touches = g.nodes.iter().any(|&i| node_body[i] != NONE);
            elem_kind.push(if inside {
                if touches {
                    couplings.push(make_coupling(&g.nodes));
                    ElemKind::Inside(couplings.len() as u32 - 1)
                } else {
                    ElemKind::Inside(NONE)
                }
            } else if touches {
                couplings.push(make_coupling(&g.nodes));
                ElemKind::Coupled(couplings.len() as u32 - 1)
            } else {
                ElemKind::Plain
            });
        }
        let tri_coupled: Vec<Vec<u32>> = model
            .cavities
            .iter()
            .map(|c| {
                c.triangles
                    .iter()
                    .map(|t| {
                        if t.iter().any(|&i| node_body[i] != NONE) {
                            couplings.push(make_coupling(t));
                            couplings.len() as u32 - 1
                        } else {
                            NONE
                        }
                    })
                    .collect()
            })
            .collect();
        let node_gdofs = |nodes: &[usize]| -> Vec<usize> {
            nodes
                .iter()
                .flat_map(|&i| (0..3).map(move |d| 3 * i + d))
                .map(|d| free_of[d])
                .filter(|&f| f != usize::MAX)
                .collect()
        };
        let mut cols: Vec<Vec<usize>> = vec![vec![]; nf];
        let mut add_clique = |g: &[usize]| {
            for &c in g {
                cols[c].extend_from_slice(g);
            }
        };
        for (g, kind) in model.elements.iter().zip(&elem_kind) {
            match *kind {
                ElemKind::Plain => add_clique(&node_gdofs(&g.nodes)),
                ElemKind::Coupled(_) | ElemKind::Inside(_) => {}
            }
        }
        for (c, tc) in model.cavities.iter().zip(&tri_coupled) {
            for (t, &k) in c.triangles.iter().zip(tc) {
                if k == NONE {
                    add_clique(&node_gdofs(t));
                }
            }
        }
        for c in &couplings {
            let g: Vec<usize> = c
                .gdof
                .iter()
                .filter(|&&f| f != NONE)
                .map(|&f| f as usize)
                .collect();
            add_clique(&g);
        }
        for b in &bodies {
            add_clique(&(b.first..b.first + 6).collect::<Vec<_>>());
        }
        let mut col_ptr = vec![0usize];
        let mut row_idx = vec![];
        for (j, col) in cols.iter_mut().enumerate() {
            col.push(j);
            col.sort_unstable();
            col.dedup();
            row_idx.extend_from_slice(col);
            col_ptr.push(row_idx.len());
        }
        drop(cols);
        if row_idx.len() >= NONE as usize {
            return Err(FemError::Model(
                "matrix too large for 32-bit value maps".into(),
            ));
        }
        let find = |r: usize, c: usize| -> u32 {
            if r == usize::MAX || c == usize::MAX {
                return NONE;
            }
            let s = &row_idx[col_ptr[c]..col_ptr[c + 1]];
            match s.binary_search(&r) {
                Ok(k) => (col_ptr[c] + k) as u32,
                Err(_) => NONE,
            }
        };
        let map_nodes = |nodes: &[usize], out: &mut [u32]| {
            let m = nodes.len() * 3;
            for (a, &na) in nodes.iter().enumerate() {
                for (b, &nb) in nodes.iter().enumerate() {
                    for i in 0..3 {
                        for k in 0..3 {
                            out[(3 * a + i) * m + 3 * b + k] =
                                find(free_of[3 * na + i], free_of[3 * nb + k]);
                        }
                    }
                }
            }
        };
        let elem_map = model
            .elements
            .iter()
            .zip(&elem_kind)
            .map(|(g, kind)| {
                let mut m = [NONE; 144];
                if *kind == ElemKind::Plain {
                    map_nodes(&g.nodes, &mut m);
                }
                m
            })
            .collect();
        let tri_maps = model
            .cavities
            .iter()
            .zip(&tri_coupled)
            .map(|(c, tc)| {
                c.triangles
                    .iter()
                    .zip(tc)
                    .map(|(t, &k)| {
                        let mut m = [NONE; 81];
                        if k == NONE {
                            map_nodes(t, &mut m);
                        }
                        m
                    })
                    .collect()
            })
            .collect();
        let unmapped = |f: u32| {
            if f == NONE { usize::MAX } else { f as usize }
        };
        for c in &mut couplings {
            let m = c.gdof.len();
            c.slots = (0..m * m)
                .map(|pq| find(unmapped(c.gdof[pq / m]), unmapped(c.gdof[pq % m])))
                .collect();
        }
        for b in &mut bodies {
            for p in 0..36 {
                b.block[p] = find(b.first + p / 6, b.first + p % 6);
            }
        }
        let diag = (0..nf).map(|j| find(j, j) as usize).collect();
        Ok(Pattern {
            free_of,
            dof_of,
            bodies,
            clamped_bodies,
            col_ptr,
            row_idx,
            elem_map,
            elem_kind,
            tri_maps,
            tri_coupled,
            couplings,
            diag,
            node_body,
        })
    }

    /// Number of reduced DOFs (free node DOFs plus six per unclamped body).
    pub fn num_free(&self) -> usize {
        self.dof_of.len() + 6 * self.bodies.len()
    }

    /// Number of stored matrix entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// Reference points of the unclamped bodies at positions `x`: the slaves' mass centres.
    pub fn body_centers(&self, x: &[f64]) -> Vec<Vector3<f64>> {
        self.bodies
            .iter()
            .map(|b| {
                b.nodes
                    .iter()
                    .zip(&b.weights)
                    .map(|(&i, w)| Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]) * *w)
                    .sum()
            })
            .collect()
    }

    /// T^T f: a full nodal vector (forces) on the reduced DOFs at positions `x`; a body gets the
    /// resultant force and its moment about the reference point.
    pub fn reduce(&self, x: &[f64], full: &[f64]) -> Vec<f64> {
        let mut out: Vec<f64> = self.dof_of.iter().map(|&d| full[d]).collect();
        for (b, c) in self.bodies.iter().zip(self.body_centers(x)) {
            let (mut f, mut m) = (Vector3::zeros(), Vector3::zeros());
            for &i in &b.nodes {
                let fi = Vector3::new(full[3 * i], full[3 * i + 1], full[3 * i + 2]);
                let r = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]) - c;
                f += fi;
                m += r.cross(&fi);
            }
            out.extend(f.iter().chain(m.iter()));
        }
        out
    }

    /// Norm of a reduced residual with each body moment divided by the body's radius of gyration,
    /// so that all entries are forces, N.
    pub fn residual_norm(&self, r: &[f64]) -> f64 {
        let mut sum: f64 = r[..self.dof_of.len()].iter().map(|v| v * v).sum();
        for b in &self.bodies {
            let f = &r[b.first..b.first + 6];
            let s = 1.0 / b.radius_m.max(f64::MIN_POSITIVE);
            sum += f[..3].iter().map(|v| v * v).sum::<f64>()
                + f[3..].iter().map(|v| v * v * s * s).sum::<f64>();
        }
        sum.sqrt()
    }

    /// Reduced velocities: free node velocities, then (v_c, omega) per body.
    pub fn reduced_velocity(&self, state: &State) -> Vec<f64> {
        let mut out: Vec<f64> = self.dof_of.iter().map(|&d| state.v[d]).collect();
        for b in &self.bodies {
            let s = &state.bodies[b.body];
            out.extend(s.velocity.iter().chain(s.angular_velocity.iter()));
        }
        out
    }

    /// Adds T^T K T of a local matrix `k` (3n x 3n, row-major, n the coupling's node count) to
    /// `vals`; `r[a]` is x_a - c of local node a when it lies on a body.
    pub(crate) fn add_coupled(
        &self,
        c: &Coupling,
        k: &[f64],
        r: &[Vector3<f64>; 4],
        vals: &mut [f64],
    ) {
        let dim = 3 * c.n as usize;
        let m = c.gdof.len();
        // Rows of T: at most three entries (1 for the translation, two from -[r]x).
        let mut trow = [[(0usize, 0.0f64); 3]; 12];
        let mut tlen = [0usize; 12];
        for a in 0..c.n as usize {
            let (o, b) = (c.local[a].0 as usize, c.local[a].1);
            for i in 0..3 {
                let row = 3 * a + i;
                trow[row][0] = (o + i, 1.0);
                tlen[row] = 1;
                if b != NONE {
                    // -[r]x row i: (0, rz, -ry), (-rz, 0, rx), (ry, -rx, 0).
                    let ra = r[a];
                    let (p, q, vp, vq) = match i {
                        0 => (1, 2, ra.z, -ra.y),
                        1 => (0, 2, -ra.z, ra.x),
                        _ => (0, 1, ra.y, -ra.x),
                    };
                    trow[row][1] = (o + 3 + p, vp);
                    trow[row][2] = (o + 3 + q, vq);
                    tlen[row] = 3;
                }
            }
        }
        let mut kt = [0.0f64; 12 * 24];
        for row in 0..dim {
            for s in 0..dim {
                let ks = k[row * dim + s];
                if ks == 0.0 {
                    continue;
                }
                for &(q, v) in &trow[s][..tlen[s]] {
                    kt[row * m + q] += ks * v;
                }
            }
        }
        let mut red = [0.0f64; 24 * 24];
        for row in 0..dim {
            for &(p, v) in &trow[row][..tlen[row]] {
                for q in 0..m {
                    red[p * m + q] += v * kt[row * m + q];
                }
            }
        }
        for (slot, v) in c.slots.iter().zip(&red[..m * m]) {
            if *slot != NONE {
                vals[*slot as usize] += v;
            }
        }
    }

    /// x_a - c for the local nodes of a coupling (zero for free nodes).
    pub(crate) fn arms(
        &self,
        c: &Coupling,
        nodes: &[usize],
        pos: &[Vector3<f64>],
        centers: &[Vector3<f64>],
    ) -> [Vector3<f64>; 4] {
        let mut r = [Vector3::zeros(); 4];
        for (a, &i) in nodes.iter().enumerate() {
            let b = c.local[a].1;
            if b != NONE {
                r[a] = pos[i] - centers[b as usize];
            }
        }
        r
    }
}
