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

/// A tensor Chebyshev expansion on `[x0, x1] x [y0, y1]`.
#[derive(Debug, Clone)]
struct Cheb2 {
    x: (f64, f64),
    y: (f64, f64),
    nx: usize,
    ny: usize,
    /// Row-major `c[j * ny + k]` for `T_j(x) T_k(y)`.
    c: Vec<f64>,
}

/// Chebyshev basis values and derivatives (with respect to the mapped
/// variable in `[-1, 1]`).
fn basis(t: f64, n: usize, v: &mut [f64; MAX_ORDER], dv: &mut [f64; MAX_ORDER]) {
    v[0] = 1.0;
    dv[0] = 0.0;
    if n > 1 {
        v[1] = t;
        dv[1] = 1.0;
    }
    for j in 2..n {
        v[j] = 2.0 * t * v[j - 1] - v[j - 2];
        dv[j] = 2.0 * v[j - 1] + 2.0 * t * dv[j - 1] - dv[j - 2];
    }
}

impl Cheb2 {
    fn fit(
        x: (f64, f64),
        y: (f64, f64),
        nx: usize,
        ny: usize,
        f: impl Fn(f64, f64) -> f64,
    ) -> Self {
        let node = |k: usize, n: usize| (std::f64::consts::PI * (k as f64 + 0.5) / n as f64).cos();
        let map = |t: f64, (a, b): (f64, f64)| 0.5 * (a + b) + 0.5 * (b - a) * t;
        let mut vals = vec![0.0; nx * ny];
        for a in 0..nx {
            for b in 0..ny {
                vals[a * ny + b] = f(map(node(a, nx), x), map(node(b, ny), y));
            }
        }
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
        Self { x, y, nx, ny, c }
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
    elastic: Cheb2,
    volume: Cheb2,
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
        let (nx, ny) = (20, 8);
        let elastic = Cheb2::fit((lo, hi), w, nx, ny, |e, w| model.energy_j(e, w.sqrt(), 0.0));
        let volume = Cheb2::fit((lo, hi), w, nx, ny, |e, w| {
            model.energy_j(e, w.sqrt(), 0.0) - model.energy_j(e, w.sqrt(), 1.0)
        });
        let p = model.params();
        Ok(Self {
            elastic,
            volume,
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
        let c = &self.elastic;
        let ty = (2.0 * w - c.y.0 - c.y.1) / (c.y.1 - c.y.0);
        let sx = 2.0 / (c.x.1 - c.x.0);
        let sy = 2.0 / (c.y.1 - c.y.0);
        let (mut vy, mut dvy) = ([0.0; MAX_ORDER], [0.0; MAX_ORDER]);
        basis(ty, c.ny, &mut vy, &mut dvy);
        // Per surface and x order: sum_k c_jk T_k(y) and its y-derivative.
        let contract = |ch: &Cheb2| {
            let mut a = [0.0; MAX_ORDER];
            let mut b = [0.0; MAX_ORDER];
            for j in 0..ch.nx {
                let row = &ch.c[j * ch.ny..(j + 1) * ch.ny];
                for k in 0..ch.ny {
                    a[j] += row[k] * vy[k];
                    b[j] += row[k] * dvy[k];
                }
            }
            (a, b)
        };
        let (ea, eb) = contract(&self.elastic);
        let (va, vb) = contract(&self.volume);
        strains.map(|e| {
            let tx = (2.0 * e - c.x.0 - c.x.1) / (c.x.1 - c.x.0);
            // T_j(x) and T_j'(x) by their recurrences, accumulated on the fly.
            let (mut t0, mut t1, mut d0, mut d1) = (1.0, tx, 0.0, 1.0);
            let mut acc = [0.0; 6];
            for j in 0..c.nx {
                let (t, d) = match j {
                    0 => (t0, d0),
                    1 => (t1, d1),
                    _ => {
                        let t2 = 2.0 * tx * t1 - t0;
                        let d2 = 2.0 * t1 + 2.0 * tx * d1 - d0;
                        (t0, t1, d0, d1) = (t1, t2, d1, d2);
                        (t2, d2)
                    }
                };
                acc[0] += t * ea[j];
                acc[1] += d * ea[j];
                acc[2] += t * eb[j];
                acc[3] += t * va[j];
                acc[4] += d * va[j];
                acc[5] += t * vb[j];
            }
            EnergyGrad {
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
            }
        })
    }
}
