//! The N-layer bar-and-hinge stack: node numbering, elements, energy and its
//! exact derivatives (forward-mode AD per element), and the uniform
//! kinematic configuration used as the reference for comparisons.
//!
//! Each layer keeps its own 40 bars, 32 hinges and 24 lateral facets, so the
//! ring bars shared by two layers are counted once per layer, as in the
//! uniform model; the stack energy at the uniform configuration is then
//! exactly `N` times the layer energy.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};
use num_dual::{Dual2SVec64, hessian};

use crate::energy::EnergyParts;
use crate::geometry::{
    Hinge, LayerGeometry, NODES, SIDES, cross, dihedral, dot, norm, ring1, ring3, sinc, sub,
    versin_over,
};
use crate::model::OcmModel;
use crate::scalar::Scalar;

/// Unit vector towards middle-ring vertex 0: the direction the lead's
/// kinematic map bends to.
pub const BEND_DIRECTION: [f64; 3] = [
    core::f64::consts::FRAC_1_SQRT_2,
    core::f64::consts::FRAC_1_SQRT_2,
    0.0,
];
/// Bending axis `t = z x b`: a positive rotation about it tilts the top
/// towards [`BEND_DIRECTION`].
pub const BEND_AXIS: [f64; 3] = [
    -core::f64::consts::FRAC_1_SQRT_2,
    core::f64::consts::FRAC_1_SQRT_2,
    0.0,
];

/// New nodes per layer: middle ring, mid nodes and top ring.
const NODES_PER_LAYER: usize = 3 * SIDES;

/// A bar of the stack.
#[derive(Debug, Clone, Copy)]
struct Bar {
    nodes: [usize; 2],
    rest_m: f64,
}

/// A hinge of the stack, nodes ordered as in [`Hinge`] (`i, j, k, l`).
#[derive(Debug, Clone, Copy)]
struct StackHinge {
    nodes: [usize; 4],
    rest_rad: f64,
}

/// Where a node's coordinates live in the vector of unknowns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Dof {
    /// Clamped base node.
    Fixed,
    /// Node on the rigid plate; its coordinates follow the plate.
    Plate,
    /// Free node with its first unknown's index.
    Free(usize),
}

/// Energy, gradients and Hessian of the stack at one configuration.
#[derive(Debug, Clone)]
pub struct Assembly {
    /// `k_b Pi_bar + k_h Pi_hinge - P (V - V0)`, joules.
    pub energy_j: f64,
    /// Energy gradient per node (all nodes, fixed ones included), newtons.
    pub node_gradient_n: Vec<[f64; 3]>,
    /// Gradient over the unknowns (free nodes, then the plate translation
    /// when `plate_free`), newtons.
    pub gradient_n: DVector<f64>,
    /// Hessian over the same unknowns, newtons per metre.
    pub hessian_n_per_m: DMatrix<f64>,
}

/// Neutral-axis length of a stack configuration, two ways.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NeutralAxis {
    /// Length of the polyline through the ring centroids, base to plate, metres.
    pub polyline_m: f64,
    /// Sum over layers of the circular arc through consecutive ring
    /// centroids whose tangent turns by the angle between the ring normals,
    /// metres; equals `s = R phi` exactly for the uniform kinematic map.
    pub arc_m: f64,
    /// Shortest per-layer arc, metres (equal to the longest when the layers
    /// deform identically).
    pub layer_arc_min_m: f64,
    /// Longest per-layer arc, metres.
    pub layer_arc_max_m: f64,
    /// Smallest per-layer bending angle (between consecutive ring normals), radians.
    pub layer_turn_min_rad: f64,
    /// Largest per-layer bending angle, radians.
    pub layer_turn_max_rad: f64,
}

/// The N-layer bar-and-hinge structure of one OCM (an immutable description).
#[derive(Debug, Clone)]
pub struct Stack {
    layers: usize,
    geometry: LayerGeometry,
    bar_stiffness_n_per_m: f64,
    hinge_stiffness_n_per_m: f64,
    rest_length_m: f64,
    layer_nodes: Vec<[usize; NODES]>,
    bars: Vec<Bar>,
    hinges: Vec<StackHinge>,
    facets: Vec<[usize; 3]>,
    bottom_cap: [usize; SIDES],
    top_cap: [usize; SIDES],
    rest_positions: Vec<[f64; 3]>,
    rest_volume_m3: f64,
    plate_offsets_m: [[f64; 3]; SIDES],
}

impl Stack {
    /// Builds the stack of `model.params().layers` layers at the rest
    /// configuration, each layer a copy of the model's reference layer.
    pub fn new(model: &OcmModel) -> Self {
        let layer = model.layer();
        let params = model.params();
        let layers = params.layers as usize;
        let geometry = layer.geometry;
        let h0 = geometry.rest_height_m;
        let node_count = SIDES + NODES_PER_LAYER * layers;

        let layer_nodes: Vec<[usize; NODES]> = (0..layers)
            .map(|i| core::array::from_fn(|n| global_node(i, n)))
            .collect();

        let local = geometry.positions::<f64>(h0, 0.0);
        let mut rest_positions = vec![[0.0; 3]; node_count];
        for (i, map) in layer_nodes.iter().enumerate() {
            for (n, &g) in map.iter().enumerate() {
                let p = local[n];
                rest_positions[g] = [p[0], p[1], p[2] + i as f64 * h0];
            }
        }

        let topo = &layer.topology;
        let rest = &layer.rest;
        let mut bars = Vec::with_capacity(layers * topo.bars.len());
        let mut hinges = Vec::with_capacity(layers * topo.hinges.len());
        let mut facets = Vec::with_capacity(layers * topo.facets.len());
        for map in &layer_nodes {
            for (&[p, q], &l0) in topo.bars.iter().zip(&rest.bar_length_m) {
                bars.push(Bar {
                    nodes: [map[p], map[q]],
                    rest_m: l0,
                });
            }
            for (h, &a0) in topo.hinges.iter().zip(&rest.dihedral_rad) {
                hinges.push(StackHinge {
                    nodes: [map[h.i], map[h.j], map[h.k], map[h.l]],
                    rest_rad: a0,
                });
            }
            for f in &topo.facets {
                facets.push(f.map(|n| map[n]));
            }
        }
        let bottom_cap = core::array::from_fn(|k| layer_nodes[0][ring1(k)]);
        let top_cap = core::array::from_fn(|k| layer_nodes[layers - 1][ring3(k)]);
        let top = [0.0, 0.0, layers as f64 * h0];
        let plate_offsets_m = core::array::from_fn(|k| sub(rest_positions[top_cap[k]], top));

        Self {
            layers,
            geometry,
            bar_stiffness_n_per_m: params.bar_stiffness_n_per_m,
            hinge_stiffness_n_per_m: params.hinge_stiffness_n_per_m,
            rest_length_m: params.rest_length_m,
            layer_nodes,
            bars,
            hinges,
            facets,
            bottom_cap,
            top_cap,
            rest_positions,
            rest_volume_m3: layers as f64 * rest.volume_m3,
            plate_offsets_m,
        }
    }

    /// Number of layers `N`.
    pub fn layers(&self) -> usize {
        self.layers
    }

    /// Number of nodes, `4 + 12 N`.
    pub fn node_count(&self) -> usize {
        self.rest_positions.len()
    }

    /// Unloaded length `l0` of the stack, metres.
    pub fn rest_length_m(&self) -> f64 {
        self.rest_length_m
    }

    /// Global node index of local node `local` (numbering of
    /// [`crate::geometry`]) of layer `layer`; `None` when out of range.
    pub fn node(&self, layer: usize, local: usize) -> Option<usize> {
        self.layer_nodes.get(layer)?.get(local).copied()
    }

    /// The clamped base ring (layer 0's bottom ring).
    pub fn base_nodes(&self) -> [usize; SIDES] {
        self.bottom_cap
    }

    /// The ring bonded to the rigid top plate (the last layer's top ring).
    pub fn plate_nodes(&self) -> [usize; SIDES] {
        self.top_cap
    }

    /// Offsets `d_k` of the plate nodes from the plate centre in the
    /// unrotated plate, metres.
    pub fn plate_offsets_m(&self) -> [[f64; 3]; SIDES] {
        self.plate_offsets_m
    }

    /// Plate centre of the unloaded stack, metres.
    pub fn rest_plate_centre_m(&self) -> [f64; 3] {
        [0.0, 0.0, self.layers as f64 * self.geometry.rest_height_m]
    }

    /// Nodal positions of the unloaded stack, metres.
    pub fn rest_positions(&self) -> &[[f64; 3]] {
        &self.rest_positions
    }

    /// Total rest volume `N V0`, cubic metres.
    pub fn rest_volume_m3(&self) -> f64 {
        self.rest_volume_m3
    }

    /// Nodal positions of the uniform model's configuration: every layer at
    /// height `l0 (1 + strain) / N` bent by `bend_angle_rad / N`, each layer
    /// placed in the top-ring frame of the one below it.
    pub fn uniform_positions(&self, strain: f64, bend_angle_rad: f64) -> Vec<[f64; 3]> {
        let n = self.layers as f64;
        let h = self.rest_length_m * (1.0 + strain) / n;
        let beta = bend_angle_rad / n;
        let local = self.geometry.positions::<f64>(h, beta);
        let step = rotation(BEND_AXIS, beta);
        let lead = {
            let (v, s) = (h * versin_over(beta), h * sinc(beta));
            [BEND_DIRECTION[0] * v, BEND_DIRECTION[1] * v, s]
        };
        let mut out = self.rest_positions.clone();
        let mut frame_rot = identity();
        let mut origin = [0.0; 3];
        for map in &self.layer_nodes {
            for (n, &g) in map.iter().enumerate() {
                if n >= SIDES {
                    out[g] = add(origin, mat_vec(&frame_rot, local[n]));
                }
            }
            origin = add(origin, mat_vec(&frame_rot, lead));
            frame_rot = mat_mul(&frame_rot, &step);
        }
        out
    }

    /// The plate centre and rotation of the uniform configuration, metres.
    pub fn uniform_plate_centre_m(&self, strain: f64, bend_angle_rad: f64) -> [f64; 3] {
        let s = self.rest_length_m * (1.0 + strain);
        let (v, z) = (s * versin_over(bend_angle_rad), s * sinc(bend_angle_rad));
        [BEND_DIRECTION[0] * v, BEND_DIRECTION[1] * v, z]
    }

    /// Energy parts of arbitrary nodal positions (the same three parts as
    /// [`crate::energy::parts_at`], summed over layers; `volume` is the total
    /// `V - N V0`).
    pub fn energy_parts(&self, x: &[[f64; 3]]) -> EnergyParts<f64> {
        let mut bar = 0.0;
        for b in &self.bars {
            bar += bar_energy(&b.nodes.map(|n| x[n]), b.rest_m);
        }
        let mut hinge = 0.0;
        for h in &self.hinges {
            hinge += hinge_energy(&h.nodes.map(|n| x[n]), h.rest_rad);
        }
        let mut volume = -self.rest_volume_m3;
        for f in &self.facets {
            volume += facet_volume(&f.map(|n| x[n]));
        }
        volume += cap_volume(&self.bottom_cap.map(|n| x[n]), false);
        volume += cap_volume(&self.top_cap.map(|n| x[n]), true);
        EnergyParts { bar, hinge, volume }
    }

    /// Potential `k_b Pi_bar + k_h Pi_hinge - P (V - V0)`, joules (no plate load).
    pub fn energy_j(&self, x: &[[f64; 3]], pressure_pa: f64) -> f64 {
        let p = self.energy_parts(x);
        self.bar_stiffness_n_per_m * p.bar + self.hinge_stiffness_n_per_m * p.hinge
            - pressure_pa * p.volume
    }

    /// Energy gradient with respect to every node, newtons.
    pub fn energy_gradient_n(&self, x: &[[f64; 3]], pressure_pa: f64) -> Vec<[f64; 3]> {
        self.assemble(x, pressure_pa, false).node_gradient_n
    }

    /// Where node `n`'s coordinates live among the unknowns.
    pub(crate) fn dof(&self, n: usize) -> Dof {
        let count = self.node_count();
        if n < SIDES {
            Dof::Fixed
        } else if n >= count - SIDES {
            Dof::Plate
        } else {
            Dof::Free(3 * (n - SIDES))
        }
    }

    /// Number of free-node unknowns (without the plate translation).
    pub fn free_node_dofs(&self) -> usize {
        3 * (self.node_count() - 2 * SIDES)
    }

    /// Energy, node gradients and the gradient and Hessian over the unknowns
    /// at positions `x`. The unknowns are the coordinates of the free nodes
    /// `4 .. node_count - 4` in node order (unknown `i` is coordinate `i % 3`
    /// of node `4 + i / 3`), then, with `plate_free`, the plate translation
    /// (the plate rotation held fixed).
    pub fn assemble(&self, x: &[[f64; 3]], pressure_pa: f64, plate_free: bool) -> Assembly {
        let free = self.free_node_dofs();
        let dim = free + if plate_free { 3 } else { 0 };
        let mut acc = Accumulator {
            stack: self,
            plate_base: plate_free.then_some(free),
            energy: 0.0,
            node_grad: vec![[0.0; 3]; self.node_count()],
            grad: DVector::zeros(dim),
            hess: DMatrix::zeros(dim, dim),
        };
        let kb = self.bar_stiffness_n_per_m;
        let kh = self.hinge_stiffness_n_per_m;
        for b in &self.bars {
            let l0 = b.rest_m;
            acc.add::<2, 6>(b.nodes, x, kb, |y| bar_energy(y, l0));
        }
        for h in &self.hinges {
            let a0 = h.rest_rad;
            acc.add::<4, 12>(h.nodes, x, kh, |y| hinge_energy(y, a0));
        }
        let w = -pressure_pa;
        if w != 0.0 {
            for f in &self.facets {
                acc.add::<3, 9>(*f, x, w, facet_volume);
            }
            acc.add::<4, 12>(self.bottom_cap, x, w, |y| cap_volume(y, false));
            acc.add::<4, 12>(self.top_cap, x, w, |y| cap_volume(y, true));
            acc.energy += pressure_pa * self.rest_volume_m3;
        }
        let energy_j = acc.energy;
        Assembly {
            energy_j,
            node_gradient_n: acc.node_grad,
            gradient_n: acc.grad,
            hessian_n_per_m: acc.hess,
        }
    }

    /// Neutral-axis length through the ring centroids (base ring, then each
    /// layer's top ring).
    pub fn neutral_axis(&self, x: &[[f64; 3]]) -> NeutralAxis {
        let ring_frame = |nodes: [usize; SIDES]| {
            let mut c = [0.0; 3];
            for &n in &nodes {
                for d in 0..3 {
                    c[d] += x[n][d] / SIDES as f64;
                }
            }
            let normal = cross(sub(x[nodes[2]], x[nodes[0]]), sub(x[nodes[3]], x[nodes[1]]));
            (c, scale(normal, 1.0 / norm(normal)))
        };
        let mut frames = vec![ring_frame(self.bottom_cap)];
        for map in &self.layer_nodes {
            frames.push(ring_frame(core::array::from_fn(|k| map[ring3(k)])));
        }
        let mut out = NeutralAxis {
            polyline_m: 0.0,
            arc_m: 0.0,
            layer_arc_min_m: f64::INFINITY,
            layer_arc_max_m: 0.0,
            layer_turn_min_rad: f64::INFINITY,
            layer_turn_max_rad: 0.0,
        };
        for w in frames.windows(2) {
            let ((c0, n0), (c1, n1)) = (w[0], w[1]);
            let chord = norm(sub(c1, c0));
            let turn = norm(cross(n0, n1)).atan2(dot(n0, n1));
            let arc = chord / sinc(0.5 * turn);
            out.polyline_m += chord;
            out.arc_m += arc;
            out.layer_arc_min_m = out.layer_arc_min_m.min(arc);
            out.layer_arc_max_m = out.layer_arc_max_m.max(arc);
            out.layer_turn_min_rad = out.layer_turn_min_rad.min(turn);
            out.layer_turn_max_rad = out.layer_turn_max_rad.max(turn);
        }
        out
    }
}

/// Global index of local node `n` of layer `i`: layer `i`'s bottom ring is
/// layer `i-1`'s top ring.
fn global_node(i: usize, n: usize) -> usize {
    if n < SIDES {
        if i == 0 {
            n
        } else {
            global_node(i - 1, ring3(n))
        }
    } else {
        // Local order: ring2 4..8, ring3 8..12, mid 12..16; in a layer's block
        // of twelve new nodes the top ring comes last so that the plate nodes
        // are the last four of the stack.
        let offset = match n {
            n if n < 2 * SIDES => n - SIDES,
            n if n < 3 * SIDES => n,
            n => n - 2 * SIDES,
        };
        SIDES + NODES_PER_LAYER * i + offset
    }
}

/// Sums element energies and scatters their AD gradients and Hessians.
struct Accumulator<'a> {
    stack: &'a Stack,
    plate_base: Option<usize>,
    energy: f64,
    node_grad: Vec<[f64; 3]>,
    grad: DVector<f64>,
    hess: DMatrix<f64>,
}

impl Accumulator<'_> {
    fn add<const M: usize, const K: usize>(
        &mut self,
        nodes: [usize; M],
        x: &[[f64; 3]],
        weight: f64,
        f: impl Fn(&[[Dual2SVec64<K>; 3]; M]) -> Dual2SVec64<K>,
    ) {
        debug_assert_eq!(K, 3 * M);
        let flat = SVector::<f64, K>::from_fn(|i, _| x[nodes[i / 3]][i % 3]);
        let (e, g, h): (f64, SVector<f64, K>, SMatrix<f64, K, K>) = hessian(
            |v| {
                let y: [[Dual2SVec64<K>; 3]; M] =
                    core::array::from_fn(|a| core::array::from_fn(|d| v[3 * a + d]));
                f(&y)
            },
            &flat,
        );
        self.energy += weight * e;
        let index: [Option<usize>; M] = nodes.map(|n| match self.stack.dof(n) {
            Dof::Fixed => None,
            Dof::Plate => self.plate_base,
            Dof::Free(i) => Some(i),
        });
        for a in 0..M {
            for d in 0..3 {
                self.node_grad[nodes[a]][d] += weight * g[3 * a + d];
            }
            let Some(ia) = index[a] else { continue };
            for d in 0..3 {
                self.grad[ia + d] += weight * g[3 * a + d];
            }
            for b in 0..M {
                let Some(ib) = index[b] else { continue };
                for d in 0..3 {
                    for e in 0..3 {
                        self.hess[(ia + d, ib + e)] += weight * h[(3 * a + d, 3 * b + e)];
                    }
                }
            }
        }
    }
}

/// `1/2 (L - L0)^2` of a bar.
fn bar_energy<D: Scalar>(x: &[[D; 3]; 2], rest_m: f64) -> D {
    let dl = norm(sub(x[1], x[0])) - rest_m;
    dl * dl * 0.5
}

/// `1/2 L (theta - theta0)^2` of a hinge, the angle change wrapped to
/// `(-pi, pi]` so that a crease passing through the flat-folded state does
/// not jump by `2 pi`.
fn hinge_energy<D: Scalar>(x: &[[D; 3]; 4], rest_rad: f64) -> D {
    let hinge = Hinge {
        i: 0,
        j: 1,
        k: 2,
        l: 3,
    };
    let len = norm(sub(x[1], x[0]));
    let mut da = dihedral(x, &hinge) - rest_rad;
    let tau = 2.0 * core::f64::consts::PI;
    if da.value() > core::f64::consts::PI {
        da -= tau;
    } else if da.value() <= -core::f64::consts::PI {
        da += tau;
    }
    len * da * da * 0.5
}

/// Signed volume of the tetrahedron of a lateral facet and the origin.
fn facet_volume<D: Scalar>(x: &[[D; 3]; 3]) -> D {
    dot(x[0], cross(x[1], x[2])) / 6.0
}

/// Signed volume of a planar-fan cap about its ring centroid, oriented as
/// in [`crate::geometry::enclosed_volume`] (`top`: outward along +z of the
/// ring's own frame).
fn cap_volume<D: Scalar>(x: &[[D; 3]; SIDES], top: bool) -> D {
    let mut c = [D::from(0.0); 3];
    for p in x {
        for d in 0..3 {
            c[d] += p[d] / SIDES as f64;
        }
    }
    let mut v = D::from(0.0);
    for k in 0..SIDES {
        let (a, b) = (x[k], x[(k + 1) % SIDES]);
        v += if top {
            dot(c, cross(a, b))
        } else {
            dot(c, cross(b, a))
        } / 6.0;
    }
    v
}

/// A 3x3 rotation matrix (row-major).
pub(crate) type Mat3 = [[f64; 3]; 3];

/// Rotation by `angle` about the unit vector `axis` (Rodrigues).
pub(crate) fn rotation(axis: [f64; 3], angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let v = 1.0 - c;
    [
        [c + x * x * v, x * y * v - z * s, x * z * v + y * s],
        [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
        [z * x * v - y * s, z * y * v + x * s, c + z * z * v],
    ]
}

fn identity() -> Mat3 {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

pub(crate) fn mat_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    core::array::from_fn(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    core::array::from_fn(|i| {
        core::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j])
    })
}

pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
