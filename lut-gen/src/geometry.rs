//! Geometry of one Yoshimura layer: its bar-and-hinge topology and the
//! kinematic map from the layer configuration (height `h`, bending angle
//! `beta`) to nodal positions.
//!
//! # The layer (dissertation Ch. 3.3.2, Fig. 3.4)
//! A layer of a Yoshimura cylinder with `n = 4` sides has three rings of
//! `n` vertices: the bottom ring `a1`, the middle ring `a2` (rotated by
//! `pi/n`) and the top ring `a3`, plus `n` mid-edge nodes `m` on the middle
//! ring's edges where the facets buckle. That gives 12 vertices + 4 mid
//! nodes, 24 lateral facets (16 crease triangles, 8 of them split in two at
//! the mid nodes), 40 bars and 32 hinges, as counted in Table 3.1.
//!
//! # Kinematic map (our modelling choice, documented in docs/model.md)
//! The bottom and top rings stay regular polygons of side `L` (they are
//! bonded to the neighbouring layers), and the diagonal creases keep their
//! length in the flat pattern, `s_d = L / (2 cos theta_d)`. These two
//! constraints fix the radius `r2(h)` of the middle ring for a layer height
//! `h`; the middle ring's edges and the mid-node bars absorb the mismatch,
//! which is where the bar energy comes from. The height runs from 0 (flat
//! folded) to `h* = L tan theta_d`, where `r2` stops being real: the
//! geometric strain limit `eps*` of eq 3.5.
//!
//! Bending (Fig. 3.4-B, eq 3.11-3.15) keeps each ring rigid and rotates it
//! about the centre of curvature, so the middle ring turns by `beta/2` and
//! the top ring by `beta`; the neutral axis is an arc of length `h`.

use crate::scalar::Scalar;

/// Number of sides of the Yoshimura polygon.
pub const SIDES: usize = 4;
/// Nodes in one layer: three rings plus the mid-edge nodes.
pub const NODES: usize = 4 * SIDES;
/// Bars in one layer (`n_b`).
pub const BARS: usize = 10 * SIDES;
/// Hinges in one layer (`n_h`).
pub const HINGES: usize = 8 * SIDES;
/// Lateral facets in one layer.
pub const FACETS: usize = 6 * SIDES;

/// Index of vertex `k` of the bottom ring.
pub const fn ring1(k: usize) -> usize {
    k % SIDES
}
/// Index of vertex `k` of the middle ring.
pub const fn ring2(k: usize) -> usize {
    SIDES + k % SIDES
}
/// Index of vertex `k` of the top ring.
pub const fn ring3(k: usize) -> usize {
    2 * SIDES + k % SIDES
}
/// Index of the mid node on the middle-ring edge from `ring2(k)` to `ring2(k+1)`.
pub const fn mid(k: usize) -> usize {
    3 * SIDES + k % SIDES
}

/// A hinge: the crease from `i` to `j` between the facets `(i, j, k)` and `(j, i, l)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hinge {
    /// First end of the crease.
    pub i: usize,
    /// Second end of the crease.
    pub j: usize,
    /// Apex of the first facet.
    pub k: usize,
    /// Apex of the second facet.
    pub l: usize,
}

/// Connectivity of one layer: bars, hinges and the closed surface used for
/// the volume.
#[derive(Debug, Clone)]
pub struct Topology {
    /// Bars as node pairs.
    pub bars: [[usize; 2]; BARS],
    /// Hinges, found from the facets.
    pub hinges: [Hinge; HINGES],
    /// Lateral facets, outward oriented (right-hand rule).
    pub facets: [[usize; 3]; FACETS],
}

impl Topology {
    /// Builds the layer topology; facet orientation is fixed by
    /// [`Topology::orient`] once positions are known.
    fn unoriented() -> ([[usize; 2]; BARS], [[usize; 3]; FACETS]) {
        let mut bars = [[0usize; 2]; BARS];
        let mut facets = [[0usize; 3]; FACETS];
        let mut b = 0;
        let mut f = 0;
        for k in 0..SIDES {
            let mut bar = |p: usize, q: usize| {
                bars[b] = [p, q];
                b += 1;
            };
            bar(ring1(k), ring1(k + 1));
            bar(ring3(k), ring3(k + 1));
            bar(ring2(k), mid(k));
            bar(mid(k), ring2(k + 1));
            bar(ring1(k), ring2(k));
            bar(ring1(k + 1), ring2(k));
            bar(ring3(k), ring2(k));
            bar(ring3(k + 1), ring2(k));
            bar(mid(k), ring1(k + 1));
            bar(mid(k), ring3(k + 1));
            let mut facet = |p: usize, q: usize, r: usize| {
                facets[f] = [p, q, r];
                f += 1;
            };
            facet(ring1(k), ring1(k + 1), ring2(k));
            facet(ring2(k), mid(k), ring1(k + 1));
            facet(mid(k), ring2(k + 1), ring1(k + 1));
            facet(ring3(k), ring3(k + 1), ring2(k));
            facet(ring2(k), mid(k), ring3(k + 1));
            facet(mid(k), ring2(k + 1), ring3(k + 1));
        }
        (bars, facets)
    }

    /// The layer topology with facets oriented outward for `layer`.
    pub fn new(layer: &LayerGeometry) -> Self {
        let (bars, mut facets) = Self::unoriented();
        let x = layer.positions::<f64>(layer.rest_height_m, 0.0);
        let centre = [0.0, 0.0, 0.5 * layer.rest_height_m];
        for facet in &mut facets {
            let [a, b, c] = facet.map(|i| x[i]);
            let n = cross(sub(b, a), sub(c, a));
            let centroid = [
                (a[0] + b[0] + c[0]) / 3.0,
                (a[1] + b[1] + c[1]) / 3.0,
                (a[2] + b[2] + c[2]) / 3.0,
            ];
            if dot(n, sub(centroid, centre)) < 0.0 {
                facet.swap(1, 2);
            }
        }
        let hinges = Self::find_hinges(&bars, &facets);
        Self {
            bars,
            hinges,
            facets,
        }
    }

    /// Every bar shared by exactly two facets is a hinge; the facet
    /// orientation gives the apex order so that dihedral angles have a
    /// consistent sign.
    fn find_hinges(bars: &[[usize; 2]; BARS], facets: &[[usize; 3]; FACETS]) -> [Hinge; HINGES] {
        let mut hinges = [Hinge {
            i: 0,
            j: 0,
            k: 0,
            l: 0,
        }; HINGES];
        let mut count = 0;
        for &[p, q] in bars {
            // Find the facet that runs p -> q and the one that runs q -> p.
            let mut forward = None;
            let mut backward = None;
            for facet in facets {
                for e in 0..3 {
                    let (s, t, apex) = (facet[e], facet[(e + 1) % 3], facet[(e + 2) % 3]);
                    if s == p && t == q {
                        forward = Some(apex);
                    } else if s == q && t == p {
                        backward = Some(apex);
                    }
                }
            }
            if let (Some(k), Some(l)) = (forward, backward) {
                hinges[count] = Hinge { i: p, j: q, k, l };
                count += 1;
            }
        }
        assert_eq!(count, HINGES, "layer topology must have n_h hinges");
        hinges
    }
}

/// Geometric constants of one layer derived from the OCM parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerGeometry {
    /// Crease triangle base `L`, metres.
    pub base_side_m: f64,
    /// Side angle `theta_d`, radians.
    pub side_angle_rad: f64,
    /// Circumradius of the bottom and top rings, metres.
    pub outer_radius_m: f64,
    /// Length of the diagonal creases, metres.
    pub diagonal_m: f64,
    /// Height of the unloaded layer `l0 / N`, metres.
    pub rest_height_m: f64,
    /// Largest geometric layer height `L tan theta_d`, metres.
    pub max_height_m: f64,
}

impl LayerGeometry {
    /// Derives the layer constants; `None` when the parameters admit no
    /// real layer (the caller turns that into a named error).
    pub fn new(base_side_m: f64, side_angle_rad: f64, rest_height_m: f64) -> Option<Self> {
        let n = SIDES as f64;
        let outer_radius_m = base_side_m / (2.0 * (core::f64::consts::PI / n).sin());
        let diagonal_m = base_side_m / (2.0 * side_angle_rad.cos());
        let max_height_m = base_side_m * side_angle_rad.tan();
        let ok = base_side_m.is_finite()
            && base_side_m > 0.0
            && side_angle_rad > 0.0
            && side_angle_rad < core::f64::consts::FRAC_PI_2
            && rest_height_m > 0.0
            && rest_height_m < max_height_m;
        ok.then_some(Self {
            base_side_m,
            side_angle_rad,
            outer_radius_m,
            diagonal_m,
            rest_height_m,
            max_height_m,
        })
    }

    /// Radius of the middle ring at layer height `h` (the outer branch, equal
    /// to the outer radius when the layer is folded flat).
    pub fn middle_radius<D: Scalar>(&self, h: D) -> D {
        let n = SIDES as f64;
        let (s, c) = (core::f64::consts::PI / n).sin_cos();
        let d2 = -(h * h) * 0.25 + self.diagonal_m * self.diagonal_m;
        let disc = d2 - (self.outer_radius_m * s).powi(2);
        // Clamp at the geometric limit so that evaluation exactly at h* is
        // finite; the model never asks beyond it.
        let disc = if disc.value() < 0.0 { disc * 0.0 } else { disc };
        disc.sqrt() + self.outer_radius_m * c
    }

    /// Nodal positions of the layer at height `h` bent by `beta` (radians)
    /// towards the direction of middle-ring vertex 0.
    pub fn positions<D: Scalar>(&self, h: D, beta: D) -> [[D; 3]; NODES] {
        let n = SIDES as f64;
        let r1 = D::from(self.outer_radius_m);
        let r2 = self.middle_radius(h);
        let step = 2.0 * core::f64::consts::PI / n;
        // Straight layer in polar form: (radius, angle, height fraction).
        let mut straight = [[D::from(0.0); 3]; NODES];
        for k in 0..SIDES {
            let a = step * k as f64;
            let a2 = a + step * 0.5;
            straight[ring1(k)] = [r1 * a.cos(), r1 * a.sin(), D::from(0.0)];
            straight[ring2(k)] = [r2 * a2.cos(), r2 * a2.sin(), h * 0.5];
            straight[ring3(k)] = [r1 * a.cos(), r1 * a.sin(), h];
        }
        for k in 0..SIDES {
            let p = straight[ring2(k)];
            let q = straight[ring2(k + 1)];
            straight[mid(k)] = [(p[0] + q[0]) * 0.5, (p[1] + q[1]) * 0.5, h * 0.5];
        }
        // Bending: in the frame (b, t, z) with b towards middle vertex 0, a
        // node at height fraction f turns by f*beta about the centre of
        // curvature at b = h/beta. Written with sinc-like helpers so that
        // beta = 0 is exact and differentiable.
        let (bs, bc) = (step * 0.5).sin_cos();
        let fractions = |i: usize| -> f64 {
            if i < SIDES {
                0.0
            } else if !(2 * SIDES..3 * SIDES).contains(&i) {
                0.5
            } else {
                1.0
            }
        };
        let mut out = straight;
        for (i, p) in straight.iter().enumerate() {
            let f = fractions(i);
            if f == 0.0 {
                continue;
            }
            let rb = p[0] * bc + p[1] * bs;
            let rt = -p[0] * bs + p[1] * bc;
            let x = beta * f;
            let (sx, cx) = x.sin_cos();
            let new_b = rb + h * f * versin_over(x) - rb * (-cx + 1.0);
            let new_z = h * f * sinc(x) - rb * sx;
            out[i] = [new_b * bc - rt * bs, new_b * bs + rt * bc, new_z];
        }
        out
    }
}

/// `sin(x)/x`, exact at 0.
pub fn sinc<D: Scalar>(x: D) -> D {
    if x.value().abs() < 1e-4 {
        let x2 = x * x;
        -x2 / 6.0 + x2 * x2 / 120.0 + 1.0
    } else {
        x.sin() / x
    }
}

/// `(1 - cos x)/x`, exact at 0.
pub fn versin_over<D: Scalar>(x: D) -> D {
    if x.value().abs() < 1e-4 {
        let x2 = x * x;
        x * 0.5 - x * x2 / 24.0
    } else {
        (-x.cos() + 1.0) / x
    }
}

/// `a - b` for 3-vectors.
pub fn sub<D: Scalar>(a: [D; 3], b: [D; 3]) -> [D; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Cross product.
pub fn cross<D: Scalar>(a: [D; 3], b: [D; 3]) -> [D; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Dot product.
pub fn dot<D: Scalar>(a: [D; 3], b: [D; 3]) -> D {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Euclidean norm.
pub fn norm<D: Scalar>(a: [D; 3]) -> D {
    dot(a, a).sqrt()
}

/// Signed dihedral (fold) angle of a hinge: the angle between the normals of
/// its two facets, positive when the crease folds towards the first facet's
/// normal.
pub fn dihedral<D: Scalar>(x: &[[D; 3]], h: &Hinge) -> D {
    let e = sub(x[h.j], x[h.i]);
    let n1 = cross(e, sub(x[h.k], x[h.i]));
    let n2 = cross(sub(x[h.l], x[h.i]), e);
    let s = dot(cross(n1, n2), e) / norm(e);
    s.atan2(dot(n1, n2))
}

/// Volume enclosed by the closed surface made of the lateral facets and two
/// planar caps on the bottom and top rings, by tetrahedral decomposition
/// about the origin (divergence theorem).
pub fn enclosed_volume<D: Scalar>(x: &[[D; 3]], facets: &[[usize; 3]]) -> D {
    let tet = |a: [D; 3], b: [D; 3], c: [D; 3]| dot(a, cross(b, c)) / 6.0;
    let mut v = D::from(0.0);
    for f in facets {
        v += tet(x[f[0]], x[f[1]], x[f[2]]);
    }
    // Caps: fans about each ring's centroid, oriented outward (bottom: -z
    // side, top: +z side in the layer frame); consistent with the lateral
    // facets' orientation because the rings run counter-clockwise.
    let centroid = |ring: fn(usize) -> usize| {
        let mut c = [D::from(0.0); 3];
        for k in 0..SIDES {
            for d in 0..3 {
                c[d] += x[ring(k)][d] / SIDES as f64;
            }
        }
        c
    };
    let c1 = centroid(ring1);
    let c3 = centroid(ring3);
    for k in 0..SIDES {
        v += tet(c1, x[ring1(k + 1)], x[ring1(k)]);
        v += tet(c3, x[ring3(k)], x[ring3(k + 1)]);
    }
    v
}
