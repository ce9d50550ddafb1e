//! Physics baselines: a fixed part plus free regressors per output channel, so that the free
//! parameters enter linearly and are fitted by least squares on the training rows.
//!
//! - `axial`: `F = s_b * bar(eps) + s_h * hinge(eps) + P * pressure(eps)` (eq 3.9): the free
//!   parameters are the scale factors on `k_b` and `k_h`; the pressure term is geometric.
//! - `bending`: `M = s_b * bar + s_h * hinge + P0 * pressure` (eq 3.20-3.21) with `P0` the
//!   pressure that holds the free cylinder at `strain0` (initial strain set by pressure, as in
//!   the dissertation's tests), which keeps `M` linear in `(s_b, s_h)`.
//! - `pose`: the quasi-static segment of [`crate::manipulator`] with one stiffness scale
//!   (golden-section search on the training rows), a free z offset (mounting height) and,
//!   per channel, the stiffness sensitivity as a free regressor (the scale linearised, so that
//!   extensions refit it jointly).
//! - `series`: the static affine map `y = A u + b`, or a linear state-space model
//!   ([`crate::statespace`]) for dynamic systems; each is reported beside the other.
//! - `series` with `sim_` columns: the simulator's prediction, no free parameter.

use ocm_shared::params::ParamPreset;

use crate::data::{Kind, Record};
use crate::error::IdentError;
use crate::manipulator::Segment;
use crate::physics::Physics;
use crate::signal;
use crate::statespace::StateSpace;
use serde::Serialize;

/// The baseline's design for one output channel on a set of input values.
#[derive(Debug, Clone)]
pub struct Design {
    /// Part of the prediction with no free coefficient.
    pub fixed: Vec<f64>,
    /// Free regressors (coefficients fitted by least squares).
    pub regressors: Vec<Vec<f64>>,
    /// Names of the free coefficients.
    pub names: Vec<String>,
    /// Which regressors scale with the structure's stiffness (for the damage extension).
    pub stiffness: Vec<bool>,
    /// Derivative of the fixed part with respect to a relative stiffness change, if any.
    pub fixed_elastic: Option<Vec<f64>>,
    /// Coefficients constrained to be non-negative (physical stiffness scales).
    pub nonneg: Vec<bool>,
}

/// Internal states of the pose baseline (see [`Baseline::pose_states`]).
#[derive(Debug, Clone)]
pub struct PoseStates {
    /// Column strains, `[column][row]`.
    pub strains: Vec<Vec<f64>>,
    /// `d tip_c / d strain_k`, `[channel][column][row]`, metres.
    pub sens: Vec<Vec<Vec<f64>>>,
}

/// A baseline model for one record.
#[derive(Debug, Clone)]
pub enum Baseline {
    /// Energy model, axial test.
    Axial(&'static Physics),
    /// Energy model, bending test.
    Bending(&'static Physics),
    /// Quasi-static manipulator segment with a fitted stiffness scale.
    Pose {
        /// Physics tables.
        physics: &'static Physics,
        /// Fitted relative stiffness.
        stiffness_scale: f64,
    },
    /// Static affine map.
    Series,
    /// A user's simulator: its prediction (`sim_<name>` columns) as it is, no free parameter.
    Simulator,
    /// Linear state-space model (subspace identification refined on free-run error); the
    /// output map `C x + D u + d` is fitted per channel.
    StateSpace(Box<StateSpace>),
}

/// Which baseline a `series` record without `sim_` columns gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SeriesModel {
    /// Static affine map `y = A u + b` (quasi-static systems).
    Static,
    /// Linear state-space model (dynamic systems).
    StateSpace,
    /// The state-space model, or the static map where the static map with the causes it
    /// names fits better (`ocm ident`'s default; the rule is `structure::static_map`'s).
    Auto,
}

impl Baseline {
    /// Builds (and for pose and the state-space model, fits the nonlinear parameters of) the
    /// baseline for a record.
    pub fn for_record(
        rec: &Record,
        train: &[bool],
        series: SeriesModel,
        ocm: ParamPreset,
    ) -> Result<Baseline, IdentError> {
        let physics = Physics::preset(ocm);
        match rec.kind {
            Kind::Axial => {
                let (lo, hi) = physics.strain_range();
                check_range(rec, 0, lo, hi)?;
                Ok(Baseline::Axial(physics))
            }
            Kind::Bending => {
                let (lo, hi) = physics.strain_range();
                check_range(rec, 0, lo, hi)?;
                let e0 = &rec.inputs[0].values;
                let a = &rec.inputs[1].values;
                if let Some(i) = (0..rec.len()).find(|&i| a[i].abs() > physics.bend_limit(e0[i])) {
                    return Err(IdentError::Invalid(format!(
                        "{}: data row {} (CSV line {}): bend angle {:.4} rad exceeds the feasible {:.4} rad at strain0 {:.3}",
                        rec.source,
                        i + 1,
                        i + 2,
                        a[i],
                        physics.bend_limit(e0[i]),
                        e0[i]
                    )));
                }
                Ok(Baseline::Bending(physics))
            }
            Kind::Pose => Ok(Baseline::Pose {
                physics,
                stiffness_scale: fit_pose_scale(rec, physics, train),
            }),
            Kind::Series if !rec.simulated.is_empty() => Ok(Baseline::Simulator),
            Kind::Series if matches!(series, SeriesModel::StateSpace | SeriesModel::Auto) => {
                Ok(Baseline::state_space(rec, train))
            }
            Kind::Series => Ok(Baseline::Series),
        }
    }

    /// The linear state-space baseline identified on the training rows of `rec`.
    pub fn state_space(rec: &Record, train: &[bool]) -> Baseline {
        let ins: Vec<&[f64]> = rec.inputs.iter().map(|c| c.values.as_slice()).collect();
        let outs: Vec<&[f64]> = rec.outputs.iter().map(|c| c.values.as_slice()).collect();
        Baseline::StateSpace(Box::new(StateSpace::identify(
            &ins,
            &outs,
            &rec.segment_starts,
            train,
        )))
    }

    /// One-line description with the free parameters' meaning.
    pub fn describe(&self) -> String {
        match self {
            Baseline::Axial(_) => {
                "energy model F_A (eq 3.9), free scales on k_b and k_h, geometric pressure term".into()
            }
            Baseline::Bending(_) => {
                "energy model F_B (eq 3.20-3.21) at free-standing initial strain, free scales on k_b and k_h".into()
            }
            Baseline::Pose {
                stiffness_scale, ..
            } => format!(
                "quasi-static PCC segment (eq 3.26-3.34), fitted stiffness scale {stiffness_scale:.4}, free z offset"
            ),
            Baseline::Series => "static affine map y = A u + b".into(),
            Baseline::Simulator => {
                "the simulator's prediction (sim_ columns) as given, no free parameter".into()
            }
            Baseline::StateSpace(ss) => format!(
                "linear state-space model of order {}{}{} (PO-MOESP, refined on free-run error; order by BIC of the free-run training error: {}), free-run predictions",
                ss.order(),
                if ss
                    .orders
                    .iter()
                    .min_by(|a, b| a.2.total_cmp(&b.2))
                    .is_some_and(|o| o.0 != ss.order())
                {
                    ", a lower order than the linear model's BIC chose, kept because the extended model's BIC is lower there"
                } else {
                    ""
                },
                if ss.entry_lag > 0.0 {
                    format!(
                        ", the extensions' forces entering after a lag of {:.1} samples (a real pole of the baseline; kept because the extended model's BIC is lower than with the forces entering where the inputs do)",
                        ss.entry_lag
                    )
                } else {
                    String::new()
                },
                ss.orders
                    .iter()
                    .map(|(n, r, b)| format!("n={n}: RMSE {r:.3e}, BIC {b:.0}"))
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        }
    }

    /// For `pose`: the model's column strains (one row per column) and the sensitivity of
    /// each tip coordinate to each column strain, `[channel][column][row]`. The memory,
    /// viscosity and static-mismatch extensions act on these internal strains.
    pub fn pose_states(&self, inputs: &[&[f64]]) -> Option<PoseStates> {
        let Baseline::Pose {
            physics,
            stiffness_scale,
        } = self
        else {
            return None;
        };
        let seg = Segment::new(physics, *stiffness_scale);
        let n = inputs[0].len();
        let mut strains = vec![vec![0.0; n]; 3];
        let mut sens = vec![vec![vec![0.0; n]; 3]; 3];
        let h = 1e-5;
        for i in 0..n {
            let e: [f64; 3] =
                std::array::from_fn(|k| seg.column_strain(inputs[3][i] / 3.0, inputs[k][i]));
            for k in 0..3 {
                strains[k][i] = e[k];
                let mut a = e;
                let mut b = e;
                a[k] += h;
                b[k] -= h;
                let ta = seg.tip(seg.configuration(a));
                let tb = seg.tip(seg.configuration(b));
                for c in 0..3 {
                    sens[c][k][i] = (ta[c] - tb[c]) / (2.0 * h);
                }
            }
        }
        Some(PoseStates { strains, sens })
    }

    /// The design of output `c` on the given input columns; `simulated` holds the simulator's
    /// predictions (used by [`Baseline::Simulator`] only).
    pub fn design(
        &self,
        inputs: &[&[f64]],
        time_s: &[f64],
        starts: &[usize],
        c: usize,
        simulated: &[crate::data::Channel],
    ) -> Design {
        let n = time_s.len();
        match self {
            Baseline::Simulator => Design {
                fixed: simulated[c].values.clone(),
                regressors: Vec::new(),
                names: Vec::new(),
                stiffness: Vec::new(),
                // a stiffness change of the simulated structure scales its response
                fixed_elastic: Some(simulated[c].values.clone()),
                nonneg: Vec::new(),
            },
            Baseline::Axial(p) => {
                let mut fixed = vec![0.0; n];
                let mut rb = vec![0.0; n];
                let mut rh = vec![0.0; n];
                for i in 0..n {
                    let t = p.axial(inputs[0][i]);
                    fixed[i] = inputs[1][i] * t[2];
                    rb[i] = t[0];
                    rh[i] = t[1];
                }
                Design {
                    fixed,
                    regressors: vec![rb, rh],
                    names: vec!["k_b scale".into(), "k_h scale".into()],
                    stiffness: vec![true, true],
                    fixed_elastic: None,
                    nonneg: vec![true, true],
                }
            }
            Baseline::Bending(p) => {
                let mut rb = vec![0.0; n];
                let mut rh = vec![0.0; n];
                for i in 0..n {
                    let t = p.free_bending_terms(inputs[1][i], inputs[0][i]);
                    rb[i] = t[0];
                    rh[i] = t[1];
                }
                Design {
                    fixed: vec![0.0; n],
                    regressors: vec![rb, rh],
                    names: vec!["k_b scale".into(), "k_h scale".into()],
                    stiffness: vec![true, true],
                    fixed_elastic: None,
                    nonneg: vec![true, true],
                }
            }
            Baseline::Pose {
                physics,
                stiffness_scale,
            } => {
                let tip = |s: f64| -> Vec<f64> {
                    let seg = Segment::new(physics, s);
                    (0..n)
                        .map(|i| {
                            seg.tip_for([inputs[0][i], inputs[1][i], inputs[2][i]], inputs[3][i])[c]
                        })
                        .collect()
                };
                let fixed = tip(*stiffness_scale);
                let h = 0.02;
                let up = tip(stiffness_scale * (1.0 + h));
                let dn = tip(stiffness_scale * (1.0 - h));
                let el: Vec<f64> = up
                    .iter()
                    .zip(&dn)
                    .map(|(a, b)| (a - b) / (2.0 * h))
                    .collect();
                // The stiffness scale enters linearised (its sensitivity as a free regressor),
                // so that extensions are fitted jointly with a stiffness correction; it is not
                // flagged as a stiffness regressor because `fixed_elastic` already carries it.
                let mut regressors = vec![el.clone()];
                let mut names = vec!["relative stiffness correction".to_string()];
                let mut stiffness = vec![false];
                if c == 2 {
                    regressors.push(vec![1.0; n]);
                    names.push("z offset".to_string());
                    stiffness.push(false);
                }
                Design {
                    fixed,
                    regressors,
                    names,
                    nonneg: vec![false; stiffness.len()],
                    stiffness,
                    fixed_elastic: Some(el),
                }
            }
            Baseline::StateSpace(ss) => {
                let mut regressors = ss.states(inputs, starts);
                let mut names: Vec<String> = (0..regressors.len())
                    .map(|j| format!("C[{c}][{j}]"))
                    .collect();
                for (k, u) in inputs.iter().enumerate() {
                    regressors.push(u.to_vec());
                    names.push(format!("D[{c}][{k}]"));
                }
                let mut stiffness = vec![true; regressors.len()];
                regressors.push(vec![1.0; n]);
                names.push(format!("d[{c}]"));
                stiffness.push(false);
                // after `d`: the extensions index `C` and `D` from the front
                for (j, f) in ss.free_responses(starts, n).into_iter().enumerate() {
                    regressors.push(f);
                    names.push(format!("initial-state response {j} of y[{c}]"));
                    stiffness.push(false);
                }
                Design {
                    fixed: vec![0.0; n],
                    nonneg: vec![false; regressors.len()],
                    regressors,
                    names,
                    stiffness,
                    fixed_elastic: None,
                }
            }
            Baseline::Series => {
                let mut regressors: Vec<Vec<f64>> = inputs.iter().map(|u| u.to_vec()).collect();
                let mut names: Vec<String> =
                    (0..inputs.len()).map(|k| format!("a[{c}][{k}]")).collect();
                let mut stiffness = vec![true; inputs.len()];
                regressors.push(vec![1.0; n]);
                names.push(format!("b[{c}]"));
                stiffness.push(false);
                Design {
                    fixed: vec![0.0; n],
                    nonneg: vec![false; regressors.len()],
                    regressors,
                    names,
                    stiffness,
                    fixed_elastic: None,
                }
            }
        }
    }
}

fn check_range(rec: &Record, input: usize, lo: f64, hi: f64) -> Result<(), IdentError> {
    let ch = &rec.inputs[input];
    if let Some(i) = ch.values.iter().position(|v| *v < lo || *v > hi) {
        return Err(IdentError::Invalid(format!(
            "{}: data row {} (CSV line {}): {} = {} is outside the model's range [{:.3}, {:.3}]",
            rec.source,
            i + 1,
            i + 2,
            ch.name,
            ch.values[i],
            lo,
            hi
        )));
    }
    Ok(())
}

/// Golden-section search of the stiffness scale minimising the training tip error (the z
/// offset is profiled out as the mean z residual).
fn fit_pose_scale(rec: &Record, physics: &'static Physics, train: &[bool]) -> f64 {
    let rows: Vec<usize> = (0..rec.len()).filter(|&i| train[i]).collect();
    // A subsample keeps the one-dimensional search cheap on long records.
    let step = (rows.len() / 2000).max(1);
    let rows: Vec<usize> = rows.into_iter().step_by(step).collect();
    let sse = |log_s: f64| -> f64 {
        let seg = Segment::new(physics, log_s.exp());
        let mut pred = Vec::with_capacity(rows.len());
        for &i in &rows {
            let u = |k: usize| rec.inputs[k].values[i];
            pred.push(seg.tip_for([u(0), u(1), u(2)], u(3)));
        }
        let mut s = 0.0;
        let mut zres = Vec::with_capacity(rows.len());
        for (r, &i) in rows.iter().enumerate() {
            for c in 0..2 {
                let e = rec.outputs[c].values[i] - pred[r][c];
                s += e * e;
            }
            zres.push(rec.outputs[2].values[i] - pred[r][2]);
        }
        let (_, sd) = signal::mean_std(&zres);
        s + sd * sd * zres.len() as f64
    };
    let (mut a, mut b) = ((0.1f64).ln(), (10.0f64).ln());
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = b - g * (b - a);
    let mut x2 = a + g * (b - a);
    let mut f1 = sse(x1);
    let mut f2 = sse(x2);
    for _ in 0..40 {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = sse(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = sse(x2);
        }
    }
    (0.5 * (a + b)).exp()
}
