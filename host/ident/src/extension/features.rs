//! The extension features of each cause: columns that enter the joint least-squares fit
//! beside the baseline's free regressors.

use super::prepared::{Prepared, span};
use crate::baseline::Baseline;
use crate::cause::Cause;
use crate::signal;

/// Play-operator half-widths of the hysteresis extension, as fractions of the drive range.
pub(super) const PLAY_WIDTHS: [f64; 6] = [0.005, 0.015, 0.035, 0.07, 0.14, 0.28];

/// Laguerre filters per nonlinear input term in the actuator variant of `nonlinearity`.
pub const LAGUERRE_FILTERS: usize = 8;

/// Extension features of one channel: columns, names and non-negativity flags.
pub type Features = (Vec<Vec<f64>>, Vec<String>, Vec<bool>);

impl Prepared<'_> {
    /// Extension features of `cause` for channel `c`: (columns, names, non-negative flags).
    pub fn features(&self, cause: Cause, c: usize) -> Features {
        if let Baseline::StateSpace(ss) = &self.baseline
            && let Some(f) = self.dynamic_features(ss, cause, c)
        {
            return f;
        }
        let rec = self.rec;
        let n = rec.len();
        let ch = &self.channels[c];
        let mut cols = Vec::new();
        let mut names = Vec::new();
        let mut nonneg = Vec::new();
        match cause {
            Cause::None | Cause::Latency | Cause::Unexplained => {}
            Cause::Friction => {
                let rich = self.flexible.get() == Some(Cause::Friction);
                // Per velocity source: a smoothed sign (the Coulomb level, +- the same force
                // in both directions), its magnitude (a direction-independent level while
                // moving, so that unequal levels per direction are one friction), a viscous
                // term and a Stribeck peak at breakaway. Each enters with the prediction's
                // sensitivity to a force at the output (1 for a force output).
                for (name, v, v0) in self.velocities() {
                    let vs = 5.0 * v0;
                    // The direction of motion, held while the part stands still (a stuck seal
                    // keeps the friction force of its last motion): an elastic-plastic element
                    // on the position with a pre-sliding displacement of 0.5 % of the stroke.
                    let sgn: Vec<f64> = match rec.states.iter().find(|s| s.name == name) {
                        Some(st) => {
                            let r = 0.005 * span(&st.values);
                            let p = signal::play(&st.values, &rec.segment_starts, r);
                            st.values.iter().zip(&p).map(|(x, q)| (x - q) / r).collect()
                        }
                        None => v.iter().map(|x| (x / v0).tanh()).collect(),
                    };
                    cols.push(sgn.clone());
                    names.push(format!("Coulomb friction from d{name}/dt"));
                    cols.push(sgn.iter().map(|s| s.abs()).collect());
                    names.push(format!("level while moving, d{name}/dt"));
                    cols.push(v.iter().map(|x| x / vs).collect());
                    names.push(format!("viscous friction at {vs:.4} /s of {name}"));
                    cols.push(
                        (0..n)
                            .map(|i| sgn[i] * (-(v[i] / vs).powi(2)).exp())
                            .collect(),
                    );
                    names.push(format!("Stribeck peak of d{name}/dt"));
                    nonneg.extend([false; 4]);
                    if rich {
                        // the most flexible variant: pre-sliding (the friction force follows
                        // the sign through first-order lags, Dahl-like) and a Coulomb level
                        // that varies along the stroke
                        for m in [1.0, 3.0, 10.0] {
                            let lp = signal::lowpass(
                                &sgn,
                                &rec.time_s,
                                &rec.segment_starts,
                                m * self.dt,
                            );
                            cols.push(sgn.iter().zip(&lp).map(|(a, b)| a - b).collect());
                            names.push(format!("pre-sliding lag {m} samples, d{name}/dt"));
                        }
                        if let Some(st) = rec.states.iter().find(|s| s.name == name) {
                            let (mx, _) = signal::mean_std(&st.values);
                            let r = 0.5 * span(&st.values);
                            for p in [1, 2] {
                                cols.push(
                                    (0..n)
                                        .map(|i| sgn[i] * ((st.values[i] - mx) / r).powi(p))
                                        .collect(),
                                );
                                names.push(format!("Coulomb level * ({name} - mean)^{p}"));
                            }
                            nonneg.extend([false; 2]);
                        }
                        nonneg.extend([false; 3]);
                        // and a level that follows the inputs (a seal pressed harder at
                        // higher pressure)
                        for (k, inp) in rec.inputs.iter().enumerate() {
                            for p in [1, 2] {
                                cols.push(
                                    (0..n)
                                        .map(|i| {
                                            sgn[i]
                                                * ((inp.values[i] - self.means[k]) / self.ranges[k])
                                                    .powi(p)
                                        })
                                        .collect(),
                                );
                                names.push(format!("Coulomb level * ({} - mean)^{p}", inp.name));
                                nonneg.push(false);
                            }
                        }
                    }
                }
            }
            Cause::Hysteresis if self.pose.is_some() => {
                // Memory in each column: play operators on the model's column strain, mapped to
                // the tip by the strain sensitivity; the strain lags (dissipates), so weights
                // are non-negative on the negated sensitivity.
                for (k, e, sens) in self.column_terms(c) {
                    let range = span(e);
                    for &w in &PLAY_WIDTHS {
                        let p = signal::play(e, &rec.segment_starts, w * range);
                        cols.push((0..n).map(|i| -sens[i] * (e[i] - p[i])).collect());
                        names.push(format!("PI weight column {} r={:.4}", k + 1, w * range));
                        nonneg.push(true);
                    }
                }
            }
            Cause::Hysteresis => {
                let simulator = matches!(self.baseline, Baseline::Simulator);
                for &k in &rec.drives {
                    let u = &rec.inputs[k].values;
                    // On a simulator, the sign of its mean sensitivity to the input (read off
                    // the simulated rows) in the orientation being fitted (`memory_sign`:
                    // whether the output lags its input or leads it, which a simulator does
                    // not say). Weighting the memory by the sensitivity row by row named a
                    // spurious `gain` beside a memory added at the output.
                    let through = if simulator {
                        ch.sign[k] * self.memory_sign.get()
                    } else {
                        ch.sign[k]
                    };
                    for &w in &PLAY_WIDTHS {
                        let r = w * self.ranges[k];
                        let p = signal::play(u, &rec.segment_starts, r);
                        cols.push((0..n).map(|i| through * (u[i] - p[i])).collect());
                        names.push(format!("PI weight {} r={:.3}", rec.inputs[k].name, r));
                        nonneg.push(true);
                    }
                }
                // Memory in the simulator's states (where they determine its output): play
                // operators on each state, reaching the output through its sensitivity row by
                // row, in the orientation being fitted.
                for (st, jx) in rec.states.iter().zip(&ch.state_jac) {
                    let x = &st.values;
                    let range = span(x);
                    for &w in &PLAY_WIDTHS {
                        let r = w * range;
                        let p = signal::play(x, &rec.segment_starts, r);
                        let m = self.memory_sign.get();
                        cols.push((0..n).map(|i| m * jx[i] * (x[i] - p[i])).collect());
                        names.push(format!("PI weight state {} r={:.4}", st.name, r));
                        nonneg.push(true);
                    }
                }
                if self.flexible.get() == Some(Cause::Hysteresis)
                    && let Some(col) = self.preisach_column(c, &cols)
                {
                    // the most flexible variant: the Preisach class (see `preisach`)
                    cols.push(col);
                    names.push("Preisach plane (NNLS weights, scale)".into());
                    nonneg.push(true);
                }
            }
            Cause::RateDependence if self.pose.is_some() => {
                // Viscosity in each column: Prony terms on the model's column strain.
                for (k, e, sens) in self.column_terms(c) {
                    for tau in self.prony_taus() {
                        let lp = signal::lowpass(e, &rec.time_s, &rec.segment_starts, tau);
                        cols.push((0..n).map(|i| -sens[i] * (e[i] - lp[i])).collect());
                        names.push(format!("Prony modulus column {} tau={:.3}s", k + 1, tau));
                        nonneg.push(true);
                    }
                }
            }
            Cause::RateDependence => {
                for &k in &rec.drives {
                    let u = &rec.inputs[k].values;
                    for tau in self.prony_taus() {
                        let lp = signal::lowpass(u, &rec.time_s, &rec.segment_starts, tau);
                        cols.push((0..n).map(|i| ch.sign[k] * (u[i] - lp[i])).collect());
                        names.push(format!(
                            "Prony modulus {} tau={:.3}s",
                            rec.inputs[k].name, tau
                        ));
                        nonneg.push(true);
                    }
                }
            }
            Cause::Softening => {
                // Each stiffness-proportional term loses stiffness with the damage histories:
                // (s_j - d_jm h_m(t)) phi_j, linear in the damage coefficients d_jm.
                let (path, peak) = self.damage_histories();
                // Wear saturates (the dissertation's curves converge after conditioning), so the
                // cycle history enters linearly and through two saturating shapes.
                let fast: Vec<f64> = path.iter().map(|p| 1.0 - (-p / 0.1).exp()).collect();
                let slow: Vec<f64> = path.iter().map(|p| 1.0 - (-p / 0.3).exp()).collect();
                let hist = [
                    ("cycles", &path),
                    ("saturating cycles (0.1)", &fast),
                    ("saturating cycles (0.3)", &slow),
                    ("peak", &peak),
                ];
                // Only stiffness terms the baseline clearly resolves (|coefficient| above three
                // standard errors) get damage coefficients: damage on an unresolved term is an
                // unconstrained time-varying stiffness and overfits.
                let stiff: Vec<usize> = (0..ch.design.regressors.len())
                    .filter(|&j| ch.design.stiffness[j])
                    .collect();
                let resolved: Vec<usize> = stiff
                    .iter()
                    .copied()
                    .filter(|&j| ch.theta[j].abs() > 3.0 * ch.theta_se[j])
                    .collect();
                let chosen = if resolved.is_empty() { stiff } else { resolved };
                let mut terms: Vec<(String, &[f64])> = chosen
                    .iter()
                    .map(|&j| {
                        (
                            ch.design.names[j].clone(),
                            ch.design.regressors[j].as_slice(),
                        )
                    })
                    .collect();
                if let Some(fe) = &ch.design.fixed_elastic {
                    terms.push(("stiffness".into(), fe.as_slice()));
                }
                for (name, phi) in terms {
                    for (hn, h) in hist {
                        cols.push((0..n).map(|i| -phi[i] * h[i]).collect());
                        names.push(format!("damage of {name} per {hn}"));
                        nonneg.push(false);
                    }
                }
            }
            Cause::Offset => {
                // pose z already has its free mounting height: a second constant is redundant
                let has_constant = self.pose.is_some()
                    && ch
                        .design
                        .regressors
                        .iter()
                        .any(|r| r.iter().all(|v| *v == 1.0));
                if !has_constant {
                    cols.push(vec![1.0; n]);
                    names.push(output_bias_name(&rec.outputs[c].name));
                    nonneg.push(false);
                }
                for (k, inp) in rec.inputs.iter().enumerate() {
                    cols.push(ch.jac[k].clone());
                    names.push(format!("{} bias", inp.name));
                    nonneg.push(false);
                }
                for (st, jx) in rec.states.iter().zip(&ch.state_jac) {
                    cols.push(jx.clone());
                    names.push(format!("state {} bias", st.name));
                    nonneg.push(false);
                }
            }
            Cause::Gain => {
                if matches!(self.baseline, Baseline::Simulator) {
                    cols.push(ch.design.fixed.clone());
                    names.push(output_gain_name(&rec.outputs[c].name));
                    nonneg.push(false);
                }
                for (k, inp) in rec.inputs.iter().enumerate() {
                    cols.push((0..n).map(|i| inp.values[i] * ch.jac[k][i]).collect());
                    names.push(format!("{} gain - 1", inp.name));
                    nonneg.push(false);
                }
                // A state off by a factor, about the state's zero: states whose zero is the
                // unloaded configuration (an elongation, not a length) make a gain and an offset
                // two different shapes.
                for (st, jx) in rec.states.iter().zip(&ch.state_jac) {
                    cols.push((0..n).map(|i| st.values[i] * jx[i]).collect());
                    names.push(format!("state {} gain - 1", st.name));
                    nonneg.push(false);
                }
            }
            Cause::Nonlinearity if self.pose.is_some() => {
                // Static mismatch of the columns' force law: a strain correction that is a
                // complete cubic in the column's pressure and force, mapped to the tip. The
                // columns are stacks of the same OCM, so they share the correction.
                let (pm, pr) = {
                    let m = (0..3).map(|k| self.means[k]).sum::<f64>() / 3.0;
                    let r = (0..3).map(|k| self.ranges[k]).fold(0.0, f64::max);
                    (m, if r > 0.0 { r } else { 1.0 })
                };
                let zl: Vec<f64> = rec.inputs[3]
                    .values
                    .iter()
                    .map(|v| (v - self.means[3]) / self.ranges[3])
                    .collect();
                let terms = self.column_terms(c);
                for (a, b) in [
                    (0, 0),
                    (1, 0),
                    (0, 1),
                    (2, 0),
                    (1, 1),
                    (0, 2),
                    (3, 0),
                    (2, 1),
                    (1, 2),
                    (0, 3),
                ] {
                    let mut col = vec![0.0; n];
                    for &(k, _, sens) in &terms {
                        let p = &rec.inputs[k].values;
                        for i in 0..n {
                            col[i] += sens[i] * ((p[i] - pm) / pr).powi(a) * zl[i].powi(b);
                        }
                    }
                    cols.push(col);
                    names.push(format!("column strain per pressure^{a}*load^{b}"));
                    nonneg.push(false);
                }
            }
            Cause::Nonlinearity => {
                let k_in = rec.inputs.len();
                let z: Vec<Vec<f64>> = (0..k_in)
                    .map(|k| {
                        rec.inputs[k]
                            .values
                            .iter()
                            .map(|v| (v - self.means[k]) / self.ranges[k])
                            .collect()
                    })
                    .collect();
                // The actuator variant on a state-space baseline: each term of degree 2 and 3
                // gets dynamics of its own, a combination of Laguerre filters (a Hammerstein
                // branch per term beside the linear model; see `joint_fit`).
                let pole = match self.baseline {
                    Baseline::StateSpace(_) => self.actuator_pole.get(),
                    _ => None,
                };
                let mut push = |col: Vec<f64>, name: String| match pole {
                    Some(a) => {
                        let lag = a.ln().recip().abs() * self.dt;
                        let filtered =
                            signal::laguerre(&col, &rec.segment_starts, a, LAGUERRE_FILTERS);
                        for (j, f) in filtered.into_iter().enumerate() {
                            cols.push(f);
                            names.push(format!("{name} through Laguerre filter {j} ({lag:.3} s)"));
                            nonneg.push(false);
                        }
                    }
                    None => {
                        cols.push(col);
                        names.push(name);
                        nonneg.push(false);
                    }
                };
                // Complete polynomial up to degree 3 (the constant and linear terms keep the
                // correction centred wherever the mismatch is), less the terms an affine
                // baseline already has.
                let affine = matches!(self.baseline, Baseline::Series | Baseline::StateSpace(_));
                if !affine {
                    push(vec![1.0; n], "constant".into());
                }
                for a in 0..k_in {
                    if !affine {
                        push(z[a].clone(), rec.inputs[a].name.clone());
                    }
                    for b in a..k_in {
                        push(
                            (0..n).map(|i| z[a][i] * z[b][i]).collect(),
                            format!("{}*{}", rec.inputs[a].name, rec.inputs[b].name),
                        );
                        for d in b..k_in {
                            push(
                                (0..n).map(|i| z[a][i] * z[b][i] * z[d][i]).collect(),
                                format!(
                                    "{}*{}*{}",
                                    rec.inputs[a].name, rec.inputs[b].name, rec.inputs[d].name
                                ),
                            );
                        }
                    }
                }
            }
        }
        if matches!(self.baseline, Baseline::Simulator)
            && matches!(cause, Cause::Offset | Cause::Gain)
        {
            // A simulator linear in an input has a constant sensitivity: its input offset is
            // the output bias, its input gain the output gain. Dependent columns are left out
            // (they would only cancel each other).
            keep_independent(&mut cols, &mut names, &mut nonneg, &self.train);
        }
        (cols, names, nonneg)
    }
}

/// Name of the offset extension's bias of output `output`.
fn output_bias_name(output: &str) -> String {
    format!("{output} bias")
}

/// Name of the gain extension's scale of the simulated output `output`.
fn output_gain_name(output: &str) -> String {
    format!("{output} simulated output gain - 1")
}

/// Whether extension column `name` acts on output `output` alone (its bias or the scale of its
/// simulated value) rather than through an input or a state.
pub(super) fn is_output_column(output: &str, name: &str) -> bool {
    name == output_bias_name(output) || name == output_gain_name(output)
}

/// Drops each column that the columns before it span on the training rows to 1e-6 of its
/// norm (modified Gram-Schmidt), with its name and flag.
fn keep_independent(
    cols: &mut Vec<Vec<f64>>,
    names: &mut Vec<String>,
    nonneg: &mut Vec<bool>,
    train: &[bool],
) {
    let rows: Vec<usize> = (0..train.len()).filter(|&i| train[i]).collect();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut keep = Vec::new();
    for col in cols.iter() {
        let mut v: Vec<f64> = rows.iter().map(|&i| col[i]).collect();
        let norm0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        for q in &basis {
            let d: f64 = v.iter().zip(q).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(q).for_each(|(a, b)| *a -= d * b);
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let independent = norm0 > 0.0 && norm > 1e-6 * norm0;
        if independent {
            basis.push(v.iter().map(|x| x / norm).collect());
        }
        keep.push(independent);
    }
    let mut it = keep.iter();
    cols.retain(|_| *it.next().unwrap_or(&false));
    let mut it = keep.iter();
    names.retain(|_| *it.next().unwrap_or(&false));
    let mut it = keep.iter();
    nonneg.retain(|_| *it.next().unwrap_or(&false));
}

/// Threshold levels per drive of the Preisach plane (`levels (levels + 1) / 2` relays).
const PREISACH_LEVELS: usize = 8;
/// Most training rows the plane's NNLS fit uses (evenly thinned).
const PREISACH_ROWS: usize = 20_000;

impl Prepared<'_> {
    /// The hysteresis of a discretised Preisach plane on each drive, as one column: relays on
    /// an 8-level grid of thresholds across the drive's training range, their non-negative
    /// weights fitted by NNLS jointly with the baseline's free regressors (either sign) and the
    /// play-operator columns `pi` (non-negative) on the training rows. The joint fit then only
    /// scales it, so its 36 weights per drive are not counted as parameters: it serves as the
    /// reference a further cause must beat, never as a named extension of its own.
    fn preisach_column(&self, c: usize, pi: &[Vec<f64>]) -> Option<Vec<f64>> {
        let rec = self.rec;
        let ch = &self.channels[c];
        let mut relays: Vec<Vec<f64>> = Vec::new();
        for &k in &rec.drives {
            let u = &rec.inputs[k].values;
            let lo = u
                .iter()
                .zip(&self.train)
                .filter(|(_, t)| **t)
                .map(|(v, _)| *v)
                .fold(f64::INFINITY, f64::min);
            let hi = lo + self.ranges[k];
            for (_, _, r) in crate::preisach::plane(u, &rec.segment_starts, lo, hi, PREISACH_LEVELS)
            {
                relays.push(r.iter().map(|v| ch.sign[k] * v).collect());
            }
        }
        let target: Vec<f64> =
            ch.y.iter()
                .zip(&ch.design.fixed)
                .map(|(y, f)| y - f)
                .collect();
        let mut nonneg: Vec<&[f64]> = relays.iter().map(|v| v.as_slice()).collect();
        nonneg.extend(pi.iter().map(|v| v.as_slice()));
        let free: Vec<&[f64]> = ch.design.regressors.iter().map(|v| v.as_slice()).collect();
        let (w, _) =
            crate::preisach::nnls_fit(&nonneg, &free, &target, &self.train, PREISACH_ROWS)?;
        let mut col = vec![0.0; rec.len()];
        for (r, wj) in relays.iter().zip(&w) {
            if *wj > 0.0 {
                for (a, b) in col.iter_mut().zip(r) {
                    *a += wj * b;
                }
            }
        }
        col.iter().any(|v| *v != 0.0).then_some(col)
    }
}
