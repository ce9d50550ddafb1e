//! Joint fit of the baseline's free coefficients and a set of extensions on the training
//! rows; latency searches its dead time and lag around the linear fit.

use super::features::Features;
use super::loop_signal::LoopSignal;
use super::prepared::{LatencyKey, Prepared, channel_scale};
use crate::baseline::Baseline;
use crate::cause::Cause;
use crate::lsq;
use crate::signal;
use rayon::prelude::*;

/// Dead times of the latency extension's coarse grid, in samples (refined to fractions).
const DELAYS: [f64; 8] = [0.0, 1.0, 2.0, 3.0, 5.0, 8.0, 13.0, 21.0];
/// Lag constants of the coarse grid, in sampling intervals (0 = none), refined afterwards.
const LAGS: [f64; 8] = [0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0];

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
    /// Output channels whose joint fit is ill-conditioned (see [`lsq::LsqFit`]).
    pub ill_conditioned: Vec<String>,
    /// Time constant (s) of the Laguerre filters when the actuator variant of `nonlinearity`
    /// was kept (see [`Prepared::fit_set`]); `None` otherwise.
    pub actuator_lag_s: Option<f64>,
}

/// The stacked fit of every output channel at once, where some extension columns are shared
/// (see `Prepared::shared_column`): the channels' rows one below the other, each weighted by
/// its baseline residual's scale (as the sets' training criterion weighs them), each channel's
/// own columns (its baseline's regressors and its own extension columns) in a block of its
/// rows, a shared column's per-channel values stacked into one column. Returned per channel
/// as the separate fits are: its coefficients (shared values repeated), its training RSS and
/// predictions; the shared coefficients count among the first channel's degrees of freedom.
fn fit_stacked(
    channels: &[super::ChannelFit],
    feats: &[Features],
    shared: &[Vec<bool>],
    train: &[bool],
    tr: &dyn Fn(&Vec<f64>) -> Vec<f64>,
) -> ChannelFits {
    let n = train.len();
    let m = channels.len();
    let rows = m * n;
    let weights: Vec<f64> = channels
        .iter()
        .map(|ch| 1.0 / channel_scale(ch, train).sqrt())
        .collect();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut nonneg: Vec<bool> = Vec::new();
    // per channel: the stacked column of each regressor, baseline's then extension's
    let mut index: Vec<Vec<usize>> = vec![Vec::new(); m];
    let mut shared_names: Vec<(String, usize)> = Vec::new();
    let mut fixed: Vec<Vec<f64>> = Vec::with_capacity(m);
    let mut own_cols: Vec<Vec<Vec<f64>>> = Vec::with_capacity(m);
    let mut target = vec![0.0; rows];
    for (c, ch) in channels.iter().enumerate() {
        let f = tr(&ch.design.fixed);
        for i in 0..n {
            target[c * n + i] = weights[c] * (ch.y[i] - f[i]);
        }
        fixed.push(f);
        let mut mine: Vec<Vec<f64>> = ch.design.regressors.iter().map(tr).collect();
        mine.extend(feats[c].0.iter().map(tr));
        let nn: Vec<bool> = ch
            .design
            .nonneg
            .iter()
            .chain(&feats[c].2)
            .copied()
            .collect();
        let nb = ch.design.regressors.len();
        for (j, col) in mine.iter().enumerate() {
            let is_shared = j >= nb && shared[c][j - nb];
            let at = if is_shared {
                let name = &feats[c].1[j - nb];
                match shared_names.iter().find(|(s, _)| s == name) {
                    Some(&(_, k)) => k,
                    None => {
                        cols.push(vec![0.0; rows]);
                        nonneg.push(nn[j]);
                        shared_names.push((name.clone(), cols.len() - 1));
                        cols.len() - 1
                    }
                }
            } else {
                cols.push(vec![0.0; rows]);
                nonneg.push(nn[j]);
                cols.len() - 1
            };
            for i in 0..n {
                cols[at][c * n + i] = weights[c] * col[i];
            }
            index[c].push(at);
        }
        own_cols.push(mine);
    }
    let mask: Vec<bool> = (0..m).flat_map(|_| train.iter().copied()).collect();
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let fit = lsq::fit(&refs, &target, &mask, &nonneg);
    let mut counted = vec![false; cols.len()];
    let mut out = Vec::with_capacity(m);
    for (c, ch) in channels.iter().enumerate() {
        let coef: Vec<f64> = index[c].iter().map(|&k| fit.coef[k]).collect();
        let std_err: Vec<f64> = index[c].iter().map(|&k| fit.std_err[k]).collect();
        let mine: Vec<&[f64]> = own_cols[c].iter().map(|v| v.as_slice()).collect();
        let mut pred = lsq::predict(&mine, &coef, n);
        for (p, f) in pred.iter_mut().zip(&fixed[c]) {
            *p += f;
        }
        let rss: f64 = (0..n)
            .filter(|&i| train[i])
            .map(|i| (ch.y[i] - pred[i]).powi(2))
            .sum();
        let mut dof_used = 0;
        for &k in &index[c] {
            if !counted[k] && fit.coef[k] != 0.0 {
                counted[k] = true;
                dof_used += 1;
            }
        }
        let nb = ch.design.regressors.len();
        out.push((
            lsq::LsqFit {
                coef,
                std_err,
                rss,
                rows: train.iter().filter(|t| **t).count(),
                dof_used,
                ill_conditioned: fit.ill_conditioned,
            },
            pred,
            nb,
        ));
    }
    out
}

/// Time constants (samples) of the Laguerre poles tried by the actuator variant of
/// `nonlinearity`: with 8 filters each spans a memory of about 16 to 400 samples.
const ACTUATOR_LAGS: [f64; 4] = [1.0, 3.0, 8.0, 24.0];

/// Per output channel: the least-squares fit, the prediction on every row and the number of
/// the baseline's regressors in the fit.
type ChannelFits = Vec<(lsq::LsqFit, Vec<f64>, usize)>;

/// A point of the latency search: training RSS, dead time and lag (samples), and the fit
/// (`None` outside the search's bounds).
type Point = (f64, f64, f64, Option<ChannelFits>);

/// Whether a sequential search would take this point: inside the bounds, with a finite RSS.
fn takeable(p: &Point) -> bool {
    p.3.is_some() && p.0 < f64::INFINITY
}

/// The earlier of two points of the search unless the later one is strictly lower: reduced
/// in the order the points are visited (associative, so in parallel too), this keeps the first
/// lowest point, as a sequential search that replaces its best only on a strict improvement
/// does.
fn earlier(a: Point, b: Point) -> Point {
    if takeable(&b) && (!takeable(&a) || b.0 < a.0) {
        b
    } else {
        a
    }
}

impl Prepared<'_> {
    /// Whether the coefficient of extension column `name` of `cause` on channel `c` is one
    /// parameter for every output channel. On a simulator record with several outputs that
    /// logs its sensitivities, an input's or a state's offset or gain is one number that
    /// reaches each output through that output's sensitivity (a regulator's offset moves one
    /// chamber's pressure whatever coordinate of the tip is watched); fitted per output, each
    /// cause had three times its parameters and the two fitted each other's effects on the
    /// lab's circle (see the README). With estimated sensitivities the per-output parameters
    /// stay: they absorb the estimate's error. Output biases and gains stay per channel; so
    /// does every other cause.
    fn shared_column(&self, cause: Cause, c: usize, name: &str) -> bool {
        self.sensitivities_logged
            && self.channels.len() > 1
            && matches!(cause, Cause::Offset | Cause::Gain)
            && !super::features::is_output_column(&self.rec.outputs[c].name, name)
    }

    /// Fits the baseline plus the extensions of `causes` jointly on the training rows.
    ///
    /// On a state-space baseline `nonlinearity` has two variants, and the one with the lower
    /// BIC on training rows is kept: stiffening inside the dynamics (a restoring force of the
    /// model's own coordinate, refined in the loop) and an actuator nonlinearity with dynamics
    /// of its own (each quadratic and cubic term of the inputs through 8 Laguerre filters,
    /// linear in their weights, at the best of four poles; the pole counts as a parameter).
    /// The first is what a structure with a stiffening spring needs, the second what a soft
    /// actuator needs whose pressure-to-force map is curved and slower than the structure (the
    /// soft arm, see the README). The second is tried for `nonlinearity` alone.
    pub fn fit_set(&self, causes: &[Cause]) -> SetFit {
        if matches!(self.baseline, Baseline::Simulator) && causes.contains(&Cause::Hysteresis) {
            // A simulator does not say whether its output lags its inputs or leads them (a
            // displacement driven by a force lags, a force driven by a displacement leads):
            // the memory is fitted in both orientations, with non-negative weights each, and
            // the lower BIC on training rows kept.
            let bic = |f: &SetFit| -> f64 {
                if !f.ill_conditioned.is_empty() {
                    return f64::INFINITY;
                }
                let rows = f.rows.max(1) as f64;
                f.rss.iter().map(|r| rows * r.max(1e-300).ln()).sum()
            };
            self.memory_sign.set(1.0);
            let leads = self.fit_set_variant(causes);
            self.memory_sign.set(-1.0);
            let lags = self.fit_set_variant(causes);
            self.memory_sign.set(1.0);
            return if bic(&lags) < bic(&leads) {
                lags
            } else {
                leads
            };
        }
        let stiffening = self.fit_set_variant(causes);
        // Alone only: the actuator variant is fitted outside the loop, so beside it a further
        // cause would lose its in-loop refinement (with it in sets, a friction beside a
        // stiffening went unnamed on the battery's pairs, 1 of 6 exact instead of 2).
        let applies = matches!(&self.baseline, Baseline::StateSpace(ss) if ss.order() > 0)
            && causes == [Cause::Nonlinearity]
            && self.pose.is_none();
        if !applies {
            return stiffening;
        }
        let rows = stiffening.rows.max(1) as f64;
        let total = rows * self.channels.len() as f64;
        let bic = |f: &SetFit| -> f64 {
            if !f.ill_conditioned.is_empty() {
                return f64::INFINITY;
            }
            let fit: f64 = f.rss.iter().map(|r| rows * r.max(1e-300).ln()).sum();
            fit + f.extra_params as f64 * total.ln()
        };
        let mut best = stiffening;
        let mut best_bic = bic(&best);
        for lag in ACTUATOR_LAGS {
            self.actuator_pole.set(Some((-1.0 / lag).exp()));
            let mut f = self.fit_set_variant(causes);
            self.actuator_pole.set(None);
            f.extra_params += 1;
            f.actuator_lag_s = Some(lag * self.dt);
            let b = bic(&f);
            if b < best_bic {
                best_bic = b;
                best = f;
            }
        }
        best
    }

    /// [`Prepared::fit_set`] for the variant of `nonlinearity` set by `actuator_pole`.
    fn fit_set_variant(&self, causes: &[Cause]) -> SetFit {
        if !causes.contains(&Cause::Latency) {
            return self.fit_set_computed(causes);
        }
        let key = LatencyKey {
            causes: causes.to_vec(),
            flexible: self.flexible.get(),
            memory_sign: self.memory_sign.get().to_bits(),
            actuator_pole: self.actuator_pole.get().map(f64::to_bits),
            hint: (causes.len() > 1)
                .then(|| self.latency_hint.get())
                .flatten()
                .map(|(d, m)| (d.to_bits(), m.to_bits())),
        };
        let hit = self
            .latency_fits
            .borrow()
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, f)| f.clone());
        if let Some(f) = hit {
            return f;
        }
        let f = self.fit_set_computed(causes);
        self.latency_fits.borrow_mut().push((key, f.clone()));
        f
    }

    /// [`Prepared::fit_set_variant`] without the store of latency fits.
    fn fit_set_computed(&self, causes: &[Cause]) -> SetFit {
        let rec = self.rec;
        let n = rec.len();
        let starts = &rec.segment_starts;
        let with_latency = causes.contains(&Cause::Latency);
        // Features do not depend on the latency hyper-parameters: compute them once.
        let (feats, shared): (Vec<Features>, Vec<Vec<bool>>) = (0..self.channels.len())
            .map(|c| {
                let mut cols = Vec::new();
                let mut names = Vec::new();
                let mut nn = Vec::new();
                let mut one = Vec::new();
                for &cause in causes {
                    let (a, b, d) = self.features(cause, c);
                    one.extend(b.iter().map(|name| self.shared_column(cause, c, name)));
                    cols.extend(a);
                    names.extend(b);
                    nn.extend(d);
                }
                ((cols, names, nn), one)
            })
            .unzip();
        let shared = &shared;
        // Latency acts on the whole model output: a fractional dead time (linear
        // interpolation between samples) followed by a first-order lag.
        let lag = |x: &[f64], d: f64, tau: f64, factors: &[f64]| -> Vec<f64> {
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
                signal::lowpass_with(&delayed, starts, factors)
            } else {
                delayed
            }
        };
        // only `Sync` parts of the record are captured: the grid and the profile run in parallel
        let (channels, train, dt) = (&self.channels, &self.train, self.dt);
        let feats = &feats;
        let fit_at = |d: f64, tau: f64| -> ChannelFits {
            let mut out = Vec::new();
            // one set of low-pass factors for every column of every channel
            let factors = if tau > 0.0 {
                signal::lowpass_factors(&rec.time_s, tau)
            } else {
                Vec::new()
            };
            let shift = d > 0.0 || tau > 0.0;
            let tr = |x: &Vec<f64>| {
                if shift {
                    lag(x, d, tau, &factors)
                } else {
                    x.clone()
                }
            };
            if shared.iter().flatten().any(|s| *s) {
                return fit_stacked(channels, feats, shared, train, &tr);
            }
            for (c, ch) in channels.iter().enumerate() {
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
                let fit = lsq::fit(&cols, &target, train, &nn);
                let mut pred = lsq::predict(&cols, &fit.coef, n);
                for (p, f) in pred.iter_mut().zip(&fixed) {
                    *p += f;
                }
                out.push((fit, pred, base.len()));
            }
            out
        };
        let total_rss = |f: &ChannelFits| -> f64 {
            f.iter()
                .zip(channels)
                .map(|((fit, _, _), ch)| fit.rss / channel_scale(ch, train))
                .sum()
        };
        let mut best = (0.0f64, 0.0f64);
        let mut fits = if with_latency {
            let max_delay = (n / 20) as f64;
            // One point of the search: its training RSS (infinite outside the search's
            // bounds) and its fit.
            let eval = |d: f64, m: f64| -> Point {
                if d < 0.0 || m < 0.0 || d > max_delay || (d == 0.0 && m == 0.0) {
                    return (f64::INFINITY, d, m, None);
                }
                let f = fit_at(d, m * dt);
                (total_rss(&f), d, m, Some(f))
            };
            // A golden-section search of the log lag at dead time `d` over `[a, b]`: every
            // point visited, in the order visited, reduced to the first lowest (see `earlier`).
            let golden = |d: f64, mut a: f64, mut b: f64, iters: usize| -> Point {
                let g = 0.5 * (5f64.sqrt() - 1.0);
                let mut x1 = b - g * (b - a);
                let mut x2 = a + g * (b - a);
                let p1 = eval(d, x1.exp());
                let p2 = eval(d, x2.exp());
                let (mut f1, mut f2) = (p1.0, p2.0);
                let mut kept = earlier(p1, p2);
                for _ in 0..iters {
                    let p = if f1 < f2 {
                        b = x2;
                        x2 = x1;
                        f2 = f1;
                        x1 = b - g * (b - a);
                        let p = eval(d, x1.exp());
                        f1 = p.0;
                        p
                    } else {
                        a = x1;
                        x1 = x2;
                        f1 = f2;
                        x2 = a + g * (b - a);
                        let p = eval(d, x2.exp());
                        f2 = p.0;
                        p
                    };
                    kept = earlier(kept, p);
                }
                kept
            };
            // Sets with further causes reuse the single-cause latency estimate.
            let hint = if causes.len() > 1 {
                self.latency_hint.get()
            } else {
                None
            };
            let found = if let Some((d_fix, m_fix)) = hint {
                // The single-cause estimate is biased by whatever else is in the data: refine
                // it locally with the other extensions in the fit (lag by golden section on
                // its log, then the dead time on quarter samples).
                let centre = if m_fix > 0.0 {
                    m_fix.ln()
                } else {
                    (0.25f64).ln()
                };
                let mut kept = eval(d_fix, m_fix);
                kept = earlier(kept, golden(d_fix, centre - 0.8, centre + 0.8, 5));
                let m_best = if takeable(&kept) { kept.2 } else { 0.0 };
                let steps: Vec<Point> = [-0.5, -0.25, 0.25, 0.5]
                    .into_par_iter()
                    .map(|step| eval(d_fix + step, m_best))
                    .collect();
                steps.into_iter().fold(kept, earlier)
            } else {
                let grid: Vec<(f64, f64)> = DELAYS
                    .iter()
                    .flat_map(|&d| LAGS.iter().map(move |&m| (d, m)))
                    .collect();
                let coarse = grid
                    .into_par_iter()
                    .map(|(d, m)| eval(d, m))
                    .reduce_with(earlier)
                    .unwrap_or((f64::INFINITY, 0.0, 0.0, None));
                // Dead time and lag trade off along a narrow valley: profile the dead time on
                // quarter samples and golden-search the log lag constant at each.
                let (d0, m0) = if takeable(&coarse) {
                    (coarse.1, coarse.2)
                } else {
                    (0.0, 0.0)
                };
                let centre = if m0 > 0.0 { m0.ln() } else { (0.25f64).ln() };
                let mut profile = Vec::new();
                let mut d = (d0 - 2.0).max(0.0);
                while d <= (d0 + 2.0).min(max_delay) {
                    profile.push(d);
                    d += 0.25;
                }
                let fine = profile
                    .into_par_iter()
                    .map(|d| golden(d, centre - 2.5, centre + 2.5, 12))
                    .reduce_with(earlier);
                fine.into_iter().fold(coarse, earlier)
            };
            let taken = takeable(&found);
            let (_, d, m, fit) = found;
            if taken {
                best = (d, m);
            }
            if causes.len() == 1 && hint.is_none() {
                self.latency_hint.set(Some(best));
            }
            fit.filter(|_| taken).unwrap_or_else(|| fit_at(0.0, 0.0))
        } else {
            fit_at(0.0, 0.0)
        };
        let mut in_loop_extra = 0usize;
        // Extensions inside the dynamics of a state-space baseline: refine them in the loop
        // (see `in_loop`), keeping the linear fit where that does not lower the training error.
        if let Baseline::StateSpace(ss) = &self.baseline
            && !with_latency
            && ss.order() > 0
            && !causes.is_empty()
        {
            for (c, (fit, pred, nb)) in fits.iter_mut().enumerate() {
                let groups: Option<Vec<Vec<LoopSignal>>> = causes
                    .iter()
                    .map(|&cause| {
                        self.loop_signals(cause, c)
                            .map(|v| v.into_iter().map(|(s, _)| s).collect())
                    })
                    .collect();
                let Some(groups) = groups else { continue };
                if let Some(il) = self.refine_in_loop(ss, c, causes, &groups, &fit.coef)
                    && il.rss < fit.rss
                {
                    in_loop_extra += il.extra;
                    fit.rss = il.rss;
                    *pred = il.pred;
                    for (j, (w, se)) in il.weights.into_iter().enumerate() {
                        fit.coef[*nb + j] = w;
                        fit.std_err[*nb + j] = se;
                    }
                }
            }
        }
        // Standard errors of the latency parameters from the curvature of the residual sum of
        // squares (profile likelihood, Gaussian residuals): se = sqrt(2 s^2 / RSS'').
        let latency_se = if with_latency {
            let rows = train.iter().filter(|t| **t).count() * self.channels.len();
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
                curv_se(&|x| total_rss(&fit_at(x, m * dt)), d, hd)
            } else {
                f64::NAN
            };
            let hm = (0.1 * m).max(0.05);
            let se_m = if m >= hm {
                curv_se(&|x| total_rss(&fit_at(d, x * dt)), m, hm)
            } else {
                f64::NAN
            };
            (se_d * dt, se_m * dt)
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
        let mut ill_conditioned = Vec::new();
        for (c, (fit, p, nb)) in fits.drain(..).enumerate() {
            used += fit.dof_used;
            if fit.ill_conditioned || p.iter().any(|v| !v.is_finite()) {
                ill_conditioned.push(rec.outputs[c].name.clone());
            }
            for (j, name) in feats[c].1.iter().enumerate() {
                let v = fit.coef[nb + j];
                let once = shared[c][j];
                if once && c > 0 {
                    // one parameter for every output, listed with the first
                    continue;
                }
                if v != 0.0 {
                    let label = if self.channels.len() > 1 && !once {
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
        extra += used.saturating_sub(base_params) + in_loop_extra;
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
            ill_conditioned,
            actuator_lag_s: None,
        }
    }
}
