//! Model extensions, one per cause, fitted jointly with the baseline's free coefficients on the
//! training rows. All but latency are linear in their parameters (features computed from the
//! inputs, the baseline and causal operators); latency searches a small grid of dead times and
//! first-order lag constants applied to the baseline's output.

use crate::baseline::{Baseline, Design, PoseStates};
use crate::cause::Cause;
use crate::data::Record;
use crate::lsq;
use crate::signal;

/// Dead times of the latency extension's coarse grid, in samples (refined to fractions).
const DELAYS: [f64; 8] = [0.0, 1.0, 2.0, 3.0, 5.0, 8.0, 13.0, 21.0];
/// Lag constants of the coarse grid, in sampling intervals (0 = none), refined afterwards.
const LAGS: [f64; 8] = [0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0];
/// Play-operator half-widths of the hysteresis extension, as fractions of the drive range.
const PLAY_WIDTHS: [f64; 6] = [0.005, 0.015, 0.035, 0.07, 0.14, 0.28];
/// Number of Prony time constants (log-spaced between 2 samples and a tenth of the record).
const PRONY_TERMS: usize = 7;

/// Extension features of one channel: columns, names and non-negativity flags.
pub type Features = (Vec<Vec<f64>>, Vec<String>, Vec<bool>);

/// One output channel, prepared with its baseline fit.
#[derive(Debug, Clone)]
pub struct ChannelFit {
    /// Measured output.
    pub y: Vec<f64>,
    /// Baseline design on the measured inputs.
    pub design: Design,
    /// Baseline coefficients fitted on the training rows.
    pub theta: Vec<f64>,
    /// Standard errors of `theta`.
    pub theta_se: Vec<f64>,
    /// Baseline prediction.
    pub yhat: Vec<f64>,
    /// Sensitivity of the prediction to a relative stiffness change.
    pub elastic: Vec<f64>,
    /// `d yhat / d u_k` per input.
    pub jac: Vec<Vec<f64>>,
    /// Sign of the mean sensitivity to each input (+1 when flat).
    pub sign: Vec<f64>,
}

/// A record prepared for identification: split, baseline fitted, sensitivities known.
#[derive(Debug, Clone)]
pub struct Prepared<'a> {
    /// The record.
    pub rec: &'a Record,
    /// The baseline.
    pub baseline: Baseline,
    /// Training rows.
    pub train: Vec<bool>,
    /// Held-out rows.
    pub test: Vec<bool>,
    /// Median sampling interval, seconds.
    pub dt: f64,
    /// Per-output fits.
    pub channels: Vec<ChannelFit>,
    /// Input ranges on the training rows.
    pub ranges: Vec<f64>,
    /// Input means on the training rows.
    pub means: Vec<f64>,
    /// Latency (dead time in samples, lag in samples) found by the single-cause fit.
    pub latency_hint: std::cell::Cell<Option<(f64, f64)>>,
    /// Column strains and tip sensitivities of the pose baseline (`None` for other kinds).
    pub pose: Option<PoseStates>,
}

/// The fit of a set of extensions.
#[derive(Debug, Clone)]
pub struct SetFit {
    /// Causes whose extensions are included.
    pub causes: Vec<Cause>,
    /// Prediction per channel on every row.
    pub pred: Vec<Vec<f64>>,
    /// Training RSS per channel.
    pub rss: Vec<f64>,
    /// Training rows per channel.
    pub rows: usize,
    /// Parameters used beyond the baseline's (coefficients plus grid hyper-parameters).
    pub extra_params: usize,
    /// Fitted extension parameters: (name, value, standard error).
    pub params: Vec<(String, f64, f64)>,
}

impl<'a> Prepared<'a> {
    /// Splits the record, fits the baseline and computes sensitivities.
    pub fn new(rec: &'a Record, baseline: Baseline, test: Vec<bool>) -> Prepared<'a> {
        let train: Vec<bool> = test.iter().map(|t| !t).collect();
        let n = rec.len();
        let cols: Vec<&[f64]> = rec.inputs.iter().map(|c| c.values.as_slice()).collect();
        let mut ranges = Vec::new();
        let mut means = Vec::new();
        for c in &rec.inputs {
            let tr: Vec<f64> = (0..n).filter(|&i| train[i]).map(|i| c.values[i]).collect();
            let lo = tr.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = tr.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let r = hi - lo;
            ranges.push(if r > 0.0 && r.is_finite() { r } else { 1.0 });
            means.push(signal::mean_std(&tr).0);
        }
        let mut channels = Vec::new();
        for (c, out) in rec.outputs.iter().enumerate() {
            let design = baseline.design(&cols, &rec.time_s, &rec.segment_starts, c);
            let target: Vec<f64> = out
                .values
                .iter()
                .zip(&design.fixed)
                .map(|(y, f)| y - f)
                .collect();
            let regs: Vec<&[f64]> = design.regressors.iter().map(|r| r.as_slice()).collect();
            let fit = lsq::fit(&regs, &target, &train, &design.nonneg);
            let mut yhat = lsq::predict(&regs, &fit.coef, n);
            for (p, f) in yhat.iter_mut().zip(&design.fixed) {
                *p += f;
            }
            let mut elastic = vec![0.0; n];
            for (j, r) in design.regressors.iter().enumerate() {
                if design.stiffness[j] {
                    for i in 0..n {
                        elastic[i] += fit.coef[j] * r[i];
                    }
                }
            }
            if let Some(fe) = &design.fixed_elastic {
                for i in 0..n {
                    elastic[i] += fe[i];
                }
            }
            // Central differences of the fitted baseline in each input.
            let mut jac = Vec::new();
            let mut sign = Vec::new();
            for k in 0..rec.inputs.len() {
                let h = 1e-4 * ranges[k];
                let eval = |delta: f64| -> Vec<f64> {
                    let shifted: Vec<f64> =
                        rec.inputs[k].values.iter().map(|v| v + delta).collect();
                    let mut cc = cols.clone();
                    cc[k] = &shifted;
                    let d = baseline.design(&cc, &rec.time_s, &rec.segment_starts, c);
                    let r: Vec<&[f64]> = d.regressors.iter().map(|r| r.as_slice()).collect();
                    let mut p = lsq::predict(&r, &fit.coef, n);
                    for (a, f) in p.iter_mut().zip(&d.fixed) {
                        *a += f;
                    }
                    p
                };
                let up = eval(h);
                let dn = eval(-h);
                let j: Vec<f64> = up
                    .iter()
                    .zip(&dn)
                    .map(|(a, b)| (a - b) / (2.0 * h))
                    .collect();
                let m: f64 = (0..n).filter(|&i| train[i]).map(|i| j[i]).sum();
                sign.push(if m < 0.0 { -1.0 } else { 1.0 });
                jac.push(j);
            }
            channels.push(ChannelFit {
                y: out.values.clone(),
                design,
                theta: fit.coef,
                theta_se: fit.std_err,
                yhat,
                elastic,
                jac,
                sign,
            });
        }
        let pose = baseline.pose_states(&cols);
        Prepared {
            rec,
            pose,
            baseline,
            train,
            test,
            dt: signal::median_dt(&rec.time_s),
            channels,
            ranges,
            means,
            latency_hint: std::cell::Cell::new(None),
        }
    }

    /// Prony time constants used by the rate-dependence extension, seconds.
    pub fn prony_taus(&self) -> Vec<f64> {
        let span = self.segment_span();
        let lo = 2.0 * self.dt;
        let hi = (span / 10.0).max(4.0 * lo);
        (0..PRONY_TERMS)
            .map(|i| lo * (hi / lo).powf(i as f64 / (PRONY_TERMS - 1) as f64))
            .collect()
    }

    fn segment_span(&self) -> f64 {
        let n = self.rec.len();
        signal::segments(&self.rec.segment_starts, n)
            .iter()
            .map(|&(s, e)| self.rec.time_s[e - 1] - self.rec.time_s[s])
            .fold(0.0, f64::max)
            .max(self.dt * 10.0)
    }

    /// Cycle-count and peak-deformation history variables of the damage extension, in [0, 1].
    pub fn damage_histories(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.rec.len();
        let mut path = vec![0.0; n];
        let mut peak = vec![0.0; n];
        for &k in &self.rec.drives {
            let u = &self.rec.inputs[k].values;
            let p = signal::path_length(u);
            let m = signal::running_peak(u, u[0]);
            for i in 0..n {
                path[i] += p[i] / self.ranges[k];
                peak[i] += m[i] / self.ranges[k];
            }
        }
        let norm = |v: &mut Vec<f64>| {
            let mx = v.iter().copied().fold(0.0, f64::max);
            if mx > 0.0 {
                v.iter_mut().for_each(|x| *x /= mx);
            }
        };
        norm(&mut path);
        norm(&mut peak);
        (path, peak)
    }

    /// Per column of the pose baseline: (column, its strain, channel `c`'s sensitivity to it).
    fn column_terms(&self, c: usize) -> Vec<(usize, &[f64], &[f64])> {
        match &self.pose {
            Some(ps) => (0..ps.strains.len())
                .map(|k| (k, ps.strains[k].as_slice(), ps.sens[c][k].as_slice()))
                .collect(),
            None => Vec::new(),
        }
    }

    /// Extension features of `cause` for channel `c`: (columns, names, non-negative flags).
    pub fn features(&self, cause: Cause, c: usize) -> Features {
        let rec = self.rec;
        let n = rec.len();
        let ch = &self.channels[c];
        let mut cols = Vec::new();
        let mut names = Vec::new();
        let mut nonneg = Vec::new();
        match cause {
            Cause::None | Cause::Latency => {}
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
                for &k in &rec.drives {
                    let u = &rec.inputs[k].values;
                    for &w in &PLAY_WIDTHS {
                        let r = w * self.ranges[k];
                        let p = signal::play(u, &rec.segment_starts, r);
                        cols.push((0..n).map(|i| ch.sign[k] * (u[i] - p[i])).collect());
                        names.push(format!("PI weight {} r={:.3}", rec.inputs[k].name, r));
                        nonneg.push(true);
                    }
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
                    names.push(format!("{} bias", rec.outputs[c].name));
                    nonneg.push(false);
                }
                for (k, inp) in rec.inputs.iter().enumerate() {
                    cols.push(ch.jac[k].clone());
                    names.push(format!("{} bias", inp.name));
                    nonneg.push(false);
                }
            }
            Cause::Gain => {
                for (k, inp) in rec.inputs.iter().enumerate() {
                    cols.push((0..n).map(|i| inp.values[i] * ch.jac[k][i]).collect());
                    names.push(format!("{} gain - 1", inp.name));
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
                // Complete polynomial up to degree 3 (the constant and linear terms keep the
                // correction centred wherever the mismatch is), less the terms an affine
                // baseline already has.
                let affine = matches!(self.baseline, Baseline::Series | Baseline::SeriesDynamic(_));
                if !affine {
                    cols.push(vec![1.0; n]);
                    names.push("constant".into());
                    nonneg.push(false);
                }
                for a in 0..k_in {
                    if !affine {
                        cols.push(z[a].clone());
                        names.push(rec.inputs[a].name.clone());
                        nonneg.push(false);
                    }
                    for b in a..k_in {
                        cols.push((0..n).map(|i| z[a][i] * z[b][i]).collect());
                        names.push(format!("{}*{}", rec.inputs[a].name, rec.inputs[b].name));
                        nonneg.push(false);
                        for d in b..k_in {
                            cols.push((0..n).map(|i| z[a][i] * z[b][i] * z[d][i]).collect());
                            names.push(format!(
                                "{}*{}*{}",
                                rec.inputs[a].name, rec.inputs[b].name, rec.inputs[d].name
                            ));
                            nonneg.push(false);
                        }
                    }
                }
            }
        }
        (cols, names, nonneg)
    }

    /// Fits the baseline plus the extensions of `causes` jointly on the training rows.
    pub fn fit_set(&self, causes: &[Cause]) -> SetFit {
        let rec = self.rec;
        let n = rec.len();
        let starts = &rec.segment_starts;
        let with_latency = causes.contains(&Cause::Latency);
        // Features do not depend on the latency hyper-parameters: compute them once.
        let feats: Vec<Features> = (0..self.channels.len())
            .map(|c| {
                let mut cols = Vec::new();
                let mut names = Vec::new();
                let mut nn = Vec::new();
                for &cause in causes {
                    let (a, b, d) = self.features(cause, c);
                    cols.extend(a);
                    names.extend(b);
                    nn.extend(d);
                }
                (cols, names, nn)
            })
            .collect();
        // Latency acts on the whole model output: a fractional dead time (linear
        // interpolation between samples) followed by a first-order lag.
        let lag = |x: &[f64], d: f64, tau: f64| -> Vec<f64> {
            let delayed = if d > 0.0 {
                let whole = d.floor() as usize;
                let frac = d - d.floor();
                let a = signal::delay_samples(x, starts, whole);
                if frac > 0.0 {
                    let b = signal::delay_samples(x, starts, whole + 1);
                    a.iter()
                        .zip(&b)
                        .map(|(p, q)| (1.0 - frac) * p + frac * q)
                        .collect()
                } else {
                    a
                }
            } else {
                x.to_vec()
            };
            if tau > 0.0 {
                signal::lowpass(&delayed, &rec.time_s, starts, tau)
            } else {
                delayed
            }
        };
        let fit_at = |d: f64, tau: f64| {
            let mut out = Vec::new();
            for (c, ch) in self.channels.iter().enumerate() {
                let shift = d > 0.0 || tau > 0.0;
                let tr = |x: &Vec<f64>| if shift { lag(x, d, tau) } else { x.clone() };
                let fixed = tr(&ch.design.fixed);
                let base: Vec<Vec<f64>> = ch.design.regressors.iter().map(tr).collect();
                let ext: Vec<Vec<f64>> = if shift {
                    feats[c].0.iter().map(tr).collect()
                } else {
                    Vec::new()
                };
                let ext_ref: &Vec<Vec<f64>> = if shift { &ext } else { &feats[c].0 };
                let target: Vec<f64> = ch.y.iter().zip(&fixed).map(|(y, f)| y - f).collect();
                let mut cols: Vec<&[f64]> = base.iter().map(|r| r.as_slice()).collect();
                cols.extend(ext_ref.iter().map(|r| r.as_slice()));
                let mut nn = ch.design.nonneg.clone();
                nn.extend(&feats[c].2);
                let fit = lsq::fit(&cols, &target, &self.train, &nn);
                let mut pred = lsq::predict(&cols, &fit.coef, n);
                for (p, f) in pred.iter_mut().zip(&fixed) {
                    *p += f;
                }
                out.push((fit, pred, base.len()));
            }
            out
        };
        let total_rss = |f: &Vec<(lsq::LsqFit, Vec<f64>, usize)>| -> f64 {
            f.iter()
                .zip(&self.channels)
                .map(|((fit, _, _), ch)| fit.rss / channel_scale(ch, &self.train))
                .sum()
        };
        let mut best = (0.0f64, 0.0f64);
        let mut fits = if with_latency {
            let max_delay = (n / 20) as f64;
            let mut best_rss = f64::INFINITY;
            let mut best_fit = None;
            let mut consider = |d: f64, m: f64, best: &mut (f64, f64)| -> f64 {
                if d < 0.0 || m < 0.0 || d > max_delay || (d == 0.0 && m == 0.0) {
                    return f64::INFINITY;
                }
                let f = fit_at(d, m * self.dt);
                let r = total_rss(&f);
                if r < best_rss {
                    best_rss = r;
                    *best = (d, m);
                    best_fit = Some(f);
                }
                r
            };
            // Sets with further causes reuse the single-cause latency estimate.
            let hint = if causes.len() > 1 {
                self.latency_hint.get()
            } else {
                None
            };
            if let Some((d_fix, m_fix)) = hint {
                // The single-cause estimate is biased by whatever else is in the data: refine
                // it locally with the other extensions in the fit (lag by golden section on
                // its log, then the dead time on quarter samples).
                consider(d_fix, m_fix, &mut best);
                let g = 0.5 * (5f64.sqrt() - 1.0);
                let centre = if m_fix > 0.0 {
                    m_fix.ln()
                } else {
                    (0.25f64).ln()
                };
                let (mut a, mut b) = (centre - 0.8, centre + 0.8);
                let mut x1 = b - g * (b - a);
                let mut x2 = a + g * (b - a);
                let mut f1 = consider(d_fix, x1.exp(), &mut best);
                let mut f2 = consider(d_fix, x2.exp(), &mut best);
                for _ in 0..5 {
                    if f1 < f2 {
                        b = x2;
                        x2 = x1;
                        f2 = f1;
                        x1 = b - g * (b - a);
                        f1 = consider(d_fix, x1.exp(), &mut best);
                    } else {
                        a = x1;
                        x1 = x2;
                        f1 = f2;
                        x2 = a + g * (b - a);
                        f2 = consider(d_fix, x2.exp(), &mut best);
                    }
                }
                let m_best = best.1;
                for step in [-0.5, -0.25, 0.25, 0.5] {
                    consider(d_fix + step, m_best, &mut best);
                }
            } else {
                for &d in &DELAYS {
                    for &m in &LAGS {
                        consider(d, m, &mut best);
                    }
                }
                // Dead time and lag trade off along a narrow valley: profile the dead time on
                // quarter samples and golden-search the log lag constant at each.
                let (d0, m0) = best;
                let centre = if m0 > 0.0 { m0.ln() } else { (0.25f64).ln() };
                let g = 0.5 * (5f64.sqrt() - 1.0);
                let mut d = (d0 - 2.0).max(0.0);
                while d <= (d0 + 2.0).min(max_delay) {
                    let (mut a, mut b) = (centre - 2.5, centre + 2.5);
                    let mut x1 = b - g * (b - a);
                    let mut x2 = a + g * (b - a);
                    let mut f1 = consider(d, x1.exp(), &mut best);
                    let mut f2 = consider(d, x2.exp(), &mut best);
                    for _ in 0..12 {
                        if f1 < f2 {
                            b = x2;
                            x2 = x1;
                            f2 = f1;
                            x1 = b - g * (b - a);
                            f1 = consider(d, x1.exp(), &mut best);
                        } else {
                            a = x1;
                            x1 = x2;
                            f1 = f2;
                            x2 = a + g * (b - a);
                            f2 = consider(d, x2.exp(), &mut best);
                        }
                    }
                    d += 0.25;
                }
                if causes.len() == 1 {
                    self.latency_hint.set(Some(best));
                }
            }
            best_fit.unwrap_or_else(|| fit_at(0.0, 0.0))
        } else {
            fit_at(0.0, 0.0)
        };
        // Standard errors of the latency parameters from the curvature of the residual sum of
        // squares (profile likelihood, Gaussian residuals): se = sqrt(2 s^2 / RSS'').
        let latency_se = if with_latency {
            let rows = self.train.iter().filter(|t| **t).count() * self.channels.len();
            let r0 = total_rss(&fits);
            let s2 = r0 / (rows.saturating_sub(1).max(1)) as f64;
            let curv_se = |f: &dyn Fn(f64) -> f64, x: f64, h: f64| -> f64 {
                let c = (f(x + h) - 2.0 * r0 + f(x - h)) / (h * h);
                if c > 0.0 {
                    (2.0 * s2 / c).sqrt()
                } else {
                    f64::INFINITY
                }
            };
            let (d, m) = best;
            let hd = 0.25;
            let se_d = if d >= hd {
                curv_se(&|x| total_rss(&fit_at(x, m * self.dt)), d, hd)
            } else {
                f64::NAN
            };
            let hm = (0.1 * m).max(0.05);
            let se_m = if m >= hm {
                curv_se(&|x| total_rss(&fit_at(d, x * self.dt)), m, hm)
            } else {
                f64::NAN
            };
            (se_d * self.dt, se_m * self.dt)
        } else {
            (0.0, 0.0)
        };
        let best = (best.0, best.1 * self.dt);
        let mut params = Vec::new();
        let mut extra = 0usize;
        let base_params: usize = self.channels.iter().map(|c| c.theta.len()).sum();
        let mut used = 0usize;
        let mut pred = Vec::new();
        let mut rss = Vec::new();
        let mut rows = 0;
        for (c, (fit, p, nb)) in fits.drain(..).enumerate() {
            used += fit.dof_used;
            for (j, name) in feats[c].1.iter().enumerate() {
                let v = fit.coef[nb + j];
                if v != 0.0 {
                    let label = if self.channels.len() > 1 {
                        format!("{} [{}]", name, rec.outputs[c].name)
                    } else {
                        name.clone()
                    };
                    params.push((label, v, fit.std_err[nb + j]));
                }
            }
            rows = fit.rows;
            rss.push(fit.rss);
            pred.push(p);
        }
        extra += used.saturating_sub(base_params);
        if with_latency {
            extra += 2;
            // NaN marks a parameter at its lower bound (no two-sided curvature).
            params.push(("dead time [s]".into(), best.0 * self.dt, latency_se.0));
            params.push(("lag time constant [s]".into(), best.1, latency_se.1));
        }
        SetFit {
            causes: causes.to_vec(),
            pred,
            rss,
            rows,
            extra_params: extra,
            params,
        }
    }
}

/// Range of a series (1 when flat or empty).
fn span(x: &[f64]) -> f64 {
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let r = hi - lo;
    if r > 0.0 && r.is_finite() { r } else { 1.0 }
}

/// Training mean square of a channel's baseline residual, used to weigh channels.
pub fn channel_scale(ch: &ChannelFit, train: &[bool]) -> f64 {
    let mut s = 0.0;
    let mut k = 0usize;
    for i in 0..ch.y.len() {
        if train[i] {
            let e = ch.y[i] - ch.yhat[i];
            s += e * e;
            k += 1;
        }
    }
    if k == 0 || s <= 0.0 {
        1.0
    } else {
        s / k as f64
    }
}
