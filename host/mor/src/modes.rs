//! Natural vibration modes of the full FEM at rest, and enrichment of a POD basis with them.
//!
//! A POD basis of displacement snapshots is optimal in the Euclidean norm of the displacements,
//! not in the energy norm: shapes of small amplitude but large strain energy (how the bellows'
//! walls flex while the top plate's inertia loads them) are truncated first, and the Galerkin
//! model then rings too stiffly after an input step (the crate README measures +18% on the
//! third mode at rank 48). Appending the lowest modes of the linearised full model gives the
//! reduced model those frequencies exactly at rest; on the held-out bellows trajectories that
//! helps no more than as many extra POD modes (crate README: the error sits in the viscous steps
//! after pressure jumps, not in the rest frequencies).
//!
//! The modes solve K phi = omega^2 M phi on the solver's reduced DOFs (free node DOFs plus six
//! per rigid body, mass T^T M T, tangent at rest and zero pressure) by subspace iteration with
//! the sparse factor of K, and are returned as nodal displacements (rigid bodies moved by their
//! linearised motion v + theta x r at rest).

use crate::{MorError, Result};
use nalgebra::{DMatrix, DVector, SymmetricEigen, Vector3};
use ocm_fem::model::{Loads, Model, Pattern};
use ocm_fem::solve::linear::SparseSolver;

/// Lowest natural modes of a model at rest.
#[derive(Debug, Clone)]
pub struct RestModes {
    /// Natural frequencies, Hz, ascending.
    pub frequencies_hz: Vec<f64>,
    /// Mode shapes as nodal displacements (3N x count), mass-normalised (phi^T M phi = 1).
    pub shapes: DMatrix<f64>,
}

/// y = A x for the CSC values `vals` of `pat`.
fn spmv(pat: &Pattern, vals: &[f64], x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for j in 0..x.len() {
        for p in pat.col_ptr[j]..pat.col_ptr[j + 1] {
            y[pat.row_idx[p]] += vals[p] * x[j];
        }
    }
    y
}

/// Eigenpairs of the dense symmetric pencil (k, m), m positive definite, ascending; the vectors
/// are m-orthonormal.
pub fn pencil(k: &DMatrix<f64>, m: &DMatrix<f64>) -> Result<(Vec<f64>, DMatrix<f64>)> {
    let l = m
        .clone()
        .cholesky()
        .ok_or_else(|| MorError::Solve("mass matrix is not positive definite".into()))?
        .l();
    let li = l
        .try_inverse()
        .ok_or_else(|| MorError::Solve("singular mass factor".into()))?;
    let a = &li * k * li.transpose();
    let eig = SymmetricEigen::new((&a + a.transpose()) * 0.5);
    let mut idx: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    idx.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let vecs = li.transpose() * &eig.eigenvectors;
    let vals = idx.iter().map(|&i| eig.eigenvalues[i]).collect();
    Ok((
        vals,
        DMatrix::from_fn(vecs.nrows(), idx.len(), |r, c| vecs[(r, idx[c])]),
    ))
}

/// Frequency in Hz of an eigenvalue omega^2.
pub fn hz(lambda: f64) -> f64 {
    lambda.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)
}

/// The linearised full model at rest on the solver's reduced DOFs: tangent, mass and the sparse
/// factor of the tangent.
struct RestOperator<'a> {
    model: &'a Model,
    pat: Pattern,
    x0: Vec<f64>,
    kv: Vec<f64>,
    mv: Vec<f64>,
    solver: SparseSolver,
}

impl<'a> RestOperator<'a> {
    fn new(model: &'a Model) -> Result<Self> {
        Self::shifted(model, 0.0, 1.0)
    }

    /// The operator whose factor is `mass_coeff` M + `stiffness_coeff` K (K at rest).
    fn shifted(model: &'a Model, mass_coeff: f64, stiffness_coeff: f64) -> Result<Self> {
        let pressures = vec![0.0; model.cavities.len()];
        Self::shifted_at(
            model,
            model.rest_dofs(),
            &pressures,
            mass_coeff,
            stiffness_coeff,
        )
    }

    /// [`Self::shifted`] with K the tangent (internal minus pressure load) at positions `x0`.
    fn shifted_at(
        model: &'a Model,
        x0: Vec<f64>,
        pressures_pa: &[f64],
        mass_coeff: f64,
        stiffness_coeff: f64,
    ) -> Result<Self> {
        let pat = Pattern::new(model)?;
        let loads = Loads {
            pressures_pa: pressures_pa.to_vec(),
        };
        let kv = model
            .evaluate(&pat, &x0, &loads, 1.0, true)?
            .tangent
            .ok_or_else(|| MorError::Solve("the model gave no tangent".into()))?;
        let mv = model.mass_values(&pat);
        let mut solver =
            SparseSolver::new(pat.num_free(), pat.col_ptr.clone(), pat.row_idx.clone());
        if mass_coeff == 0.0 && stiffness_coeff == 1.0 {
            solver.factorize(&kv)?;
        } else {
            let jv: Vec<f64> = kv
                .iter()
                .zip(&mv)
                .map(|(k, m)| stiffness_coeff * k + mass_coeff * m)
                .collect();
            solver.factorize(&jv)?;
        }
        Ok(RestOperator {
            model,
            pat,
            x0,
            kv,
            mv,
            solver,
        })
    }

    /// Nodal displacements of reduced coordinates `z` (rigid bodies: v + theta x r at `x0`).
    fn to_full(&self, z: &[f64]) -> Vec<f64> {
        let mut u = vec![0.0; self.x0.len()];
        for (j, &d) in self.pat.dof_of.iter().enumerate() {
            u[d] = z[j];
        }
        let centers = self.pat.body_centers(&self.x0);
        for (bd, c) in self.pat.bodies.iter().zip(&centers) {
            let v = Vector3::new(z[bd.first], z[bd.first + 1], z[bd.first + 2]);
            let th = Vector3::new(z[bd.first + 3], z[bd.first + 4], z[bd.first + 5]);
            for &i in &self.model.rigid_bodies[bd.body].nodes {
                let xi = Vector3::new(self.x0[3 * i], self.x0[3 * i + 1], self.x0[3 * i + 2]);
                let ui = v + th.cross(&(xi - c));
                u[3 * i..3 * i + 3].copy_from_slice(ui.as_slice());
            }
        }
        u
    }

    /// The static response K^-1 T^T f to a nodal load `f` (3N), as nodal displacements.
    fn static_response(&self, f: &[f64]) -> Result<Vec<f64>> {
        let mut z = self.pat.reduce(&self.x0, f);
        self.solver.solve_factored(&mut z)?;
        Ok(self.to_full(&z))
    }
}

/// The `count` lowest modes of `model` at rest (zero pressure) by subspace iteration.
pub fn rest_modes(model: &Model, count: usize) -> Result<RestModes> {
    if count == 0 {
        return Err(MorError::Invalid("asked for zero modes".into()));
    }
    let op = RestOperator::new(model)?;
    let (pat, kv, mv) = (&op.pat, &op.kv, &op.mv);
    let n = pat.num_free();
    if count > n {
        return Err(MorError::Invalid(format!(
            "asked for {count} modes of a model with {n} DOFs"
        )));
    }
    // Block size with a guard band: the convergence rate of mode i is lambda_i / lambda_{p+1}.
    let p = (2 * count).max(count + 8).min(n);
    let mut x = DMatrix::<f64>::from_fn(n, p, |i, j| {
        (((i * 7919 + j * 104_729 + 17) % 1009) as f64 / 1009.0) - 0.5
    });
    let mut lam = vec![f64::INFINITY; p];
    let mut converged = false;
    for _ in 0..200 {
        let mut y = DMatrix::<f64>::zeros(n, p);
        let (mut ky, mut my) = (DMatrix::<f64>::zeros(n, p), DMatrix::<f64>::zeros(n, p));
        for j in 0..p {
            let mut col = spmv(pat, mv, x.column(j).as_slice());
            op.solver.solve_factored(&mut col)?;
            ky.set_column(j, &DVector::from_vec(spmv(pat, kv, &col)));
            my.set_column(j, &DVector::from_vec(spmv(pat, mv, &col)));
            y.set_column(j, &DVector::from_vec(col));
        }
        let kr = y.transpose() * &ky;
        let mr = y.transpose() * &my;
        let (vals, vecs) = pencil(&kr, &mr)?;
        x = &y * vecs;
        let change = (0..count)
            .map(|i| ((vals[i] - lam[i]) / vals[i]).abs())
            .fold(0.0, f64::max);
        lam = vals;
        if change < 1e-12 {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(MorError::Solve(
            "subspace iteration for the rest modes did not converge in 200 sweeps".into(),
        ));
    }
    let mut shapes = DMatrix::<f64>::zeros(op.x0.len(), count);
    for k in 0..count {
        shapes.set_column(k, &DVector::from_vec(op.to_full(x.column(k).as_slice())));
    }
    Ok(RestModes {
        frequencies_hz: lam[..count].iter().map(|&l| hz(l)).collect(),
        shapes,
    })
}

/// Static responses at rest to the unit loads of the inputs: 1 Pa in each cavity alone (the
/// follower load at the rest geometry), then 1 N along x, y and z shared by `tip_nodes`; nodal
/// displacements, 3N x (cavities + 3), m per Pa and m per N.
pub fn static_shapes(model: &Model, tip_nodes: &[usize]) -> Result<DMatrix<f64>> {
    if tip_nodes.is_empty() {
        return Err(MorError::Invalid("no tip nodes for the tip force".into()));
    }
    let op = RestOperator::new(model)?;
    let nc = model.cavities.len();
    let mut out = DMatrix::<f64>::zeros(op.x0.len(), nc + 3);
    for c in 0..nc {
        let mut p = vec![0.0; nc];
        p[c] = 1.0;
        let ev = model.evaluate(&op.pat, &op.x0, &Loads { pressures_pa: p }, 1.0, false)?;
        // f_ext also holds the model's dead loads (gravity, point forces): remove them.
        let ev0 = model.evaluate(
            &op.pat,
            &op.x0,
            &Loads {
                pressures_pa: vec![0.0; nc],
            },
            1.0,
            false,
        )?;
        let f: Vec<f64> = ev
            .f_ext
            .iter()
            .zip(&ev0.f_ext)
            .map(|(a, b)| a - b)
            .collect();
        out.set_column(c, &DVector::from_vec(op.static_response(&f)?));
    }
    for d in 0..3 {
        let mut f = vec![0.0; op.x0.len()];
        for &i in tip_nodes {
            f[3 * i + d] = 1.0 / tip_nodes.len() as f64;
        }
        out.set_column(nc + d, &DVector::from_vec(op.static_response(&f)?));
    }
    Ok(out)
}

/// The Petrov-Galerkin test basis W = T J0^-1 T^T V of a basis V (3N x r) for backward-Euler
/// steps of `h` seconds: J0 = (1/h^2 + alpha/h) M + (1 + beta/h) K0 is the full model's step
/// matrix at rest on the solver's reduced DOFs (T: free nodes plus the rigid bodies' linearised
/// motion). For a linear step with this matrix, W^T R(V q) = V^T T J0^-1 T^T J0 T (z_q - z*) is
/// the Euclidean projection of the step's error, so the reduced step returns the projection of
/// the full one; it is the frozen-Jacobian form of least-squares Petrov-Galerkin in the norm
/// ||J0^-1 R||. The columns are scaled by one common factor so that ||W||_F = ||V||_F (the
/// equations' solution does not depend on it).
pub fn step_test_basis(model: &Model, basis: &DMatrix<f64>, h: f64) -> Result<DMatrix<f64>> {
    let pressures = vec![0.0; model.cavities.len()];
    step_test_basis_at(model, basis, h, &model.rest_dofs(), &pressures)
}

/// [`step_test_basis`] with the step matrix at nodal positions `x` (3N) under cavity pressures
/// `pressures_pa` (the tangent there, pressure load included, and T linearised there).
pub fn step_test_basis_at(
    model: &Model,
    basis: &DMatrix<f64>,
    h: f64,
    x: &[f64],
    pressures_pa: &[f64],
) -> Result<DMatrix<f64>> {
    if !(h.is_finite() && h > 0.0) {
        return Err(MorError::Invalid(format!(
            "time step must be positive and finite, got {h}"
        )));
    }
    let n3 = 3 * model.num_nodes();
    if basis.nrows() != n3 {
        return Err(MorError::Invalid(format!(
            "basis has {} rows, the model {n3} DOFs",
            basis.nrows()
        )));
    }
    if x.len() != n3 || pressures_pa.len() != model.cavities.len() {
        return Err(MorError::Invalid(format!(
            "state has {} DOFs and {} pressures, the model {n3} and {}",
            x.len(),
            pressures_pa.len(),
            model.cavities.len()
        )));
    }
    let op = RestOperator::shifted_at(
        model,
        x.to_vec(),
        pressures_pa,
        1.0 / (h * h) + model.rayleigh_alpha / h,
        1.0 + model.rayleigh_beta / h,
    )?;
    let mut w = DMatrix::<f64>::zeros(n3, basis.ncols());
    for k in 0..basis.ncols() {
        w.set_column(
            k,
            &DVector::from_vec(op.static_response(basis.column(k).as_slice())?),
        );
    }
    let (nv, nw) = (basis.norm(), w.norm());
    if nw > 0.0 && nw.is_finite() {
        w *= nv / nw;
    }
    Ok(w)
}

/// Appends the columns of `extra` to the orthonormal `basis` (3N x r), each orthonormalised
/// against what is there (Gram-Schmidt, twice); a column whose remainder is below `drop_tol`
/// of its norm is dropped. Returns the new basis (Euclidean-orthonormal, as a POD basis).
pub fn enrich(basis: &DMatrix<f64>, extra: &DMatrix<f64>, drop_tol: f64) -> Result<DMatrix<f64>> {
    if basis.nrows() != extra.nrows() {
        return Err(MorError::Invalid(format!(
            "cannot enrich a basis of {} rows with vectors of {}",
            basis.nrows(),
            extra.nrows()
        )));
    }
    let mut cols: Vec<DVector<f64>> = basis.column_iter().map(|c| c.into_owned()).collect();
    for c in extra.column_iter() {
        let norm0 = c.norm();
        if !(norm0.is_finite() && norm0 > 0.0) {
            continue;
        }
        let mut v = c.into_owned();
        for _ in 0..2 {
            for b in &cols {
                let d = b.dot(&v);
                v.axpy(-d, b, 1.0);
            }
        }
        let nv = v.norm();
        if nv > drop_tol * norm0 {
            cols.push(v / nv);
        }
    }
    Ok(DMatrix::from_columns(&cols))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rom::ReducedModel;
    use ocm_fem::material::Material;
    use ocm_fem::mesh::generate;

    /// A clamped block with a rigid end (the bellows' structure in small).
    fn block(rigid_end: bool) -> Model {
        let mesh = generate::box_mesh([4, 2, 2], [0.08, 0.02, 0.02]);
        let mut model = Model::new(&mesh, Material::neo_hookean_bulk(2e5, 0.4), 1040.0).unwrap();
        model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
        if rigid_end {
            model.add_rigid_body("end", |p| p.x >= 0.08 - 1e-9).unwrap();
        }
        model
    }

    /// Dense reference: all eigenvalues of (T^T K T, T^T M T) from the solver's own matrices.
    fn dense_reference(model: &Model) -> Vec<f64> {
        let pat = Pattern::new(model).unwrap();
        let n = pat.num_free();
        let x0 = model.rest_dofs();
        let loads = Loads {
            pressures_pa: vec![],
        };
        let kv = model
            .evaluate(&pat, &x0, &loads, 1.0, true)
            .unwrap()
            .tangent
            .unwrap();
        let mv = model.mass_values(&pat);
        let (mut k, mut m) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
        for j in 0..n {
            for p in pat.col_ptr[j]..pat.col_ptr[j + 1] {
                k[(pat.row_idx[p], j)] += kv[p];
                m[(pat.row_idx[p], j)] += mv[p];
            }
        }
        pencil(&k, &m).unwrap().0
    }

    /// Subspace iteration agrees with the dense generalised eigenproblem, with and without a
    /// rigid body, and the shapes are mass-normalised.
    #[test]
    fn rest_modes_match_the_dense_eigenproblem() {
        for rigid in [false, true] {
            let model = block(rigid);
            let modes = rest_modes(&model, 6).unwrap();
            let reference = dense_reference(&model);
            for (f, l) in modes.frequencies_hz.iter().zip(&reference) {
                assert!((f - hz(*l)).abs() <= 1e-8 * hz(*l), "{f} vs {} Hz", hz(*l));
            }
            let m = model.nodal_masses();
            for k in 0..6 {
                let s = modes.shapes.column(k);
                let mm: f64 = (0..s.len()).map(|d| m[d / 3] * s[d] * s[d]).sum();
                // The rigid end's linearised motion gives its nodes exactly T phi.
                assert!((mm - 1.0).abs() < 1e-9, "mode {k}: phi^T M phi = {mm}");
            }
        }
    }

    /// The static responses satisfy the model's own force balance to first order: the internal
    /// force at a small multiple eps of a response equals eps times the unit load (central
    /// differences, 1 um of motion); with a rigid end the tip force acts through the body.
    #[test]
    fn static_shapes_balance_the_unit_loads() {
        for rigid in [false, true] {
            let mut model = block(rigid);
            let on_top = |p: &Vector3<f64>| (p.z - 0.02).abs() < 1e-12 && p.x < 0.06;
            let mut tris = vec![];
            for g in &model.elements {
                for skip in 0..4 {
                    let f: Vec<usize> = (0..4).filter(|&k| k != skip).map(|k| g.nodes[k]).collect();
                    if f.iter().all(|&i| on_top(&model.rest[i])) {
                        tris.push([f[0], f[1], f[2]]);
                    }
                }
            }
            model.add_pressure_surface("top", tris).unwrap();
            let tip: Vec<usize> = (0..model.num_nodes())
                .filter(|&i| model.rest[i].x >= 0.08 - 1e-9)
                .collect();
            let shapes = static_shapes(&model, &tip).unwrap();
            assert_eq!(shapes.ncols(), 4);
            let pat = Pattern::new(&model).unwrap();
            let x0 = model.rest_dofs();
            let zero = Loads {
                pressures_pa: vec![0.0],
            };
            for c in 0..4 {
                let u = shapes.column(c);
                // Unit load on the reduced DOFs: 1 Pa (follower, at rest) or 1 N at the tip.
                let load = if c == 0 {
                    let e1 = Loads {
                        pressures_pa: vec![1.0],
                    };
                    let f1 = model.evaluate(&pat, &x0, &e1, 1.0, false).unwrap().residual;
                    let f0 = model
                        .evaluate(&pat, &x0, &zero, 1.0, false)
                        .unwrap()
                        .residual;
                    f0.iter().zip(&f1).map(|(a, b)| a - b).collect::<Vec<f64>>()
                } else {
                    let mut f = vec![0.0; x0.len()];
                    for &i in &tip {
                        f[3 * i + c - 1] = 1.0 / tip.len() as f64;
                    }
                    pat.reduce(&x0, &f)
                };
                let eps = 1e-6 / u.amax();
                let res = |sign: f64| {
                    let mut x = x0.clone();
                    for d in 0..x.len() {
                        x[d] += sign * eps * u[d];
                    }
                    model
                        .evaluate(&pat, &x, &zero, 1.0, false)
                        .unwrap()
                        .residual
                };
                let (rp, rm) = (res(1.0), res(-1.0));
                let err: f64 = (0..load.len())
                    .map(|j| ((rp[j] - rm[j]) / (2.0 * eps) - load[j]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let scale = load.iter().map(|v| v * v).sum::<f64>().sqrt();
                assert!(
                    err <= 1e-6 * scale,
                    "shape {c} (rigid {rigid}): {err} vs {scale}"
                );
            }
        }
    }

    /// A Galerkin model on a basis that contains the first modes has exactly their frequencies
    /// (Rayleigh-Ritz on an invariant subspace), while a basis without them is stiffer.
    #[test]
    fn enriched_galerkin_model_has_the_full_frequencies() {
        let model = block(false);
        let modes = rest_modes(&model, 4).unwrap();
        let n3 = 3 * model.num_nodes();
        // A static shape (uniform load along y): not a mode, spans none of them.
        let seed = DMatrix::from_fn(n3, 1, |i, _| {
            if model.fixed[i] || i % 3 != 1 {
                0.0
            } else {
                let x = model.rest[i / 3].x;
                x * x
            }
        });
        let seed = enrich(&DMatrix::zeros(n3, 0), &seed, 1e-12).unwrap();
        let rom = ReducedModel::galerkin(&model, seed.clone(), &[model.num_nodes() - 1]).unwrap();
        let k = rom.internal(&DVector::zeros(1), true).unwrap().k.unwrap();
        let single = hz(pencil(&k, &rom.mass).unwrap().0[0]);
        assert!(single > modes.frequencies_hz[0] * (1.0 + 1e-4));
        let basis = enrich(&seed, &modes.shapes, 1e-8).unwrap();
        assert_eq!(basis.ncols(), 5);
        let gram = basis.transpose() * &basis;
        assert!((gram - DMatrix::identity(5, 5)).norm() < 1e-10);
        let rom = ReducedModel::galerkin(&model, basis, &[model.num_nodes() - 1]).unwrap();
        let k = rom.internal(&DVector::zeros(5), true).unwrap().k.unwrap();
        let (vals, _) = pencil(&k, &rom.mass).unwrap();
        for (i, f) in modes.frequencies_hz.iter().enumerate() {
            assert!(
                (hz(vals[i]) - f).abs() <= 1e-7 * f,
                "{} vs {f} Hz",
                hz(vals[i])
            );
        }
    }
}
