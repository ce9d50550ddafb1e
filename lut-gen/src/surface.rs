//! The one fast evaluator of the OCM energy model: a tensor Chebyshev
//! expansion of the model's energy parts over strain and bend, with exact
//! derivatives of the expansion.
//!
//! Why an expansion: one direct evaluation of [`OcmModel`] costs about a
//! microsecond and a half (a layer's bar-and-hinge geometry with dual
//! numbers), while the virtual lab needs the gradient of three columns every
//! millisecond and `ocm ident` the force and moment of every row of a record
//! in every fit iteration. The expansion is built from the model at
//! construction (a few hundred to a few thousand model evaluations), is
//! checked against it in the tests, and evaluates in well under a
//! microsecond. It is not the firmware's LUT: it covers the coupled energy
//! (axial and bending at once) in `f64`.
//!
//! The energy is even in the bending angle, so the bend coordinate is the
//! squared angle `w = phi^2`, which keeps the expansion smooth and halves its
//! size. The bend range is either a fixed angle ([`BendDomain::Absolute`]:
//! the lab, whose three columns of a segment share one bend, so the bend
//! direction of the expansion is contracted once for all three) or a fraction
//! of the largest feasible bend at each strain ([`BendDomain::Relative`]:
//! identification, which needs the whole feasible range; that range shrinks
//! to nothing as the module folds flat, so no rectangle in `(strain, phi)`
//! covers it).

use crate::model::{ModelError, OcmModel};

/// How far the expansion reaches in bend.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BendDomain {
    /// Up to `max_rad` per OCM at every strain; the coordinate is `phi^2`.
    Absolute {
        /// Largest bend angle covered, radians.
        max_rad: f64,
    },
    /// Up to `fraction` of the largest feasible bend at each strain; the
    /// coordinate is `(phi / phi_max(strain))^2`.
    Relative {
        /// Share of the largest feasible bend covered, in (0, 1).
        fraction: f64,
    },
}

/// Value and gradient of one energy part at a point.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PartGrad {
    /// Value (joules, or cubic metres for a volume part).
    pub value: f64,
    /// Derivative with respect to the strain.
    pub d_strain: f64,
    /// Derivative with respect to `w = phi^2` (per-OCM bend angle squared).
    pub d_w: f64,
}

/// The parts of an OCM's energy an expansion carries, as functions of
/// `(model, strain, bend angle)`.
pub type PartsFn<const K: usize> = fn(&OcmModel, f64, f64) -> [f64; K];

/// Elastic energy (bars and hinges, joules) and volume (cubic metres; the
/// pressure's energy is `-P V`): what a simulation of the module needs.
pub fn elastic_and_volume(model: &OcmModel, strain: f64, bend_rad: f64) -> [f64; 2] {
    // One layer evaluation for both, and the volume without the cancellation
    // of a difference of energies.
    let [bar, hinge, volume] = bar_hinge_volume(model, strain, bend_rad);
    [bar + hinge, volume]
}

/// Bar energy, hinge energy (joules) and volume (cubic metres) apart: what a
/// fit of the two stiffnesses needs.
pub fn bar_hinge_volume(model: &OcmModel, strain: f64, bend_rad: f64) -> [f64; 3] {
    let p = model.params();
    let n = f64::from(p.layers);
    let parts = model
        .layer()
        .parts(model.layer_height_m(strain), bend_rad / n);
    [
        n * p.bar_stiffness_n_per_m * parts.bar,
        n * p.hinge_stiffness_n_per_m * parts.hinge,
        n * parts.volume,
    ]
}

/// A tensor Chebyshev expansion of `K` energy parts, order `NX` in strain
/// and `NY` in the bend coordinate (both fixed, so that the evaluation works
/// on arrays the compiler unrolls and vectorizes).
#[derive(Debug, Clone)]
pub struct EnergySurface<const NX: usize, const NY: usize, const K: usize> {
    strain: (f64, f64),
    bend: BendDomain,
    /// Upper end of the bend coordinate (`max_rad^2` or `fraction^2`).
    y_max: f64,
    /// `coef[k][j][m]` multiplies `T_j(x) T_m(y)` in part `k`.
    coef: Box<[[[f64; NY]; NX]; K]>,
    /// The expansion at zero bend, `sum_m coef[k][j][m] T_m(-1)`, and its
    /// bend derivative there, `sum_m coef[k][j][m] T_m'(-1)`.
    straight: Box<[[[f64; NX]; 2]; K]>,
    /// The derivative expansions the gradient path sums.
    grad: Box<GradTables<NX, NY, K>>,
    model: OcmModel,
}

/// Chebyshev coefficients below this share of a part's largest one are
/// fitting noise (the parts are smooth, so the coefficients fall by orders
/// of magnitude per degree); over an absolute bend range the gradient path
/// skips the bend orders made only of them, which moves the gradients by a
/// few parts in 1e9. Over a relative range nothing is skipped: near the fold
/// the strain derivative carries the bend derivative times
/// `phi_max' / phi_max`, which grows without bound.
const NEGLIGIBLE: f64 = 1e-12;

/// The expansion's derivatives as expansions of their own, in the layout the
/// gradient sums stream through.
///
/// With `T_n' = n U_{n-1}`, the strain derivative of part `k` is
/// `sum_{m, j} dx[k][m][j] U_j(x) T_m(y)` and the bend derivative
/// `sum_{m, j} dy[k][m][j] T_j(x) U_m(y)`: the factor `n` sits in the
/// coefficients, and both directions use the same two-term recurrences.
/// Rows are indexed by the bend order, so that contracting the bend is a sum
/// of whole rows over the strain order, which vectorizes.
#[derive(Debug, Clone)]
struct GradTables<const NX: usize, const NY: usize, const K: usize> {
    /// `dx[k][m][j] = (j + 1) coef[k][j + 1][m]` (0 for `j = NX - 1`).
    dx: [[[f64; NX]; NY]; K],
    /// `dy[k][m][j] = (m + 1) coef[k][j][m + 1]` (0 for `m = NY - 1`).
    dy: [[[f64; NX]; NY]; K],
    /// Rows of `dx[k]` and `dy[k]` that carry more than noise.
    rows_x: [usize; K],
    rows_y: [usize; K],
}

impl<const NX: usize, const NY: usize, const K: usize> GradTables<NX, NY, K> {
    fn new(coef: &[[[f64; NY]; NX]; K], negligible: f64) -> Box<Self> {
        let mut t = Box::new(Self {
            dx: [[[0.0; NX]; NY]; K],
            dy: [[[0.0; NX]; NY]; K],
            rows_x: [0; K],
            rows_y: [0; K],
        });
        for (k, part) in coef.iter().enumerate() {
            let largest = part.iter().flatten().fold(0.0f64, |a, c| a.max(c.abs()));
            // Bend orders up to the last one with a coefficient above noise.
            let orders = (0..NY)
                .rev()
                .find(|&m| part.iter().any(|row| row[m].abs() > negligible * largest))
                .map_or(0, |m| m + 1);
            for m in 0..NY {
                for j in 0..NX {
                    if j + 1 < NX {
                        t.dx[k][m][j] = (j + 1) as f64 * part[j + 1][m];
                    }
                    if m + 1 < NY {
                        t.dy[k][m][j] = (m + 1) as f64 * part[j][m + 1];
                    }
                }
            }
            t.rows_x[k] = orders;
            t.rows_y[k] = orders.saturating_sub(1);
        }
        t
    }

    /// Per part, the strain-derivative and bend-derivative rows contracted
    /// over the bend at the mapped coordinate `ty`.
    #[inline(always)]
    fn contract(&self, ty: f64) -> [[[f64; NX]; 2]; K] {
        let (mut t, mut u) = ([0.0; NY], [0.0; NY]);
        t[0] = 1.0;
        u[0] = 1.0;
        if NY > 1 {
            t[1] = ty;
            u[1] = 2.0 * ty;
        }
        for m in 2..NY {
            t[m] = 2.0 * ty * t[m - 1] - t[m - 2];
            u[m] = 2.0 * ty * u[m - 1] - u[m - 2];
        }
        let mut out = [[[0.0; NX]; 2]; K];
        for (k, [ox, oy]) in out.iter_mut().enumerate() {
            for (row, tm) in self.dx[k][..self.rows_x[k]].iter().zip(&t) {
                for (o, c) in ox.iter_mut().zip(row) {
                    *o += c * tm;
                }
            }
            for (row, um) in self.dy[k][..self.rows_y[k]].iter().zip(&u) {
                for (o, c) in oy.iter_mut().zip(row) {
                    *o += c * um;
                }
            }
        }
        out
    }
}

/// Per strain and part, `[sum_j U_j(x) rows[k][0][j], sum_j T_j(x)
/// rows[k][1][j]]` at the mapped strains `tx` (each with its own contracted
/// rows): the strain and bend derivatives in mapped coordinates. The three
/// strains run side by side, so the recurrences and the sums form twelve
/// independent chains instead of one long one.
#[inline(always)]
fn sum_gradient3<const NX: usize, const K: usize>(
    rows: [&[[[f64; NX]; 2]; K]; 3],
    tx: [f64; 3],
) -> [[[f64; 2]; K]; 3] {
    let mut acc = [[[0.0; 2]; K]; 3];
    let add = |acc: &mut [[[f64; 2]; K]; 3], j: usize, t: [f64; 3], u: [f64; 3]| {
        for s in 0..3 {
            for k in 0..K {
                acc[s][k][0] += u[s] * rows[s][k][0][j];
                acc[s][k][1] += t[s] * rows[s][k][1][j];
            }
        }
    };
    let (mut t0, mut t1) = ([1.0; 3], tx);
    let (mut u0, mut u1) = ([1.0; 3], tx.map(|x| 2.0 * x));
    add(&mut acc, 0, t0, u0);
    if NX > 1 {
        add(&mut acc, 1, t1, u1);
    }
    for j in 2..NX {
        let mut t2 = [0.0; 3];
        let mut u2 = [0.0; 3];
        for s in 0..3 {
            t2[s] = 2.0 * tx[s] * t1[s] - t0[s];
            u2[s] = 2.0 * tx[s] * u1[s] - u0[s];
        }
        add(&mut acc, j, t2, u2);
        (t0, t1, u0, u1) = (t1, t2, u1, u2);
    }
    acc
}

/// Chebyshev nodes `cos(pi (a + 1/2) / n)`.
fn node(a: usize, n: usize) -> f64 {
    (std::f64::consts::PI * (a as f64 + 0.5) / n as f64).cos()
}

impl<const NX: usize, const NY: usize, const K: usize> EnergySurface<NX, NY, K> {
    /// Fits the expansion of `parts` of `model` over `strain` (a range inside
    /// the model's strain limits) and `bend`.
    pub fn new(
        model: &OcmModel,
        strain: (f64, f64),
        bend: BendDomain,
        parts: PartsFn<K>,
    ) -> Result<Self, ModelError> {
        const { assert!(NX >= 2 && NY >= 2 && NY.is_multiple_of(2)) };
        let (lo, hi) = model.strain_limits();
        if !(strain.0 > lo && strain.1 < hi && strain.0 < strain.1) {
            return Err(ModelError::OutOfRange {
                what: "strain range of the energy expansion",
                value: if strain.0 > lo { strain.1 } else { strain.0 },
                min: lo,
                max: hi,
            });
        }
        let y_max = match bend {
            BendDomain::Absolute { max_rad } => {
                let reach = model.max_bend_angle_rad(strain.0);
                if !(max_rad > 0.0 && max_rad < reach) {
                    return Err(ModelError::OutOfRange {
                        what: "bend angle of the energy expansion, rad",
                        value: max_rad,
                        min: 0.0,
                        max: reach,
                    });
                }
                max_rad * max_rad
            }
            BendDomain::Relative { fraction } => {
                if !(fraction > 0.0 && fraction < 1.0) {
                    return Err(ModelError::OutOfRange {
                        what: "share of the largest bend covered",
                        value: fraction,
                        min: 0.0,
                        max: 1.0,
                    });
                }
                fraction * fraction
            }
        };
        let map = |t: f64, (a, b): (f64, f64)| 0.5 * (a + b) + 0.5 * (b - a) * t;
        // Values at the tensor nodes, [k][a][b].
        let mut vals = vec![[0.0; K]; NX * NY];
        for a in 0..NX {
            let e = map(node(a, NX), strain);
            let reach = model.max_bend_angle_rad(e);
            for b in 0..NY {
                let y = map(node(b, NY), (0.0, y_max));
                let phi = match bend {
                    BendDomain::Absolute { .. } => y.sqrt(),
                    BendDomain::Relative { .. } => y.sqrt() * reach,
                };
                vals[a * NY + b] = parts(model, e, phi);
            }
        }
        if let Some(bad) = vals.iter().flatten().find(|v| !v.is_finite()) {
            return Err(ModelError::OutOfRange {
                what: "energy part inside the expansion's domain",
                value: *bad,
                min: f64::MIN,
                max: f64::MAX,
            });
        }
        // Discrete Chebyshev transform in both directions.
        let table = |n: usize| -> Vec<f64> {
            (0..n * n)
                .map(|i| {
                    let (j, a) = (i / n, i % n);
                    (j as f64 * std::f64::consts::PI * (a as f64 + 0.5) / n as f64).cos()
                })
                .collect()
        };
        let (tx, ty) = (table(NX), table(NY));
        let mut coef = Box::new([[[0.0; NY]; NX]; K]);
        for (k, part) in coef.iter_mut().enumerate() {
            for (j, row) in part.iter_mut().enumerate() {
                for (m, c) in row.iter_mut().enumerate() {
                    let mut sum = 0.0;
                    for a in 0..NX {
                        let inner: f64 =
                            (0..NY).map(|b| vals[a * NY + b][k] * ty[m * NY + b]).sum();
                        sum += tx[j * NX + a] * inner;
                    }
                    let wj = if j == 0 { 1.0 } else { 2.0 };
                    let wm = if m == 0 { 1.0 } else { 2.0 };
                    *c = sum * wj * wm / (NX * NY) as f64;
                }
            }
        }
        let mut straight = Box::new([[[0.0; NX]; 2]; K]);
        for (s, part) in straight.iter_mut().zip(coef.iter()) {
            for (j, row) in part.iter().enumerate() {
                // T_m(-1) = (-1)^m and T_m'(-1) = (-1)^(m+1) m^2
                for (m, c) in row.iter().enumerate() {
                    let sign = if m % 2 == 0 { 1.0 } else { -1.0 };
                    s[0][j] += sign * c;
                    s[1][j] -= sign * (m * m) as f64 * c;
                }
            }
        }
        let negligible = match bend {
            BendDomain::Absolute { .. } => NEGLIGIBLE,
            BendDomain::Relative { .. } => 0.0,
        };
        let grad = GradTables::new(&coef, negligible);
        Ok(Self {
            strain,
            bend,
            y_max,
            coef,
            straight,
            grad,
            model: model.clone(),
        })
    }

    /// The model the expansion was fitted to.
    pub fn model(&self) -> &OcmModel {
        &self.model
    }

    /// Strain range covered.
    pub fn strain_range(&self) -> (f64, f64) {
        self.strain
    }

    /// How far the expansion reaches in bend.
    pub fn bend_domain(&self) -> BendDomain {
        self.bend
    }

    /// Largest bend angle covered at `strain`, radians.
    pub fn bend_limit_rad(&self, strain: f64) -> f64 {
        match self.bend {
            BendDomain::Absolute { max_rad } => max_rad,
            BendDomain::Relative { fraction } => fraction * self.model.max_bend_angle_rad(strain),
        }
    }

    /// Parts and their derivatives along the straight pose (`phi = 0`): the
    /// axial terms, at the cost of a one-dimensional expansion.
    pub fn straight(&self, strain: f64) -> [PartGrad; K] {
        let (x0, x1) = self.strain;
        let tx = (2.0 * strain - x0 - x1) / (x1 - x0);
        let sx = 2.0 / (x1 - x0);
        let sy = 2.0 / self.y_max;
        let dy = match self.bend {
            BendDomain::Absolute { .. } => 1.0,
            BendDomain::Relative { .. } => {
                let reach = self.model.max_bend_angle_rad(strain);
                1.0 / (reach * reach)
            }
        };
        std::array::from_fn(|k| {
            let (v, d) = clenshaw_with_derivative(&self.straight[k][0], tx);
            let (w, _) = clenshaw_with_derivative(&self.straight[k][1], tx);
            PartGrad {
                value: v,
                d_strain: d * sx,
                d_w: w * sy * dy,
            }
        })
    }

    /// All parts and their gradients at `(strain, w = phi^2)`; the point must
    /// lie in the covered range (callers clamp).
    pub fn eval(&self, strain: f64, w: f64) -> [PartGrad; K] {
        let [one, _, _] = self.eval3([strain; 3], w);
        one
    }

    /// [`Self::eval`] at three strains sharing one bend (the three columns of
    /// a segment).
    pub fn eval3(&self, strains: [f64; 3], w: f64) -> [[PartGrad; K]; 3] {
        self.eval3_values(strains, w)
    }

    /// [`Self::eval3`] without the values (left 0): the gradients are all a
    /// dynamic simulation needs. They come from the derivative expansions,
    /// which skip the bend orders that carry only fitting noise, so they
    /// agree with [`Self::eval3`]'s to rounding, not bit for bit.
    pub fn grad3(&self, strains: [f64; 3], w: f64) -> [[PartGrad; K]; 3] {
        let (x0, x1) = self.strain;
        let sx = 2.0 / (x1 - x0);
        let sy = 2.0 / self.y_max;
        let ty = |y: f64| (2.0 * y - self.y_max) / self.y_max;
        let tx = |e: f64| (2.0 * e - x0 - x1) / (x1 - x0);
        let part = |d: [f64; 2]| PartGrad {
            value: 0.0,
            d_strain: d[0] * sx,
            d_w: d[1] * sy,
        };
        let ts = strains.map(tx);
        match self.bend {
            BendDomain::Absolute { .. } => {
                let rows = self.grad.contract(ty(w));
                sum_gradient3([&rows; 3], ts).map(|d| d.map(part))
            }
            BendDomain::Relative { .. } => {
                // u = w / phi_max(e)^2: du/dw = 1 / phi_max^2 and
                // du/de = -2 u phi_max' / phi_max.
                let per = strains.map(|e| {
                    let (reach, slope) = self.model.max_bend_angle_and_slope(e);
                    let inv = 1.0 / (reach * reach);
                    let u = w * inv;
                    (u, inv, slope / reach, self.grad.contract(ty(u)))
                });
                let d = sum_gradient3([&per[0].3, &per[1].3, &per[2].3], ts);
                std::array::from_fn(|s| {
                    let (u, inv, rate, _) = per[s];
                    d[s].map(|[dx, dy]| {
                        let d_u = dy * sy;
                        PartGrad {
                            value: 0.0,
                            d_strain: dx * sx - d_u * 2.0 * u * rate,
                            d_w: d_u * inv,
                        }
                    })
                })
            }
        }
    }

    #[inline(always)]
    fn eval3_values(&self, strains: [f64; 3], w: f64) -> [[PartGrad; K]; 3] {
        let (x0, x1) = self.strain;
        let sx = 2.0 / (x1 - x0);
        let sy = 2.0 / self.y_max;
        match self.bend {
            BendDomain::Absolute { .. } => {
                // The bend direction is contracted once for all three strains.
                let rows = self.contract_bend(w);
                strains.map(|e| {
                    let tx = (2.0 * e - x0 - x1) / (x1 - x0);
                    let acc = sum_strain::<NX, K>(&rows, tx);
                    std::array::from_fn(|k| PartGrad {
                        value: acc[k][0],
                        d_strain: acc[k][1] * sx,
                        d_w: acc[k][2] * sy,
                    })
                })
            }
            BendDomain::Relative { .. } => strains.map(|e| {
                // u = w / phi_max(e)^2: du/dw = 1 / phi_max^2 and
                // du/de = -2 u phi_max' / phi_max.
                let (reach, slope) = self.model.max_bend_angle_and_slope(e);
                let inv = 1.0 / (reach * reach);
                let u = w * inv;
                let rows = self.contract_bend(u);
                let tx = (2.0 * e - x0 - x1) / (x1 - x0);
                let acc = sum_strain::<NX, K>(&rows, tx);
                std::array::from_fn(|k| {
                    let d_u = acc[k][2] * sy;
                    PartGrad {
                        value: acc[k][0],
                        d_strain: acc[k][1] * sx - d_u * 2.0 * u * slope / reach,
                        d_w: d_u * inv,
                    }
                })
            }),
        }
    }

    /// Per strain order and part: `sum_m c[k][j][m] T_m(y)` and its
    /// derivative with respect to the mapped bend coordinate.
    #[inline(always)]
    fn contract_bend(&self, y: f64) -> [[[f64; 2]; K]; NX] {
        let ty = (2.0 * y - self.y_max) / self.y_max;
        let (mut v, mut dv) = ([0.0; NY], [0.0; NY]);
        v[0] = 1.0;
        v[1] = ty;
        dv[1] = 1.0;
        for m in 2..NY {
            v[m] = 2.0 * ty * v[m - 1] - v[m - 2];
            dv[m] = 2.0 * v[m - 1] + 2.0 * ty * dv[m - 1] - dv[m - 2];
        }
        // Two lanes wide: independent partial sums.
        let dot = |a: &[f64; NY], b: &[f64; NY]| {
            let (mut p, mut q) = (0.0, 0.0);
            for m in (0..NY).step_by(2) {
                p += a[m] * b[m];
                q += a[m + 1] * b[m + 1];
            }
            p + q
        };
        let mut rows = [[[0.0; 2]; K]; NX];
        for (j, r) in rows.iter_mut().enumerate() {
            for (rk, part) in r.iter_mut().zip(self.coef.iter()) {
                *rk = [dot(&part[j], &v), dot(&part[j], &dv)];
            }
        }
        rows
    }
}

/// Value, strain derivative and bend derivative (all in mapped coordinates)
/// of each part from the contracted rows, `T_j(x)` and `T_j'(x)` by their
/// recurrences.
#[inline(always)]
fn sum_strain<const NX: usize, const K: usize>(
    rows: &[[[f64; 2]; K]; NX],
    tx: f64,
) -> [[f64; 3]; K] {
    // Independent sums per part and quantity, so the recurrence is the only
    // dependency chain.
    let mut acc = [[0.0; 3]; K];
    let add = |acc: &mut [[f64; 3]; K], t: f64, d: f64, r: &[[f64; 2]; K]| {
        for (a, rk) in acc.iter_mut().zip(r) {
            a[0] += t * rk[0];
            a[1] += d * rk[0];
            a[2] += t * rk[1];
        }
    };
    let (mut t0, mut t1, mut d0, mut d1) = (1.0, tx, 0.0, 1.0);
    add(&mut acc, t0, d0, &rows[0]);
    add(&mut acc, t1, d1, &rows[1]);
    for r in &rows[2..] {
        let t2 = 2.0 * tx * t1 - t0;
        let d2 = 2.0 * t1 + 2.0 * tx * d1 - d0;
        add(&mut acc, t2, d2, r);
        (t0, t1, d0, d1) = (t1, t2, d1, d2);
    }
    acc
}

/// Value and derivative of `sum_j c_j T_j(t)`.
fn clenshaw_with_derivative(c: &[f64], t: f64) -> (f64, f64) {
    let (mut t0, mut t1, mut d0, mut d1) = (1.0, t, 0.0, 1.0);
    let mut v = c[0] + c[1] * t;
    let mut d = c[1];
    for cj in &c[2..] {
        let t2 = 2.0 * t * t1 - t0;
        let d2 = 2.0 * t1 + 2.0 * t * d1 - d0;
        v += cj * t2;
        d += cj * d2;
        (t0, t1, d0, d1) = (t1, t2, d1, d2);
    }
    (v, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ocm_shared::params::OcmParams;

    fn model() -> OcmModel {
        OcmModel::new(OcmParams::CALIBRATED).unwrap()
    }

    /// The slope of the largest bend is its finite difference.
    #[test]
    fn bend_reach_slope_is_its_derivative() {
        let m = model();
        for e in [-0.8, -0.3, 0.2, 1.1] {
            let (r, s) = m.max_bend_angle_and_slope(e);
            assert!((r - m.max_bend_angle_rad(e)).abs() < 1e-14);
            let h = 1e-6;
            let fd = (m.max_bend_angle_rad(e + h) - m.max_bend_angle_rad(e - h)) / (2.0 * h);
            assert!((s - fd).abs() < 1e-6 * s.abs().max(1.0), "{s} vs {fd}");
        }
    }

    /// Values and both gradients against the model, its finite differences
    /// and each other, in both domains.
    fn check<const NX: usize, const NY: usize>(bend: BendDomain, strain: (f64, f64), tol: f64) {
        let m = model();
        let s = EnergySurface::<NX, NY, 3>::new(&m, strain, bend, bar_hinge_volume).unwrap();
        let scale = [1e-3, 1e-3, 1e-6];
        let mut worst: f64 = 0.0;
        for a in 0..13 {
            let e = strain.0 + (strain.1 - strain.0) * (a as f64 + 0.31) / 13.2;
            for b in 0..7 {
                let phi = s.bend_limit_rad(e) * (b as f64 + 0.17) / 7.1;
                let w = phi * phi;
                let got = s.eval(e, w);
                let exact = bar_hinge_volume(&m, e, phi);
                let he = 1e-6;
                let up = bar_hinge_volume(&m, e + he, phi);
                let dn = bar_hinge_volume(&m, e - he, phi);
                let hp = 1e-5 * phi.max(1e-3);
                let wu = bar_hinge_volume(&m, e, phi + hp);
                let wd = bar_hinge_volume(&m, e, phi - hp);
                for k in 0..3 {
                    let rel = |x: f64, y: f64| (x - y).abs() / scale[k];
                    worst = worst.max(rel(got[k].value, exact[k]));
                    worst = worst.max(rel(got[k].d_strain, (up[k] - dn[k]) / (2.0 * he)) * 1e-1);
                    // dE/dphi = 2 phi dE/dw
                    let dphi = (wu[k] - wd[k]) / (2.0 * hp);
                    worst = worst.max(rel(2.0 * phi * got[k].d_w, dphi) * 1e-1);
                }
                // eval3 with three strains agrees with three evals
                let three = s.eval3([e, strain.0 + 0.01, e], w);
                assert_eq!(three[0], got);
                assert_eq!(three[2], got);
                // The gradient path's derivative expansions agree with the
                // full expansion to rounding (where the second strain's bend
                // range covers `w`: outside it both extrapolate).
                let other = strain.0 + 0.01;
                let g = s.grad3([e, other, e], w);
                let inside = w <= s.bend_limit_rad(other).powi(2);
                for k in 0..3 {
                    let close = |a: f64, b: f64| (a - b).abs() <= 1e-8 * scale[k].max(b.abs());
                    assert!(close(g[0][k].d_strain, got[k].d_strain), "{k}: d_strain");
                    assert!(close(g[2][k].d_w, got[k].d_w), "{k}: d_w");
                    if inside {
                        assert!(
                            close(g[1][k].d_strain, three[1][k].d_strain),
                            "{k}: d_strain"
                        );
                        assert!(close(g[1][k].d_w, three[1][k].d_w), "{k}: d_w");
                    }
                    assert_eq!(g[0][k].value, 0.0);
                }
            }
            // the straight pose through its own path
            let st = s.straight(e);
            let full = s.eval(e, 0.0);
            for k in 0..3 {
                assert!((st[k].value - full[k].value).abs() < 1e-12 * scale[k]);
                assert!((st[k].d_strain - full[k].d_strain).abs() < 1e-10 * scale[k]);
                assert!((st[k].d_w - full[k].d_w).abs() < 1e-9 * scale[k].max(full[k].d_w.abs()));
            }
        }
        assert!(worst < tol, "{bend:?}: worst relative error {worst:e}");
    }

    #[test]
    fn absolute_domain_matches_the_model() {
        check::<20, 8>(BendDomain::Absolute { max_rad: 0.5 }, (-0.7, 1.2), 1e-6);
    }

    #[test]
    fn relative_domain_matches_the_model() {
        check::<40, 12>(BendDomain::Relative { fraction: 0.97 }, (-0.8, 1.9), 1e-5);
    }

    #[test]
    fn domains_outside_the_model_are_refused() {
        let m = model();
        let (lo, hi) = m.strain_limits();
        let abs = BendDomain::Absolute { max_rad: 0.3 };
        assert!(EnergySurface::<8, 4, 2>::new(&m, (lo, 0.0), abs, elastic_and_volume).is_err());
        assert!(EnergySurface::<8, 4, 2>::new(&m, (0.0, hi), abs, elastic_and_volume).is_err());
        let wide = BendDomain::Absolute { max_rad: 5.0 };
        assert!(EnergySurface::<8, 4, 2>::new(&m, (-0.5, 0.5), wide, elastic_and_volume).is_err());
        let full = BendDomain::Relative { fraction: 1.0 };
        assert!(EnergySurface::<8, 4, 2>::new(&m, (-0.5, 0.5), full, elastic_and_volume).is_err());
    }
}
