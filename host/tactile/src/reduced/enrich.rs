//! Modes that follow a placement's contact: the rest stiffness' responses to loads on the
//! indenter's footprint, added to the POD basis per placement.

use super::basis::ReducedModel;
use crate::gel::Gel;
use crate::indent::Approach;
use crate::indenter::{Indenter, Placed};
use crate::{Result, TactileError};
use nalgebra::{DMatrix, Vector3};
use ocm_fem::model::{Loads, Pattern};
use ocm_fem::solve::linear::SparseSolver;
use rayon::prelude::*;

/// The gel's stiffness at rest, factorised once, for modes that follow a placement's contact.
pub struct RestStiffness {
    pub(super) pattern: Pattern,
    pub(super) values: Vec<f64>,
    solver: SparseSolver,
    nodes: usize,
}

impl RestStiffness {
    /// Assembles and factorises the fem tangent of `gel` at rest.
    pub fn new(gel: &Gel) -> Result<Self> {
        let pattern = Pattern::new(&gel.model)?;
        let x0 = gel.model.rest_dofs();
        let ev = gel
            .model
            .evaluate(&pattern, &x0, &Loads::default(), 1.0, true)?;
        let values = ev
            .tangent
            .ok_or_else(|| TactileError::Input("the fem returned no tangent at rest".into()))?;
        let mut solver = SparseSolver::new(
            pattern.num_free(),
            pattern.col_ptr.clone(),
            pattern.row_idx.clone(),
        );
        solver.factorize(&values)?;
        Ok(RestStiffness {
            pattern,
            values,
            solver,
            nodes: gel.num_nodes(),
        })
    }

    /// The linear response at rest (3N, m) to 1 N along -z on each listed node.
    pub fn respond_z(&self, nodes: &[usize]) -> Result<Vec<f64>> {
        let loads: Vec<(usize, [f64; 3])> = nodes.iter().map(|&i| (i, [0.0, 0.0, -1.0])).collect();
        self.respond(&loads)
    }

    /// The linear response at rest (3N, m) to the nodal forces `loads` (node, N); forces on
    /// fixed dofs are dropped.
    pub fn respond(&self, loads: &[(usize, [f64; 3])]) -> Result<Vec<f64>> {
        let mut rhs = vec![0.0; self.pattern.num_free()];
        for &(i, f) in loads {
            for (d, fd) in f.iter().enumerate() {
                if let Some(&k) = self.pattern.free_of.get(3 * i + d)
                    && k != usize::MAX
                {
                    rhs[k] += fd;
                }
            }
        }
        self.solver.solve_factored(&mut rhs)?;
        let mut u = vec![0.0; 3 * self.nodes];
        for (j, &d) in self.pattern.dof_of.iter().enumerate() {
            u[d] = rhs[j];
        }
        Ok(u)
    }
}

impl RestStiffness {
    /// One modified-Newton correction of the field `u` (3N, m) with the rest tangent: the change
    /// -K_0^{-1} (f_int(X + u) - K_0 u) (3N, m), which keeps the forces the linear model
    /// balances (K_0 u) and trades its linear internal force for the gel's Neo-Hookean one.
    pub fn nonlinear_correction(&self, gel: &Gel, u: &[f64]) -> Result<Vec<f64>> {
        if u.len() != 3 * self.nodes {
            return Err(TactileError::Input(format!(
                "a field of {} entries for a gel of {} nodes",
                u.len(),
                self.nodes
            )));
        }
        let mut x = gel.model.rest_dofs();
        for (xi, ui) in x.iter_mut().zip(u) {
            *xi += ui;
        }
        let ev = gel
            .model
            .evaluate(&self.pattern, &x, &Loads::default(), 1.0, false)?;
        let uf: Vec<f64> = self.pattern.dof_of.iter().map(|&d| u[d]).collect();
        let ku = ocm_fem::solve::spmv(&self.pattern, &self.values, &uf);
        let mut rhs: Vec<f64> = ku.iter().zip(&ev.residual).map(|(k, r)| k - r).collect();
        self.solver.solve_factored(&mut rhs)?;
        let mut du = vec![0.0; 3 * self.nodes];
        for (j, &d) in self.pattern.dof_of.iter().enumerate() {
            du[d] = rhs[j];
        }
        Ok(du)
    }
}

/// Rim width of the footprint's second load (README, "The worst held-out frame"), m.
pub const FOOTPRINT_RIM_M: f64 = 0.4e-3;

/// Nodal forces: (mesh node, force N).
pub type NodalLoads = Vec<(usize, [f64; 3])>;

/// Candidate loads on a placement's footprint (label, nodal forces N), from the geometry alone:
/// the top nodes inside `placed` at rest, the outside top nodes, and per footprint node its
/// nearest outside top node (the in-plane direction out of the footprint, the distance to its edge).
pub fn footprint_load_cases(
    gel: &Gel,
    placed: &Placed,
    rim_m: f64,
) -> Vec<(&'static str, NodalLoads)> {
    let at = |i: usize| Vector3::from(gel.mesh.points[i]);
    let inside: Vec<bool> = gel
        .top
        .par_iter()
        .map(|&i| placed.query(&at(i)).distance < 0.0)
        .collect();
    let (mut foot, mut out) = (Vec::new(), Vec::new());
    for (&i, &on) in gel.top.iter().zip(&inside) {
        if on { foot.push(i) } else { out.push(i) }
    }
    if foot.is_empty() {
        return Vec::new();
    }
    let nearest = |i: usize, set: &[usize]| -> (f64, Vector3<f64>) {
        let mut best = (f64::INFINITY, Vector3::zeros());
        for &o in set {
            let mut d = at(o) - at(i);
            d.z = 0.0;
            let n = d.norm();
            if n < best.0 {
                best = (n, d / n.max(1e-30));
            }
        }
        best
    };
    let edge: Vec<(f64, Vector3<f64>)> = foot.iter().map(|&i| nearest(i, &out)).collect();
    let c = foot.iter().map(|&i| at(i)).sum::<Vector3<f64>>() / foot.len() as f64;
    let reach = foot
        .iter()
        .map(|&i| ((at(i) - c).xy()).norm())
        .fold(0.0, f64::max)
        .max(1e-9);
    let z = |w: f64| [0.0, 0.0, -w];
    let mut cases: Vec<(&'static str, NodalLoads)> = Vec::new();
    cases.push(("foot", foot.iter().map(|&i| (i, z(1.0))).collect()));
    cases.push((
        "rim",
        foot.iter()
            .zip(&edge)
            .filter(|(_, e)| e.0 < rim_m)
            .map(|(&i, _)| (i, z(1.0)))
            .collect(),
    ));
    cases.push((
        "ring2",
        foot.iter()
            .zip(&edge)
            .filter(|(_, e)| e.0 >= rim_m && e.0 < 2.5 * rim_m)
            .map(|(&i, _)| (i, z(1.0)))
            .collect(),
    ));
    cases.push((
        "out",
        foot.iter()
            .zip(&edge)
            .map(|(&i, e)| (i, [e.1.x, e.1.y, 0.0]))
            .collect(),
    ));
    cases.push((
        "out_rim",
        foot.iter()
            .zip(&edge)
            .filter(|(_, e)| e.0 < rim_m)
            .map(|(&i, e)| (i, [e.1.x, e.1.y, 0.0]))
            .collect(),
    ));
    cases.push((
        "radial",
        foot.iter()
            .map(|&i| {
                let d = (at(i) - c) / reach;
                (i, [d.x, d.y, 0.0])
            })
            .collect(),
    ));
    for (name, k) in [("tilt_x", 0), ("tilt_y", 1)] {
        cases.push((
            name,
            foot.iter()
                .map(|&i| (i, z((at(i)[k] - c[k]) / reach)))
                .collect(),
        ));
    }
    let skirt: Vec<(usize, [f64; 3])> = out
        .iter()
        .filter_map(|&o| {
            let (d, v) = nearest(o, &foot);
            (d < 2.5 * rim_m).then_some((o, [-v.x, -v.y, 0.0]))
        })
        .collect();
    cases.push(("skirt", skirt));
    cases.retain(|(_, l)| !l.is_empty());
    cases
}

/// Every footprint load [`footprint_load_cases`] knows: the normal loads `foot` (uniform on the
/// footprint), `rim` (its nodes within the rim width of its edge), `ring2` (the next 1.5 rim
/// widths inwards), `tilt_x` / `tilt_y` (linear in x / y across it); the in-plane loads `out`
/// (each footprint node towards its nearest outside top node), `out_rim` (the same on the rim),
/// `radial` (away from the footprint's centroid, growing with the distance) and `skirt` (outside
/// top nodes within 2.5 rim widths, away from the footprint).
pub const FOOTPRINT_LOADS: [&str; 9] = [
    "foot", "rim", "ring2", "out", "out_rim", "radial", "tilt_x", "tilt_y", "skirt",
];

/// The footprint loads `--enrich` uses unless told otherwise (README, "The worst held-out frame").
pub const DEFAULT_FOOTPRINT_LOADS: [&str; 2] = ["foot", "rim"];

/// Per-placement modes: the rest stiffness and the footprint loads whose responses join the basis.
#[derive(Clone, Copy)]
pub struct Enrichment<'a> {
    /// The factorised rest stiffness.
    pub rest: &'a RestStiffness,
    /// Labels out of [`FOOTPRINT_LOADS`].
    pub loads: &'a [&'a str],
}

/// Checks that every label in `loads` is one of [`FOOTPRINT_LOADS`], or `nl_` and one of them
/// (the second-order field of that load's response, [`second_order_mode`]).
pub fn check_footprint_loads(loads: &[&str]) -> Result<()> {
    let known = |l: &str| FOOTPRINT_LOADS.contains(&l.strip_prefix("nl_").unwrap_or(l));
    match loads.iter().find(|l| !known(l)) {
        Some(bad) => Err(TactileError::Input(format!(
            "unknown footprint load '{bad}' (known: {}, each also with the prefix nl_)",
            FOOTPRINT_LOADS.join(", ")
        ))),
        None => Ok(()),
    }
}

/// `model` with the modes of this placement appended: the rest responses to the footprint
/// loads `loads` ([`footprint_load_cases`]) of the indenter at `depth_m`, in that order; a load
/// with no node (e.g. no rim on a footprint a few nodes wide) or one the modes already hold adds none.
pub fn placement_model(
    model: &ReducedModel,
    enrich: Enrichment,
    gel: &Gel,
    indenter: &Indenter,
    approach: &Approach,
    depth_m: f64,
) -> Result<ReducedModel> {
    check_footprint_loads(enrich.loads)?;
    let placed = Placed {
        indenter,
        pose: approach.pose_at(depth_m),
    };
    let cases = footprint_load_cases(gel, &placed, FOOTPRINT_RIM_M);
    let mut responses: Vec<(&str, Vec<f64>)> = Vec::new();
    let mut extra = Vec::new();
    for l in enrich.loads {
        let base = l.strip_prefix("nl_").unwrap_or(l);
        let Some((_, loads)) = cases.iter().find(|(k, _)| *k == base) else {
            continue;
        };
        let u = match responses.iter().find(|(k, _)| *k == base) {
            Some((_, u)) => u.clone(),
            None => {
                let u = enrich.rest.respond(loads)?;
                responses.push((base, u.clone()));
                u
            }
        };
        if base == *l {
            extra.push(u);
        } else {
            extra.push(second_order_mode(enrich.rest, gel, &u, depth_m)?);
        }
    }
    model.with_extra_modes(enrich.rest, &extra)
}

/// The second-order field of a response `u` (3N, m): `u` scaled to a largest |u_z| of half of
/// `depth_m`, then one modified-Newton correction with the rest tangent
/// ([`RestStiffness::nonlinear_correction`]). It carries the in-plane flow under a pressed
/// footprint that the linear response lacks. A unit load concentrates under its nodes: where
/// the scaled field inverts an element, the scale is halved (up to 6 times).
pub fn second_order_mode(
    rest: &RestStiffness,
    gel: &Gel,
    u: &[f64],
    depth_m: f64,
) -> Result<Vec<f64>> {
    let top = u.chunks(3).map(|c| c[2].abs()).fold(0.0, f64::max);
    if !(top > 0.0 && depth_m > 0.0) {
        return Err(TactileError::Input(format!(
            "a second-order mode needs a response with a normal part and a depth > 0 (got {depth_m} m)"
        )));
    }
    let mut scale = 0.5 * depth_m / top;
    for _ in 0..6 {
        let scaled: Vec<f64> = u.iter().map(|v| v * scale).collect();
        match rest.nonlinear_correction(gel, &scaled) {
            Ok(du) => return Ok(du),
            Err(TactileError::Fem(ocm_fem::FemError::Inverted { .. })) => scale *= 0.5,
            Err(e) => return Err(e),
        }
    }
    Err(TactileError::Input(
        "a second-order mode inverts an element at every scale tried".into(),
    ))
}

impl ReducedModel {
    /// This basis with `extra` full fields (3N each, m) appended as modes: each is
    /// orthogonalised against the modes and the columns before it (twice) and dropped when
    /// nothing of it is left; the stiffness grows by the new rows and columns of Phi^T K_0 Phi.
    pub fn with_extra_modes(&self, rest: &RestStiffness, extra: &[Vec<f64>]) -> Result<Self> {
        let r = self.rank();
        let rows = self.modes.len() / r;
        let mut cols: Vec<Vec<f64>> = Vec::new();
        let col_of = |j: usize, cols: &[Vec<f64>], d: usize| -> f64 {
            if j < r {
                self.modes[d * r + j]
            } else {
                cols[j - r][d]
            }
        };
        for e in extra {
            if e.len() != rows {
                return Err(TactileError::Input(format!(
                    "an extra mode has {} entries, the basis {rows}",
                    e.len()
                )));
            }
            let mut v = e.clone();
            let scale = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            for _ in 0..2 {
                for j in 0..r + cols.len() {
                    let a: f64 = (0..rows).map(|d| col_of(j, &cols, d) * v[d]).sum();
                    for (d, y) in v.iter_mut().enumerate() {
                        *y -= a * col_of(j, &cols, d);
                    }
                }
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-8 * scale && norm > 0.0 {
                v.iter_mut().for_each(|x| *x /= norm);
                cols.push(v);
            }
        }
        let k = cols.len();
        let n = r + k;
        let mut modes = Vec::with_capacity(rows * n);
        for d in 0..rows {
            modes.extend_from_slice(&self.modes[d * r..(d + 1) * r]);
            modes.extend(cols.iter().map(|c| c[d]));
        }
        let mut stiffness = DMatrix::zeros(n, n);
        stiffness
            .view_mut((0, 0), (r, r))
            .copy_from(&self.stiffness);
        let free = &rest.pattern.dof_of;
        for (c, col) in cols.iter().enumerate() {
            let v: Vec<f64> = free.iter().map(|&d| col[d]).collect();
            let kv = ocm_fem::solve::spmv(&rest.pattern, &rest.values, &v);
            for a in 0..n {
                let x: f64 = free
                    .iter()
                    .zip(&kv)
                    .map(|(&d, y)| modes[d * n + a] * y)
                    .sum();
                stiffness[(a, r + c)] = x;
                stiffness[(r + c, a)] = x;
            }
        }
        let mut info = self.info.clone();
        info.rank = n;
        Ok(ReducedModel {
            info,
            modes,
            stiffness,
            singular_values: self.singular_values.clone(),
        })
    }
}
