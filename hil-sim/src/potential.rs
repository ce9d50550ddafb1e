//! The OCM's potential energy as the plant uses it: the lut-gen energy
//! model `Pi(eps, phi, P) = E0(eps, phi) - P V(eps, phi)` (eq 3.3, 3.8,
//! 3.19), represented by a two-dimensional Chebyshev expansion of its two
//! pressure-independent parts.
//!
//! Why an expansion and not direct calls: one direct evaluation costs about
//! 1.5 us, and the plant needs the gradient of three columns every
//! millisecond; the expansion is built from the model itself at
//! construction (a few hundred energy evaluations), is checked against it
//! in the tests to better than 1e-6 relative, and evaluates its gradient in
//! well under a microsecond. It is not the firmware's LUT: it covers the
//! coupled energy (axial and bending at once) and stays in `f64`.
//!
//! The energy is even in the bending angle, so the expansion runs in
//! `w = phi^2`, which keeps it smooth and halves its size.

use ocm_lutgen::OcmModel;

use crate::SimError;

/// Largest expansion order in either variable.
const MAX_ORDER: usize = 32;
/// Expansion orders in the strain and in `w`: fixed, so that the hot
/// evaluation works on arrays the compiler unrolls and vectorizes.
const NX: usize = 20;
const NY: usize = 8;
// The contraction over `w` runs two lanes wide.
const _: () = assert!(NY.is_multiple_of(2) && NX >= 2 && NX <= MAX_ORDER && NY <= MAX_ORDER);

/// A tensor Chebyshev expansion on `[x0, x1] x [y0, y1]`.
#[derive(Debug, Clone)]
struct Cheb2 {
    x: (f64, f64),
    y: (f64, f64),
    /// Row-major `c[j * ny + k]` for `T_j(x) T_k(y)`.
    c: Vec<f64>,
}

/// Chebyshev basis values and derivatives of orders `0..N` (with respect
/// to the mapped variable in `[-1, 1]`).
fn basis<const N: usize>(t: f64) -> ([f64; N], [f64; N]) {
    let (mut v, mut dv) = ([0.0; N], [0.0; N]);
    v[0] = 1.0;
    dv[0] = 0.0;
    if N > 1 {
        v[1] = t;
        dv[1] = 1.0;
    }
    for j in 2..N {
        v[j] = 2.0 * t * v[j - 1] - v[j - 2];
        dv[j] = 2.0 * v[j - 1] + 2.0 * t * dv[j - 1] - dv[j - 2];
    }
    (v, dv)
}

impl Cheb2 {
    /// Fits two functions at once from one call per node (the energy
    /// model yields both parts of a point together).
    fn fit2(
        x: (f64, f64),
        y: (f64, f64),
        nx: usize,
        ny: usize,
        f: impl Fn(f64, f64) -> [f64; 2],
    ) -> [Self; 2] {
        let node = |k: usize, n: usize| (std::f64::consts::PI * (k as f64 + 0.5) / n as f64).cos();
        let map = |t: f64, (a, b): (f64, f64)| 0.5 * (a + b) + 0.5 * (b - a) * t;
        let mut both = [vec![0.0; nx * ny], vec![0.0; nx * ny]];
        for a in 0..nx {
            for b in 0..ny {
                let v = f(map(node(a, nx), x), map(node(b, ny), y));
                both[0][a * ny + b] = v[0];
                both[1][a * ny + b] = v[1];
            }
        }
        both.map(|vals| Self::from_values(x, y, nx, ny, &vals))
    }

    /// The expansion whose values at the Chebyshev nodes are `vals`
    /// (`vals[a * ny + b]` at x node `a`, y node `b`).
    fn from_values(x: (f64, f64), y: (f64, f64), nx: usize, ny: usize, vals: &[f64]) -> Self {
        // cos(j pi (a + 1/2) / n) = T_j at node a, tabulated once.
        let table = |n: usize| -> Vec<f64> {
            (0..n * n)
                .map(|i| {
                    let (j, a) = (i / n, i % n);
                    (j as f64 * std::f64::consts::PI * (a as f64 + 0.5) / n as f64).cos()
                })
                .collect()
        };
        let (tx, ty) = (table(nx), table(ny));
        let mut c = vec![0.0; nx * ny];
        for j in 0..nx {
            for k in 0..ny {
                let mut sum = 0.0;
                for a in 0..nx {
                    let row: f64 = (0..ny).map(|b| vals[a * ny + b] * ty[k * ny + b]).sum();
                    sum += tx[j * nx + a] * row;
                }
                let wj = if j == 0 { 1.0 } else { 2.0 };
                let wk = if k == 0 { 1.0 } else { 2.0 };
                c[j * ny + k] = sum * wj * wk / (nx * ny) as f64;
            }
        }
        Self { x, y, c }
    }
}

/// Value and gradient of one energy part at a point.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PartGrad {
    /// Value, joules (or cubic metres for the volume part).
    pub value: f64,
    /// Derivative with respect to the strain.
    pub d_strain: f64,
    /// Derivative with respect to `w = phi^2` (per-OCM bending angle squared).
    pub d_w: f64,
}

/// Both energy parts of one OCM at one point.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EnergyGrad {
    /// Elastic part `E0` (bars and hinges), joules.
    pub elastic: PartGrad,
    /// Volume part `V - V0` of the whole OCM, cubic metres (energy is `-P V`).
    pub volume: PartGrad,
}

/// The Chebyshev representation of one OCM's energy.
#[derive(Debug, Clone)]
pub struct OcmPotential {
    /// Strain range and `w` range of the expansion.
    x: (f64, f64),
    y: (f64, f64),
    /// Coefficients `[j][k]` of `T_j(x) T_k(y)` in fixed-size rows,
    /// elastic then volume.
    coef: Box<[[[f64; NY]; NX]; 2]>,
    rest_length_m: f64,
    layers: u32,
}

impl OcmPotential {
    /// Strain range covered by the expansion.
    pub const STRAIN_RANGE: (f64, f64) = (-0.7, 1.2);
    /// Largest per-OCM bending angle covered, radians.
    pub const MAX_BEND_RAD: f64 = 0.5;

    /// Fits the expansion to `model`.
    pub fn new(model: &OcmModel) -> Result<Self, SimError> {
        let (lo, hi) = Self::STRAIN_RANGE;
        let phi_cap = model.max_bend_angle_rad(lo);
        if phi_cap <= Self::MAX_BEND_RAD {
            return Err(SimError::Config(format!(
                "OCM design bends at most {phi_cap:.3} rad at strain {lo}; the plant needs {}",
                Self::MAX_BEND_RAD
            )));
        }
        let w = (0.0, Self::MAX_BEND_RAD * Self::MAX_BEND_RAD);
        let (nx, ny) = (NX, NY);
        let [elastic, volume] = Cheb2::fit2((lo, hi), w, nx, ny, |e, w| {
            let e0 = model.energy_j(e, w.sqrt(), 0.0);
            [e0, e0 - model.energy_j(e, w.sqrt(), 1.0)]
        });
        let p = model.params();
        let mut coef = Box::new([[[0.0; NY]; NX]; 2]);
        for (t, ch) in coef.iter_mut().zip([&elastic, &volume]) {
            for (j, row) in t.iter_mut().enumerate() {
                row.copy_from_slice(&ch.c[j * NY..(j + 1) * NY]);
            }
        }
        Ok(Self {
            x: elastic.x,
            y: elastic.y,
            coef,
            rest_length_m: p.rest_length_m,
            layers: p.layers,
        })
    }

    /// Rest length `l0` of one OCM, metres.
    pub fn rest_length_m(&self) -> f64 {
        self.rest_length_m
    }

    /// Layer count of the OCM.
    pub fn layers(&self) -> u32 {
        self.layers
    }

    /// Both parts and their gradients at `(strain, w = phi^2)`; the point
    /// must lie in the covered range (callers clamp).
    pub fn eval(&self, strain: f64, w: f64) -> EnergyGrad {
        self.eval3([strain; 3], w)[0]
    }

    /// [`Self::eval`] at three strains sharing one bend (the three columns
    /// of a segment): the bend direction of the expansion is contracted
    /// once.
    pub fn eval3(&self, strains: [f64; 3], w: f64) -> [EnergyGrad; 3] {
        self.eval3_with::<true>(strains, w)
    }

    /// [`Self::eval3`] without the values (left 0): the gradients are all
    /// the dynamics needs, and they cost two thirds of the sums.
    pub fn grad3(&self, strains: [f64; 3], w: f64) -> [EnergyGrad; 3] {
        self.eval3_with::<false>(strains, w)
    }

    fn eval3_with<const VALUES: bool>(&self, strains: [f64; 3], w: f64) -> [EnergyGrad; 3] {
        let (x, y) = (self.x, self.y);
        let ty = (2.0 * w - y.0 - y.1) / (y.1 - y.0);
        let sx = 2.0 / (x.1 - x.0);
        let sy = 2.0 / (y.1 - y.0);
        let (vy, dvy) = basis::<NY>(ty);
        let (vy, dvy) = (&vy, &dvy);
        let dot = |a: &[f64; NY], b: &[f64; NY]| {
            let (mut p, mut q) = (0.0, 0.0);
            for k in (0..NY).step_by(2) {
                p += a[k] * b[k];
                q += a[k + 1] * b[k + 1];
            }
            p + q
        };
        // Per surface and x order: sum_k c_jk T_k(y) and its y-derivative,
        // the bend direction contracted once for all three columns.
        let mut rows = [[0.0; 4]; NX];
        for (j, r) in rows.iter_mut().enumerate() {
            let (ce, cv) = (&self.coef[0][j], &self.coef[1][j]);
            *r = [dot(ce, vy), dot(ce, dvy), dot(cv, vy), dot(cv, dvy)];
        }
        let mut out = [EnergyGrad::default(); 3];
        for (o, &e) in out.iter_mut().zip(&strains) {
            let tx = (2.0 * e - x.0 - x.1) / (x.1 - x.0);
            // T_j(x) and T_j'(x) by their recurrences, accumulated on the
            // fly: six independent sums per step.
            let mut acc = [0.0; 6];
            let mut add = |t: f64, d: f64, r: &[f64; 4]| {
                if VALUES {
                    acc[0] += t * r[0];
                    acc[3] += t * r[2];
                }
                acc[1] += d * r[0];
                acc[2] += t * r[1];
                acc[4] += d * r[2];
                acc[5] += t * r[3];
            };
            let (mut t0, mut t1, mut d0, mut d1) = (1.0, tx, 0.0, 1.0);
            add(t0, d0, &rows[0]);
            add(t1, d1, &rows[1]);
            for r in &rows[2..] {
                let t2 = 2.0 * tx * t1 - t0;
                let d2 = 2.0 * t1 + 2.0 * tx * d1 - d0;
                add(t2, d2, r);
                (t0, t1, d0, d1) = (t1, t2, d1, d2);
            }
            *o = EnergyGrad {
                elastic: PartGrad {
                    value: acc[0],
                    d_strain: acc[1] * sx,
                    d_w: acc[2] * sy,
                },
                volume: PartGrad {
                    value: acc[3],
                    d_strain: acc[4] * sx,
                    d_w: acc[5] * sy,
                },
            };
        }
        out
    }
}
