//! Aligning the actuation spaces (Ch.4.7, Algorithm 1, eq 4.25-4.27, App. D): bounded L-BFGS-B
//! postures matching the FEM TCP, the regression f_SP from pressures to postures and its inverse.
//!
//! The optimiser works in the increment coordinates of [`Limits::from_increments`], in which the
//! grouped constraints of eq 4.23 are box bounds: every iterate, and so every optimised posture,
//! satisfies them. The objective is the squared TCP distance (same minimiser as the distance of
//! Algorithm 1, but smooth at the solution) plus a very small penalty on the increments, which
//! picks the smoothest of the redundant postures that reach the target equally well.
//!
//! f_SP is by default a cubic RBF interpolant ([`crate::rbf`]) of the optimised postures over the
//! pressures, its output projected onto the feasible set; the inverse maps the three group means
//! back to pressures with the same kind of interpolant. Any other regression (the App. D MLPs of
//! `ocm-dynamics`) can replace both through [`Regressor`] and [`ActuationMap::with_regressor`],
//! without this crate depending on the learning stack.

use crate::chain::{ChainGeometry, GROUPS, KINDS, N_JOINTS, Posture};
use crate::constraints::Limits;
use crate::fem_samples::FemSample;
use crate::rbf::Rbf;
use crate::{Result, SurrogateError};
use ganesh::Vector;
use ganesh::algorithms::gradient::{LBFGSB, LBFGSBConfig, LBFGSBErrorMode};
use ganesh::core::MaxSteps;
use ganesh::traits::{Algorithm, CostFunction, Gradient};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::convert::Infallible;
use std::sync::Arc;

/// Settings of Algorithm 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MatchConfig {
    /// Iteration cap (N_max).
    pub max_iterations: usize,
    /// Weight of the increment penalty, mm^2 per unit^2 of the scaled increments
    /// (0.1 rad, 0.01 m).
    pub smoothing: f64,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            max_iterations: 200,
            smoothing: 1e-4,
        }
    }
}

/// Optimiser scale of each joint: 0.1 rad or 0.01 m per unit, so all variables are O(1).
fn scale(j: usize) -> f64 {
    match KINDS[j] {
        crate::chain::JointKind::Prismatic => 0.01,
        _ => 0.1,
    }
}

struct TcpProblem<'a> {
    chain: &'a ChainGeometry,
    limits: &'a Limits,
    target_mm: Vector3<f64>,
    smoothing: f64,
}

impl TcpProblem<'_> {
    fn posture(&self, u: &[f64]) -> Posture {
        let z: Posture = std::array::from_fn(|j| u[j] * scale(j));
        self.limits.from_increments(&z)
    }

    fn value_grad(&self, u: &[f64]) -> (f64, [f64; N_JOINTS]) {
        let q = self.posture(u);
        let (tcp, jac) = self.chain.tcp_jacobian(&q);
        let err = tcp * 1e3 - self.target_mm;
        // dq/du by forward propagation through the clamps of each group.
        let mut dq = [[0.0; N_JOINTS]; N_JOINTS]; // dq[j][i] = dq_j / du_i
        for members in GROUPS.iter() {
            for (k, &j) in members.iter().enumerate() {
                let [lo, hi] = self.limits.range(j);
                let raw = if k == 0 {
                    u[j] * scale(j)
                } else {
                    q[members[k - 1]] + u[j] * scale(j)
                };
                // The first joint's range is the optimiser's own box bound, so its clamp never
                // acts inside the box; for the others a clamp at the limit passes the derivative
                // of the side the joint can move to (inclusive test), else the optimiser could
                // never leave a limit it starts on.
                if k == 0 || (raw >= lo && raw <= hi) {
                    if k > 0 {
                        dq[j] = dq[members[k - 1]];
                    }
                    dq[j][j] = scale(j);
                }
            }
        }
        let g_q: [f64; N_JOINTS] = std::array::from_fn(|j| 2e3 * jac.column(j).dot(&err));
        let mut f = err.norm_squared();
        let mut g = [0.0; N_JOINTS];
        for i in 0..N_JOINTS {
            g[i] = (0..N_JOINTS).map(|j| g_q[j] * dq[j][i]).sum();
        }
        for members in GROUPS.iter() {
            for &j in &members[1..] {
                f += self.smoothing * u[j] * u[j];
                g[j] += 2.0 * self.smoothing * u[j];
            }
        }
        (f, g)
    }
}

impl CostFunction for TcpProblem<'_> {
    fn evaluate(&self, x: &Vector<f64>, _: &()) -> std::result::Result<f64, Infallible> {
        Ok(self.value_grad(&x.to_vec()).0)
    }
}

impl Gradient for TcpProblem<'_> {
    fn gradient(&self, x: &Vector<f64>, _: &()) -> std::result::Result<Vector<f64>, Infallible> {
        Ok(Vector::from_vec(self.value_grad(&x.to_vec()).1.to_vec()))
    }
}

/// The result of Algorithm 1 for one target.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Match {
    /// Optimised posture (feasible).
    pub posture: Posture,
    /// Remaining TCP distance, m.
    pub error_m: f64,
}

/// Algorithm 1: the feasible posture whose TCP is closest to `target_m`, from `init` (made
/// feasible first).
pub fn match_tcp(
    chain: &ChainGeometry,
    limits: &Limits,
    target_m: &Vector3<f64>,
    init: &Posture,
    cfg: &MatchConfig,
) -> Result<Match> {
    if !target_m.iter().all(|v| v.is_finite()) {
        return Err(SurrogateError::Invalid(format!(
            "target TCP {target_m:?} is not finite"
        )));
    }
    let problem = TcpProblem {
        chain,
        limits,
        target_mm: target_m * 1e3,
        smoothing: cfg.smoothing,
    };
    let z0 = limits.to_increments(&limits.project(init)?);
    let u0: Vec<f64> = (0..N_JOINTS).map(|j| z0[j] / scale(j)).collect();
    let bounds: Vec<(f64, f64)> = limits
        .increment_bounds()
        .iter()
        .enumerate()
        .map(|(j, (a, b))| (a / scale(j), b / scale(j)))
        .collect();
    let config = LBFGSBConfig::<f64>::default()
        .with_bounds(bounds)
        .map_err(|e| SurrogateError::Solver(format!("L-BFGS-B bounds: {e}")))?
        .with_error_mode(LBFGSBErrorMode::Skip);
    let summary = LBFGSB::<f64>::default()
        .process(
            &problem,
            &(),
            Vector::from_vec(u0),
            config,
            LBFGSB::<f64>::default_callbacks().with_terminator(MaxSteps(cfg.max_iterations)),
        )
        .map_err(|e| SurrogateError::Solver(format!("L-BFGS-B: {e:?}")))?;
    let posture = problem.posture(&summary.x.to_vec());
    Ok(Match {
        posture,
        error_m: (chain.tcp(&posture) - target_m).norm(),
    })
}

/// Runs Algorithm 1 for every sample, each from the better of rest and the previous solution
/// (neighbouring grid samples have neighbouring postures).
pub fn match_samples(
    chain: &ChainGeometry,
    limits: &Limits,
    samples: &[FemSample],
    cfg: &MatchConfig,
    mut on_sample: impl FnMut(usize),
) -> Result<Vec<Match>> {
    let mut out: Vec<Match> = Vec::with_capacity(samples.len());
    let rest = limits.project(&[0.0; N_JOINTS])?;
    for (k, s) in samples.iter().enumerate() {
        let t = Vector3::from(s.tcp_m);
        let mut best = match_tcp(chain, limits, &t, &rest, cfg)?;
        if let Some(prev) = out.last() {
            let warm = match_tcp(chain, limits, &t, &prev.posture, cfg)?;
            if warm.error_m < best.error_m {
                best = warm;
            }
        }
        out.push(best);
        on_sample(k);
    }
    Ok(out)
}

/// Group means (theta_x, theta_y, d) of a posture.
pub fn group_means(q: &Posture) -> [f64; 3] {
    std::array::from_fn(|g| GROUPS[g].iter().map(|&j| q[j]).sum::<f64>() / GROUPS[g].len() as f64)
}

/// A regression that stands in for the interpolants of [`ActuationMap`]: f_SP from chamber
/// pressures to a posture and its inverse from group means to pressures. The map projects the
/// posture onto the feasible set and checks inputs itself; implementations only regress.
pub trait Regressor: Send + Sync + std::fmt::Debug {
    /// Short name reported with the map's figures (`mlp`, ...).
    fn name(&self) -> &str;
    /// Raw posture for pressures in kPa (projected by the caller).
    fn posture(&self, pressures_kpa: &[f64; 3]) -> Result<Posture>;
    /// Pressures in kPa for group means (theta_x rad, theta_y rad, d m).
    fn pressures(&self, group_means: &[f64; 3]) -> Result<[f64; 3]>;
}

/// f_SP and its inverse: the stored interpolants, or an external [`Regressor`] when one is set.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ActuationMap {
    /// Pressures (kPa) -> posture.
    pub forward: Rbf,
    /// Group means (rad, rad, m) -> pressures (kPa).
    pub inverse: Rbf,
    /// Limits the forward output is projected onto.
    pub limits: Limits,
    /// A regression used instead of both interpolants (not stored in the model file: it lives
    /// in its own checkpoints and is attached after reading).
    #[serde(skip)]
    pub regressor: Option<Arc<dyn Regressor>>,
}

impl PartialEq for ActuationMap {
    fn eq(&self, other: &Self) -> bool {
        let same_regressor = match (&self.regressor, &other.regressor) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        };
        same_regressor
            && self.forward == other.forward
            && self.inverse == other.inverse
            && self.limits == other.limits
    }
}

impl ActuationMap {
    /// Fits both interpolants to samples and their optimised postures.
    pub fn fit(samples: &[FemSample], matches: &[Match], limits: &Limits) -> Result<Self> {
        let p: Vec<Vec<f64>> = samples.iter().map(|s| s.pressures_kpa.to_vec()).collect();
        let q: Vec<Vec<f64>> = matches.iter().map(|m| m.posture.to_vec()).collect();
        let g: Vec<Vec<f64>> = matches
            .iter()
            .map(|m| group_means(&m.posture).to_vec())
            .collect();
        Ok(ActuationMap {
            forward: Rbf::fit(&p, &q)?,
            inverse: Rbf::fit(&g, &p)?,
            limits: *limits,
            regressor: None,
        })
    }

    /// The same map with `regressor` used for f_SP and its inverse instead of the interpolants.
    pub fn with_regressor(mut self, regressor: Arc<dyn Regressor>) -> Self {
        self.regressor = Some(regressor);
        self
    }

    /// Which regression answers: `rbf` (the stored interpolants) or the regressor's name.
    pub fn regression_name(&self) -> &str {
        self.regressor.as_deref().map_or("rbf", |r| r.name())
    }

    /// f_SP: the feasible posture for chamber pressures in kPa (-20..35; others are an
    /// [`crate::SurrogateError::OutOfRange`] naming the chamber). The regression's output is
    /// projected onto the grouped constraints.
    pub fn posture(&self, pressures_kpa: &[f64; 3]) -> Result<Posture> {
        crate::fem_samples::check_pressures_kpa(pressures_kpa)?;
        let q: Posture = match &self.regressor {
            Some(r) => r.posture(pressures_kpa)?,
            None => {
                let y = self.forward.eval(pressures_kpa);
                std::array::from_fn(|j| y[j])
            }
        };
        self.limits.project(&q)
    }

    /// Inverse of f_SP: pressures in kPa for a posture (through its group means).
    pub fn pressures(&self, q: &Posture) -> Result<[f64; 3]> {
        self.limits.check(q)?;
        let g = group_means(q);
        match &self.regressor {
            Some(r) => r.pressures(&g),
            None => {
                let y = self.inverse.eval(&g);
                Ok([y[0], y[1], y[2]])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A regressor with known outputs: every joint at `value`, pressures = 100 x the means.
    #[derive(Debug)]
    struct Fixed {
        value: f64,
    }

    impl Regressor for Fixed {
        fn name(&self) -> &str {
            "fixed"
        }
        fn posture(&self, _: &[f64; 3]) -> Result<Posture> {
            Ok([self.value; N_JOINTS])
        }
        fn pressures(&self, g: &[f64; 3]) -> Result<[f64; 3]> {
            Ok(g.map(|v| 100.0 * v))
        }
    }

    fn interpolant_map() -> ActuationMap {
        // Postures linear in the pressures: the interpolant reproduces linear data exactly.
        let limits = Limits::default();
        let mut p = vec![];
        let mut q = vec![];
        for a in [-20.0, 0.0, 35.0] {
            for b in [-20.0, 10.0, 35.0] {
                for c in [-20.0, 35.0] {
                    p.push(vec![a, b, c]);
                    let posture: Vec<f64> = (0..N_JOINTS)
                        .map(|j| match KINDS[j] {
                            crate::chain::JointKind::Prismatic => 1e-4 * (a + b + c + 60.0) / 3.0,
                            crate::chain::JointKind::RevoluteX => 1e-4 * (a - b),
                            crate::chain::JointKind::RevoluteY => 1e-4 * (a - c),
                        })
                        .collect();
                    q.push(posture);
                }
            }
        }
        let g: Vec<Vec<f64>> = q
            .iter()
            .map(|q| group_means(&std::array::from_fn(|j| q[j])).to_vec())
            .collect();
        ActuationMap {
            forward: Rbf::fit(&p, &q).unwrap(),
            inverse: Rbf::fit(&g, &p).unwrap(),
            limits,
            regressor: None,
        }
    }

    #[test]
    fn a_regressor_replaces_the_interpolants_and_is_projected() {
        let map = interpolant_map();
        assert_eq!(map.regression_name(), "rbf");
        let q = map.posture(&[10.0, -5.0, 3.0]).unwrap();
        assert!((q[0] - 1.5e-3).abs() < 1e-9, "interpolant posture {q:?}");
        let ext = map.clone().with_regressor(Arc::new(Fixed { value: 0.5 }));
        assert_eq!(ext.regression_name(), "fixed");
        assert!(
            ext != map,
            "a map with a regressor differs from one without"
        );
        // 0.5 rad / 0.5 m are outside the limits: the map projects the regressor's output.
        let q = ext.posture(&[10.0, -5.0, 3.0]).unwrap();
        map.limits.check(&q).unwrap();
        assert!((q[0] - 0.2).abs() < 1e-12 && (q[2] - 0.02).abs() < 1e-12);
        let p = ext.pressures(&q).unwrap();
        let g = group_means(&q);
        for k in 0..3 {
            assert!((p[k] - 100.0 * g[k]).abs() < 1e-12);
        }
        // Inputs are still checked by the map, whatever answers.
        assert!(ext.posture(&[50.0, 0.0, 0.0]).is_err());
        assert!(ext.pressures(&[1.0; N_JOINTS]).is_err());
        // The regressor is not stored: a written and read map answers with the interpolants.
        let back: ActuationMap =
            serde_json::from_str(&serde_json::to_string(&ext).unwrap()).unwrap();
        assert!(back.regressor.is_none() && back.regression_name() == "rbf");
        let (a, b) = (
            back.posture(&[10.0, -5.0, 3.0]).unwrap(),
            map.posture(&[10.0, -5.0, 3.0]).unwrap(),
        );
        for j in 0..N_JOINTS {
            assert!((a[j] - b[j]).abs() < 1e-12);
        }
    }

    #[test]
    fn pressures_and_postures_outside_their_ranges_are_typed_errors() {
        let map = interpolant_map();
        for (p, chamber, value) in [
            ([50.0, 0.0, 0.0], 1, 50.0),
            ([0.0, -20.5, 0.0], 2, -20.5),
            ([0.0, 0.0, 35.01], 3, 35.01),
        ] {
            match map.posture(&p).unwrap_err() {
                crate::SurrogateError::OutOfRange {
                    channel,
                    value: v,
                    lo,
                    hi,
                    unit,
                } => {
                    assert_eq!(channel, format!("chamber {chamber} pressure"));
                    assert_eq!((v, lo, hi, unit), (value, -20.0, 35.0, "kPa"));
                }
                e => panic!("{e}"),
            }
        }
        let e = map.posture(&[0.0, f64::NAN, 0.0]).unwrap_err();
        assert!(
            matches!(e, crate::SurrogateError::NotFinite { .. })
                && e.to_string()
                    .starts_with("chamber 2 pressure is not finite"),
            "{e}"
        );
        // The ends of the range are allowed.
        map.posture(&[-20.0, 35.0, 0.0]).unwrap();
        // The inverse refuses postures outside the limits, naming the joint.
        let mut q = [0.0; N_JOINTS];
        q[1] = -0.3;
        let e = map.pressures(&q).unwrap_err().to_string();
        assert!(
            e.contains("joint 1 (y1, theta_y) = -0.3 rad") && e.contains("[-0.2, 0.2] rad"),
            "{e}"
        );
    }
}
