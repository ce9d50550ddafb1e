//! Force calibration (Ch.4.8.3): both models hold the TCP on a fixed jig at its rest position
//! while the actuation is applied; a component-wise linear fit maps the surrogate's TCP force to
//! the FEM's and is stored with the model.
//!
//! FEM jig: the tip force F (a dead load shared by the top-face nodes, as in `ocm-mor`) that
//! brings the TCP back to its rest position under the chamber pressures, found by Broyden's
//! method from a finite-difference compliance; the robot pushes on the jig with -F. Surrogate jig:
//! the static equilibrium of the position motors (stiffness K, command f_SP(P)) with the TCP
//! pinned, K (q - q*) = J^T F, tcp(q) = x0 (gravity off, as in the FEM); the robot pushes with -F.

use crate::chain::{ChainGeometry, N_JOINTS, Posture};
use crate::{Result, SurrogateError};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use ocm_fem::bellows::Bellows;
use ocm_fem::solve::statics::StaticSolver;
use serde::{Deserialize, Serialize};

/// The surrogate held at `x0` by its TCP with motors of stiffness `stiffness` commanded to
/// `target`: the equilibrium posture and the force of the robot on the jig, N. (The jig's force
/// on the robot is the derivative of the motors' least energy over TCP-preserving postures with
/// respect to the jig position.)
pub fn surrogate_jig(
    chain: &ChainGeometry,
    stiffness: &Posture,
    target: &Posture,
    x0: &Vector3<f64>,
) -> Result<(Posture, Vector3<f64>)> {
    let mut q = [0.0; N_JOINTS];
    let n = N_JOINTS + 3;
    for _ in 0..50 {
        let (tcp, jac) = chain.tcp_jacobian(&q);
        let mut a = DMatrix::zeros(n, n);
        let mut rhs = DVector::zeros(n);
        for j in 0..N_JOINTS {
            a[(j, j)] = stiffness[j];
            rhs[j] = -stiffness[j] * (q[j] - target[j]);
            for k in 0..3 {
                a[(j, N_JOINTS + k)] = -jac[(k, j)];
                a[(N_JOINTS + k, j)] = jac[(k, j)];
            }
        }
        // The multiplier is solved for as a whole (not as an increment) each iteration.
        for k in 0..3 {
            rhs[N_JOINTS + k] = x0[k] - tcp[k];
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
        if step < 1e-13 && (chain.tcp(&q) - x0).norm() < 1e-12 {
            return Ok((q, -f));
        }
    }
    Err(SurrogateError::Solver(
        "surrogate jig: Newton did not converge in 50 iterations".into(),
    ))
}

/// Force of the FEM robot on the jig, N, at chamber pressures in kPa; `x0` is the rest TCP.
pub fn fem_jig_force(
    b: &Bellows,
    pressures_kpa: &[f64; 3],
    x0: &Vector3<f64>,
) -> Result<Vector3<f64>> {
    let mut bb = b.clone();
    let mut solver = StaticSolver::new(&bb.model)?;
    // Tip loads of a few newtons buckle the path from rest in one step: load-step it.
    solver.load_steps = 4;
    let mut tcp_at = |f: &Vector3<f64>| -> Result<Vector3<f64>> {
        bb.model.point_forces = tip_forces(&bb.top_face, f);
        let (st, _) = bb.solve_kpa(&mut solver, pressures_kpa)?;
        Ok(Vector3::from(bb.state_of(&st).tcp_m))
    };
    let mut f = Vector3::zeros();
    let mut r = tcp_at(&f)? - x0;
    // Compliance by finite differences (0.5 N), then Broyden updates of its inverse.
    let h = 0.5;
    let mut c = Matrix3::zeros();
    for k in 0..3 {
        let mut e = Vector3::zeros();
        e[k] = h;
        c.set_column(k, &((tcp_at(&e)? - x0 - r) / h));
    }
    let mut c_inv = c
        .try_inverse()
        .ok_or_else(|| SurrogateError::Solver("FEM jig: singular compliance".into()))?;
    for _ in 0..30 {
        if r.norm() < 1e-6 {
            return Ok(-f);
        }
        let mut df = -(c_inv * r);
        // Trust region of 2 N per step: the compliance stiffens far from rest.
        if df.norm() > 2.0 {
            df *= 2.0 / df.norm();
        }
        f += df;
        let r_new = tcp_at(&f)? - x0;
        let dr = r_new - r;
        let denom = df.dot(&(c_inv * dr));
        if denom.abs() > 1e-30 {
            c_inv += (df - c_inv * dr) * (df.transpose() * c_inv) / denom;
        }
        r = r_new;
    }
    if r.norm() < 1e-6 {
        Ok(-f)
    } else {
        Err(SurrogateError::Solver(format!(
            "FEM jig at {pressures_kpa:?} kPa: TCP still {:.3} mm off after 30 Broyden steps",
            r.norm() * 1e3
        )))
    }
}

fn tip_forces(top_face: &[usize], f: &Vector3<f64>) -> Vec<(usize, Vector3<f64>)> {
    let share = f / top_face.len().max(1) as f64;
    top_face.iter().map(|&i| (i, share)).collect()
}

/// Component-wise linear map F_fem,k = slope_k F_sur,k + offset_k.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceCalibration {
    /// Slopes per component.
    pub slope: [f64; 3],
    /// Offsets per component, N.
    pub offset_n: [f64; 3],
    /// RMSE of the fit per component, N.
    pub rmse_n: [f64; 3],
    /// Calibration samples.
    pub samples: usize,
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
        let (mut slope, mut offset, mut rmse) = ([0.0; 3], [0.0; 3], [0.0; 3]);
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
        }
        Ok(ForceCalibration {
            slope,
            offset_n: offset,
            rmse_n: rmse,
            samples: surrogate_n.len(),
        })
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
            assert!(c.rmse_n[k] < 1e-12);
        }
        let v = c.apply(&Vector3::new(1.0, 2.0, 3.0));
        assert!((v - Vector3::new(2.1, 0.0, 9.0)).norm() < 1e-12);
        assert!(ForceCalibration::fit(&sur[..1], &fem[..1]).is_err());
        let flat = vec![[1.0, 2.0, 3.0]; 4];
        assert!(ForceCalibration::fit(&flat, &fem[..4]).is_err());
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
        let (_, zero) = surrogate_jig(&g, &k, &[0.0; N_JOINTS], &x0).unwrap();
        assert!(zero.norm() < 1e-9);
        let target: Posture = [
            0.05, -0.03, 0.004, 0.05, -0.03, 0.004, 0.05, -0.03, 0.004, 0.05, -0.03,
        ];
        let (q, f) = surrogate_jig(&g, &k, &target, &x0).unwrap();
        assert!((g.tcp(&q) - x0).norm() < 1e-12);
        // The jig's force on the robot (-f) is the gradient of the least motor energy with
        // respect to the jig position: check it by central differences.
        let energy = |x: &Vector3<f64>| {
            let (q, _) = surrogate_jig(&g, &k, &target, x).unwrap();
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
                "axis {a}: {de} vs {}",
                -f[a]
            );
        }
        // The motors push the TCP where the free chain would go: the robot's force on the jig
        // points from x0 towards tcp(q*).
        let free = g.tcp(&target) - x0;
        assert!(f.dot(&free) > 0.0, "{f:?} vs {free:?}");
    }
}
