//! Force calibration (Ch.4.8.3): the robot pushes on a fixed jig at its rest pose while the
//! actuation is applied; a component-wise linear fit maps the surrogate's TCP force to the FEM's
//! and is stored with the model.
//!
//! FEM jig: the rigid top frame's nodes are clamped at rest (the load cell of Fig 4.13 fixes the
//! end effector) and the chamber pressures applied; the robot's force on the jig is the reaction
//! of those nodes. A clamp keeps the static problem well posed at every pressure, so the whole
//! range -20..35 kPa solves (a dead tip load that only holds the TCP point lets the pressurised
//! bellows buckle about it towards the ends of the range). Surrogate jig: the static equilibrium
//! of the position motors (stiffness K, command f_SP(P), gravity off as in the FEM) with the TCP
//! held, K (q - q*) = C^T lambda; the first three multipliers are the jig's force on the robot.
//! The calibration holds the surrogate by its TCP point ([`JigHold::TcpPinned`], how its TCP
//! sensor meets the world); the README gives the fit with the plate clamped as well.

use crate::chain::{ChainGeometry, JointKind, KINDS, N_JOINTS, Posture};
use crate::{Result, SurrogateError};
use nalgebra::{DMatrix, DVector, SMatrix, Vector3};
use ocm_fem::bellows::Bellows;
use ocm_fem::model::State;
use ocm_fem::solve::statics::StaticSolver;
use serde::{Deserialize, Serialize};

/// How the surrogate is held on the jig.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum JigHold {
    /// The TCP point is held; the plate may turn (a point sensor, like the scene's TCP sphere).
    #[default]
    TcpPinned,
    /// The TCP is held and the plate kept level (the rest orientation; the chain has no joint
    /// about the plate normal, so these five constraints fix the plate).
    PlateClamped,
}

impl JigHold {
    fn constraints(self) -> usize {
        match self {
            JigHold::TcpPinned => 3,
            JigHold::PlateClamped => 5,
        }
    }
}

/// The surrogate with its TCP pinned at `x0` ([`JigHold::TcpPinned`], the hold the force
/// calibration uses): see [`surrogate_jig_held`].
pub fn surrogate_jig(
    chain: &ChainGeometry,
    stiffness: &Posture,
    target: &Posture,
    x0: &Vector3<f64>,
) -> Result<(Posture, Vector3<f64>)> {
    surrogate_jig_held(chain, stiffness, target, x0, JigHold::TcpPinned)
}

/// The surrogate held on the jig at `x0` as `hold` says, motors of stiffness `stiffness`
/// commanded to `target`: the equilibrium posture and the force of the robot on the jig, N.
/// (The jig's force on the robot is the derivative of the motors' least energy over held
/// postures with respect to the jig position.)
pub fn surrogate_jig_held(
    chain: &ChainGeometry,
    stiffness: &Posture,
    target: &Posture,
    x0: &Vector3<f64>,
    hold: JigHold,
) -> Result<(Posture, Vector3<f64>)> {
    const NC: usize = 5;
    let nc = hold.constraints();
    let mut q = [0.0; N_JOINTS];
    let n = N_JOINTS + nc;
    for _ in 0..50 {
        let (frames, tcp) = chain.joint_frames(&q);
        let (_, jac) = chain.tcp_jacobian(&q);
        let normal = tcp.r.column(2).into_owned();
        // Rows: TCP x, y, z; plate normal x, y. A rotation about the world axis a turns the
        // normal by a x n; extensions do not turn it.
        let mut cj = SMatrix::<f64, NC, N_JOINTS>::zeros();
        for j in 0..N_JOINTS {
            let turn = match KINDS[j] {
                JointKind::RevoluteX => frames[j].r.column(0).cross(&normal),
                JointKind::RevoluteY => frames[j].r.column(1).cross(&normal),
                JointKind::Prismatic => Vector3::zeros(),
            };
            for k in 0..3 {
                cj[(k, j)] = jac[(k, j)];
            }
            cj[(3, j)] = turn.x;
            cj[(4, j)] = turn.y;
        }
        let c = [
            tcp.p.x - x0.x,
            tcp.p.y - x0.y,
            tcp.p.z - x0.z,
            normal.x,
            normal.y,
        ];
        let mut a = DMatrix::zeros(n, n);
        let mut rhs = DVector::zeros(n);
        for j in 0..N_JOINTS {
            a[(j, j)] = stiffness[j];
            rhs[j] = -stiffness[j] * (q[j] - target[j]);
            for k in 0..nc {
                a[(j, N_JOINTS + k)] = -cj[(k, j)];
                a[(N_JOINTS + k, j)] = cj[(k, j)];
            }
        }
        // The multipliers are solved for as a whole (not as increments) each iteration.
        for k in 0..nc {
            rhs[N_JOINTS + k] = -c[k];
        }
        let sol = a
            .lu()
            .solve(&rhs)
            .ok_or_else(|| SurrogateError::Solver("surrogate jig: singular KKT system".into()))?;
        let step: f64 = (0..N_JOINTS).map(|j| sol[j] * sol[j]).sum::<f64>().sqrt();
        for j in 0..N_JOINTS {
            q[j] += sol[j];
        }
        let f = Vector3::new(sol[N_JOINTS], sol[N_JOINTS + 1], sol[N_JOINTS + 2]);
        let (_, tcp) = chain.joint_frames(&q);
        let tilt = match hold {
            JigHold::TcpPinned => 0.0,
            JigHold::PlateClamped => tcp.r[(0, 2)].abs() + tcp.r[(1, 2)].abs(),
        };
        let off = (tcp.p - x0).norm() + tilt;
        if step < 1e-13 && off < 1e-12 {
            return Ok((q, -f));
        }
    }
    Err(SurrogateError::Solver(
        "surrogate jig: Newton did not converge in 50 iterations".into(),
    ))
}

/// Forces of the FEM robot on a jig that clamps its rigid top frame at rest, N, one per pressure
/// triple (kPa, solved in order, each continued from the previous equilibrium; a state that does
/// not follow is solved again from rest in load steps). The jig's force is the reaction of the
/// clamped top-frame nodes, the sum of f_ext - f_int over them. `on_point` counts finished states.
pub fn fem_clamped_jig_forces(
    b: &Bellows,
    pressures_kpa: &[[f64; 3]],
    mut on_point: impl FnMut(usize),
) -> Result<Vec<Vector3<f64>>> {
    let mut model = b.model.clone();
    let zt = b.config.rigid_top_above_mm * 1e-3;
    let clamped = model.fix_nodes(|p| p.z >= zt);
    if clamped == 0 {
        return Err(SurrogateError::Invalid(
            "FEM jig: no top-frame node to clamp".into(),
        ));
    }
    let top: Vec<usize> = (0..model.num_nodes())
        .filter(|&i| model.rest[i].z >= zt)
        .collect();
    let mut solver = StaticSolver::new(&model)?;
    let mut state = State::at_rest(&model);
    let mut prev = b.loads_kpa(&[0.0; 3]);
    let mut out = Vec::with_capacity(pressures_kpa.len());
    for (k, p) in pressures_kpa.iter().enumerate() {
        crate::fem_samples::check_pressures_kpa(p)?;
        let to = b.loads_kpa(p);
        if solver.continue_to(&model, &mut state, &prev, &to).is_err() {
            state = State::at_rest(&model);
            solver.load_steps = 8;
            let r = solver.continue_to(&model, &mut state, &b.loads_kpa(&[0.0; 3]), &to);
            solver.load_steps = 1;
            r.map_err(|e| {
                SurrogateError::Solver(format!("FEM jig at {p:?} kPa (state {k}): {e}"))
            })?;
        }
        prev = to.clone();
        let ev = model.evaluate(&solver.pattern, &state.x, &to, 1.0, false)?;
        let net = |i: usize| Vector3::from_fn(|d, _| ev.f_ext[3 * i + d] - ev.f_int[3 * i + d]);
        out.push(top.iter().map(|&i| net(i)).sum());
        on_point(k + 1);
    }
    Ok(out)
}

/// Component-wise linear map F_fem,k = slope_k F_sur,k + offset_k.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForceCalibration {
    /// Slopes per component.
    pub slope: [f64; 3],
    /// Offsets per component, N.
    pub offset_n: [f64; 3],
    /// RMSE of the fit per component on the fit samples, N.
    pub rmse_n: [f64; 3],
    /// Coefficient of determination of the fit per component on the fit samples.
    #[serde(default)]
    pub r2: [f64; 3],
    /// Calibration samples.
    pub samples: usize,
    /// RMSE per component on held-out samples (not used to fit), N; zero when there are none.
    #[serde(default)]
    pub held_out_rmse_n: [f64; 3],
    /// Held-out samples.
    #[serde(default)]
    pub held_out_samples: usize,
    /// How the surrogate was held on the jig.
    #[serde(default)]
    pub surrogate_hold: JigHold,
    /// The fit's error over the pairs (fit and held-out) inside each of [`REPORT_RANGES_KPA`].
    #[serde(default)]
    pub by_range: Vec<RangeError>,
}

/// Nested pressure boxes over which the force fit's error is reported, kPa: the range the
/// earlier point-load jig covered, a symmetric one, and the lab's whole range.
pub const REPORT_RANGES_KPA: [[f64; 2]; 3] = [[-10.0, 10.0], [-20.0, 20.0], [-20.0, 35.0]];

/// The calibrated fit's error over the pairs whose every chamber pressure lies in one range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangeError {
    /// The range of every chamber's pressure, kPa.
    pub range_kpa: [f64; 2],
    /// Pairs inside it.
    pub samples: usize,
    /// RMSE per component of the calibrated surrogate force against the FEM's, N (zero when
    /// there are no pairs).
    pub rmse_n: [f64; 3],
    /// Span (largest less smallest) per component of the FEM's force over those pairs, N.
    pub fem_span_n: [f64; 3],
    /// Held-out pairs (not used to fit) among them.
    pub held_out_samples: usize,
    /// RMSE per component over those held-out pairs alone, N (zero when there are none).
    pub held_out_rmse_n: [f64; 3],
}

/// `n` seeded random pressure triples (kPa), the k-th uniform in `REPORT_RANGES_KPA[k % 3]`, so
/// every reported range holds about a third of them (the held-out force pressures).
pub fn nested_random_pressures(n: usize, seed: u64) -> Vec<[f64; 3]> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|k| {
            let [lo, hi] = REPORT_RANGES_KPA[k % REPORT_RANGES_KPA.len()];
            [0; 3].map(|_| rng.random_range(lo..hi))
        })
        .collect()
}

impl ForceCalibration {
    /// Least-squares fit of each component (at least two samples with distinct surrogate forces).
    pub fn fit(surrogate_n: &[[f64; 3]], fem_n: &[[f64; 3]]) -> Result<Self> {
        if surrogate_n.len() != fem_n.len() || surrogate_n.len() < 2 {
            return Err(SurrogateError::Invalid(format!(
                "force calibration needs >= 2 paired samples, got {} and {}",
                surrogate_n.len(),
                fem_n.len()
            )));
        }
        let n = surrogate_n.len() as f64;
        let (mut slope, mut offset, mut rmse, mut r2) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..3 {
            let mx = surrogate_n.iter().map(|f| f[k]).sum::<f64>() / n;
            let my = fem_n.iter().map(|f| f[k]).sum::<f64>() / n;
            let sxx: f64 = surrogate_n.iter().map(|f| (f[k] - mx).powi(2)).sum();
            let sxy: f64 = surrogate_n
                .iter()
                .zip(fem_n)
                .map(|(a, b)| (a[k] - mx) * (b[k] - my))
                .sum();
            if !(sxx > 1e-24) {
                return Err(SurrogateError::Invalid(format!(
                    "force calibration: surrogate force component {k} does not vary"
                )));
            }
            slope[k] = sxy / sxx;
            offset[k] = my - slope[k] * mx;
            rmse[k] = (surrogate_n
                .iter()
                .zip(fem_n)
                .map(|(a, b)| (slope[k] * a[k] + offset[k] - b[k]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
            let syy: f64 = fem_n.iter().map(|f| (f[k] - my).powi(2)).sum();
            r2[k] = if syy > 0.0 {
                1.0 - n * rmse[k] * rmse[k] / syy
            } else {
                1.0
            };
        }
        Ok(ForceCalibration {
            slope,
            offset_n: offset,
            rmse_n: rmse,
            r2,
            samples: surrogate_n.len(),
            held_out_rmse_n: [0.0; 3],
            held_out_samples: 0,
            surrogate_hold: JigHold::TcpPinned,
            by_range: vec![],
        })
    }

    /// Records the fit's error over the pairs inside each of `ranges` (kPa; a pair is inside
    /// when all three chamber pressures are); pairs from index `fit` on are the held-out ones.
    pub fn set_range_errors(
        &mut self,
        pressures_kpa: &[[f64; 3]],
        surrogate_n: &[[f64; 3]],
        reference_n: &[[f64; 3]],
        fit: usize,
        ranges: &[[f64; 2]],
    ) {
        let rmse = |sur: &[[f64; 3]], fem: &[[f64; 3]]| {
            if fem.is_empty() {
                [0.0; 3]
            } else {
                self.rmse_on(sur, fem)
            }
        };
        self.by_range = ranges
            .iter()
            .map(|&[lo, hi]| {
                let inside: Vec<(bool, [f64; 3], [f64; 3])> = pressures_kpa
                    .iter()
                    .zip(surrogate_n.iter().zip(reference_n))
                    .enumerate()
                    .filter(|(_, (p, _))| p.iter().all(|&v| v >= lo && v <= hi))
                    .map(|(i, (_, (s, f)))| (i >= fit, *s, *f))
                    .collect();
                let sur: Vec<[f64; 3]> = inside.iter().map(|t| t.1).collect();
                let fem: Vec<[f64; 3]> = inside.iter().map(|t| t.2).collect();
                let (hs, hf): (Vec<[f64; 3]>, Vec<[f64; 3]>) =
                    inside.iter().filter(|t| t.0).map(|t| (t.1, t.2)).unzip();
                let span = std::array::from_fn(|k| {
                    let (a, b) = fem
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), f| {
                            (a.min(f[k]), b.max(f[k]))
                        });
                    if fem.is_empty() { 0.0 } else { b - a }
                });
                RangeError {
                    range_kpa: [lo, hi],
                    samples: fem.len(),
                    rmse_n: rmse(&sur, &fem),
                    fem_span_n: span,
                    held_out_samples: hf.len(),
                    held_out_rmse_n: rmse(&hs, &hf),
                }
            })
            .collect();
    }

    /// RMSE per component of the calibrated surrogate force against reference forces, N.
    pub fn rmse_on(&self, surrogate_n: &[[f64; 3]], reference_n: &[[f64; 3]]) -> [f64; 3] {
        let n = surrogate_n.len().min(reference_n.len()).max(1) as f64;
        std::array::from_fn(|k| {
            (surrogate_n
                .iter()
                .zip(reference_n)
                .map(|(a, b)| (self.slope[k] * a[k] + self.offset_n[k] - b[k]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        })
    }

    /// Records the RMSE on held-out pairs.
    pub fn set_held_out(&mut self, surrogate_n: &[[f64; 3]], reference_n: &[[f64; 3]]) {
        self.held_out_samples = surrogate_n.len().min(reference_n.len());
        self.held_out_rmse_n = if self.held_out_samples == 0 {
            [0.0; 3]
        } else {
            self.rmse_on(surrogate_n, reference_n)
        };
    }

    /// The calibrated (FEM-equivalent) force of a surrogate TCP force, N.
    pub fn apply(&self, surrogate_n: &Vector3<f64>) -> Vector3<f64> {
        Vector3::from_fn(|k, _| self.slope[k] * surrogate_n[k] + self.offset_n[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_fit_recovers_known_maps() {
        let sur: Vec<[f64; 3]> = (0..7)
            .map(|i| {
                let t = i as f64;
                [t - 3.0, 0.5 * t * t - 2.0, (0.7 * t).sin()]
            })
            .collect();
        let fem: Vec<[f64; 3]> = sur
            .iter()
            .map(|f| [2.0 * f[0] + 0.1, -0.5 * f[1] + 1.0, 3.0 * f[2]])
            .collect();
        let c = ForceCalibration::fit(&sur, &fem).unwrap();
        for (k, (s, o)) in [(2.0, 0.1), (-0.5, 1.0), (3.0, 0.0)].iter().enumerate() {
            assert!((c.slope[k] - s).abs() < 1e-12 && (c.offset_n[k] - o).abs() < 1e-12);
            assert!(c.rmse_n[k] < 1e-12 && (c.r2[k] - 1.0).abs() < 1e-12);
        }
        // Held-out pairs whose reference is off by 0.3 N in x only.
        let mut c = c;
        let shifted: Vec<[f64; 3]> = fem.iter().map(|f| [f[0] + 0.3, f[1], f[2]]).collect();
        c.set_held_out(&sur, &shifted);
        assert_eq!(c.held_out_samples, sur.len());
        assert!((c.held_out_rmse_n[0] - 0.3).abs() < 1e-12);
        assert!(c.held_out_rmse_n[1] < 1e-12 && c.held_out_rmse_n[2] < 1e-12);
        // Noise that the line cannot follow lowers R^2 below one.
        let noisy: Vec<[f64; 3]> = fem
            .iter()
            .enumerate()
            .map(|(i, f)| [f[0] + if i % 2 == 0 { 0.5 } else { -0.5 }, f[1], f[2]])
            .collect();
        let n = ForceCalibration::fit(&sur, &noisy).unwrap();
        assert!(
            n.r2[0] < 0.99 && n.r2[0] > 0.0 && n.rmse_n[0] > 0.4,
            "{n:?}"
        );
        let v = c.apply(&Vector3::new(1.0, 2.0, 3.0));
        assert!((v - Vector3::new(2.1, 0.0, 9.0)).norm() < 1e-12);
        assert!(ForceCalibration::fit(&sur[..1], &fem[..1]).is_err());
        let flat = vec![[1.0, 2.0, 3.0]; 4];
        assert!(ForceCalibration::fit(&flat, &fem[..4]).is_err());
    }

    #[test]
    fn range_errors_count_only_the_pairs_inside_each_range() {
        // FEM = 2 x surrogate exactly inside -10..10 kPa, 1 N more in x outside it.
        let p = [
            [0.0, 5.0, -10.0],
            [9.0, -3.0, 2.0],
            [15.0, 0.0, 0.0],
            [-20.0, 30.0, 35.0],
        ];
        let sur = [
            [1.0, 2.0, 3.0],
            [-1.0, 0.5, 4.0],
            [2.0, 1.0, 1.0],
            [3.0, -2.0, 5.0],
        ];
        let fem: Vec<[f64; 3]> = p
            .iter()
            .zip(&sur)
            .map(|(p, s)| {
                let off = if p.iter().all(|v: &f64| v.abs() <= 10.0) {
                    0.0
                } else {
                    1.0
                };
                [2.0 * s[0] + off, 2.0 * s[1], 2.0 * s[2]]
            })
            .collect();
        let mut c = ForceCalibration::fit(&sur[..2], &fem[..2]).unwrap();
        c.set_range_errors(&p, &sur, &fem, 2, &REPORT_RANGES_KPA);
        let r = &c.by_range;
        assert_eq!(r.iter().map(|r| r.samples).collect::<Vec<_>>(), [2, 3, 4]);
        assert_eq!(
            r.iter().map(|r| r.held_out_samples).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        assert_eq!(r[0].held_out_rmse_n, [0.0; 3]);
        assert!((r[1].held_out_rmse_n[0] - 1.0).abs() < 1e-12);
        assert!(r[0].rmse_n.iter().all(|&e| e < 1e-12), "{r:?}");
        assert!(
            (r[0].fem_span_n[0] - 4.0).abs() < 1e-12 && (r[0].fem_span_n[2] - 2.0).abs() < 1e-12
        );
        assert!(
            (r[1].rmse_n[0] - (1.0f64 / 3.0).sqrt()).abs() < 1e-12,
            "{r:?}"
        );
        assert!((r[2].rmse_n[0] - 0.5f64.sqrt()).abs() < 1e-12 && r[2].rmse_n[1] < 1e-12);
        c.set_range_errors(&p, &sur, &fem, 2, &[[20.0, 25.0]]);
        assert_eq!(c.by_range[0].samples, 0);
        assert_eq!(c.by_range[0].rmse_n, [0.0; 3]);
        // The held-out draw fills every range in turn and stays inside it.
        let h = nested_random_pressures(9, 3);
        for (k, t) in h.iter().enumerate() {
            let [lo, hi] = REPORT_RANGES_KPA[k % 3];
            assert!(t.iter().all(|&v| v >= lo && v < hi), "{k}: {t:?}");
        }
    }

    #[test]
    fn surrogate_jig_force_satisfies_equilibrium_and_vanishes_at_rest() {
        let g = ChainGeometry {
            base_height_m: 0.029,
            segment_length_m: 0.0286,
            tcp_offset_m: 0.047,
            link_radius_m: 0.074,
            base_radius_m: 0.067,
            top_radius_m: 0.083,
            top_thickness_m: 0.0195,
            link_mass_kg: 0.117,
            dummy_mass_kg: 1e-5,
        };
        let k: Posture = std::array::from_fn(|j| if j % 3 == 2 { 5000.0 } else { 50.0 });
        let x0 = g.tcp(&[0.0; N_JOINTS]);
        let target: Posture = [
            0.05, -0.03, 0.004, 0.06, -0.035, 0.004, 0.07, -0.03, 0.003, 0.065, -0.025,
        ];
        for hold in [JigHold::TcpPinned, JigHold::PlateClamped] {
            let (_, zero) = surrogate_jig_held(&g, &k, &[0.0; N_JOINTS], &x0, hold).unwrap();
            assert!(zero.norm() < 1e-9);
            let (q, f) = surrogate_jig_held(&g, &k, &target, &x0, hold).unwrap();
            let (_, plate) = g.joint_frames(&q);
            assert!((plate.p - x0).norm() < 1e-12);
            if hold == JigHold::PlateClamped {
                assert!(plate.r[(0, 2)].abs() + plate.r[(1, 2)].abs() < 1e-12);
            }
            // The jig's force on the robot (-f) is the gradient of the least motor energy with
            // respect to the jig position: check it by central differences.
            let energy = |x: &Vector3<f64>| {
                let (q, _) = surrogate_jig_held(&g, &k, &target, x, hold).unwrap();
                (0..N_JOINTS)
                    .map(|j| 0.5 * k[j] * (q[j] - target[j]).powi(2))
                    .sum::<f64>()
            };
            let h = 1e-6;
            for a in 0..3 {
                let mut dx = Vector3::zeros();
                dx[a] = h;
                let de = (energy(&(x0 + dx)) - energy(&(x0 - dx))) / (2.0 * h);
                assert!(
                    (de + f[a]).abs() < 1e-4 * (1.0 + f.norm()),
                    "{hold:?} axis {a}: {de} vs {}",
                    -f[a]
                );
            }
        }
        let (_, f) = surrogate_jig(&g, &k, &target, &x0).unwrap();
        // The motors push the TCP where the free chain would go: the robot's force on the jig
        // points from x0 towards tcp(q*).
        let free = g.tcp(&target) - x0;
        assert!(f.dot(&free) > 0.0, "{f:?} vs {free:?}");
    }
}
