//! A record prepared for identification: the baseline fitted per output channel, its input
//! sensitivities, and the history variables the extensions are built from.

use crate::baseline::{Baseline, Design, PoseStates};
use crate::cause::Cause;
use crate::data::Record;
use crate::lsq;
use crate::signal;

/// Number of Prony time constants (log-spaced between 2 samples and a tenth of the record).
const PRONY_TERMS: usize = 7;

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
    /// On a simulator record whose states (`x_` columns) determine its output: `d sim / d x_j`
    /// per state, row by row (see [`STATES_DETERMINE_R2`]); empty otherwise.
    pub state_jac: Vec<Vec<f64>>,
    /// True when the baseline's own fit is ill-conditioned (see [`lsq::LsqFit`]).
    pub ill_conditioned: bool,
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
    /// True on a simulator record that logs its sensitivities to its states for every
    /// output (`dsim_` columns): then offsets and gains of its inputs and states are one
    /// parameter for all outputs (see `joint_fit`).
    pub sensitivities_logged: bool,
    /// Latency (dead time in samples, lag in samples) found by the single-cause fit.
    pub latency_hint: std::cell::Cell<Option<(f64, f64)>>,
    /// Column strains and tip sensitivities of the pose baseline (`None` for other kinds).
    pub pose: Option<PoseStates>,
    /// The cause whose most flexible variant is fitted (while a further cause is tested
    /// against it), if any.
    pub flexible: std::cell::Cell<Option<Cause>>,
    /// While the actuator variant of `nonlinearity` on a state-space baseline is fitted: the
    /// pole of the Laguerre filters that give each nonlinear input term its own dynamics (see
    /// `joint_fit`); `None` for the stiffening variant and every other baseline.
    pub actuator_pole: std::cell::Cell<Option<f64>>,
    /// In-loop refinements already done, per channel and set of causes (see `in_loop`): the
    /// selection fits the same sets repeatedly, and a larger set starts from a smaller one.
    pub(super) in_loop_cache: std::cell::RefCell<Vec<super::refined::Cached>>,
    /// Orientation of the hysteresis on a simulator record, +1 or -1: whether the measured
    /// output leads the simulated one through the memory in its inputs or lags it (see
    /// `joint_fit`: both are fitted, the lower BIC kept).
    pub memory_sign: std::cell::Cell<f64>,
    /// Fits of sets with latency, by everything they depend on (see `joint_fit`): they are
    /// not refined in the loop, so a repeated set (a swap back to a single cause, the
    /// backward check) gives the same fit, and its dead-time search is the selection's
    /// costliest.
    pub(super) latency_fits: std::cell::RefCell<Vec<(LatencyKey, super::SetFit)>>,
}

/// What the fit of a set with latency depends on beyond the record: the set, the flexible
/// cause, the hysteresis orientation, the actuator pole and (for a set of several causes) the
/// single-cause latency estimate it starts from; floats by their bits.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct LatencyKey {
    pub(super) causes: Vec<Cause>,
    pub(super) flexible: Option<Cause>,
    pub(super) memory_sign: u64,
    pub(super) actuator_pole: Option<u64>,
    pub(super) hint: Option<(u64, u64)>,
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
        // which input each state follows, and its slope in it: the same for every channel
        let followed = if rec.sensitivities.is_empty() {
            None
        } else {
            states_following_inputs(rec, &train)
        };
        let mut channels = Vec::new();
        for (c, out) in rec.outputs.iter().enumerate() {
            let design =
                baseline.design(&cols, &rec.time_s, &rec.segment_starts, c, &rec.simulated);
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
            let simulator = matches!(baseline, Baseline::Simulator);
            let input_map = simulator
                .then(|| SimulatorMap::fit(&cols, &rec.simulated[c].values, &means, &ranges))
                .flatten();
            let state_jac = if simulator {
                state_sensitivities(rec, c, &train)
            } else {
                Vec::new()
            };
            // only through sensitivities the simulator logs (estimated ones are extrapolated
            // across the curve the states lie on, and the chain inherits that error), and only
            // where the states determine the output (else an input also acts directly)
            let through_states = match &followed {
                Some(f)
                    if rec.logged_sensitivities(c).is_some()
                        && states_map(rec, c, &train).is_some() =>
                {
                    input_sensitivities_through_states(rec.inputs.len(), f, &state_jac)
                }
                _ => None,
            };
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
                    let d =
                        baseline.design(&cc, &rec.time_s, &rec.segment_starts, c, &rec.simulated);
                    let r: Vec<&[f64]> = d.regressors.iter().map(|r| r.as_slice()).collect();
                    let mut p = lsq::predict(&r, &fit.coef, n);
                    for (a, f) in p.iter_mut().zip(&d.fixed) {
                        *a += f;
                    }
                    p
                };
                let j: Vec<f64> = if let Some(through) = &through_states {
                    through[k].clone()
                } else if let Some(map) = &input_map {
                    // the simulator's output is given, not a function ident can evaluate:
                    // its sensitivity to each input is read off the simulated rows
                    map.derivative(k)
                } else if simulator {
                    vec![0.0; n]
                } else {
                    let up = eval(h);
                    let dn = eval(-h);
                    up.iter()
                        .zip(&dn)
                        .map(|(a, b)| (a - b) / (2.0 * h))
                        .collect()
                };
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
                state_jac,
                ill_conditioned: fit.ill_conditioned,
            });
        }
        let pose = baseline.pose_states(&cols);
        let sensitivities_logged = matches!(baseline, Baseline::Simulator)
            && (0..rec.outputs.len()).all(|c| rec.logged_sensitivities(c).is_some());
        Prepared {
            rec,
            sensitivities_logged,
            pose,
            baseline,
            train,
            test,
            dt: signal::median_dt(&rec.time_s),
            channels,
            ranges,
            means,
            latency_hint: std::cell::Cell::new(None),
            flexible: std::cell::Cell::new(None),
            actuator_pole: std::cell::Cell::new(None),
            in_loop_cache: std::cell::RefCell::new(Vec::new()),
            memory_sign: std::cell::Cell::new(1.0),
            latency_fits: std::cell::RefCell::new(Vec::new()),
        }
    }

    /// Measurement noise RMS estimated from the baseline's training residual: robust second
    /// differences per channel (see [`signal::noise_sd`]), pooled like the RMSE. A model error
    /// that is smooth at the sampling rate does not enter it.
    pub fn noise_rmse(&self) -> f64 {
        let ms: f64 = self
            .channels
            .iter()
            .map(|ch| {
                let r: Vec<f64> = ch.y.iter().zip(&ch.yhat).map(|(a, b)| a - b).collect();
                signal::noise_sd(&r, &self.rec.segment_starts, &self.train).powi(2)
            })
            .sum::<f64>()
            / self.channels.len().max(1) as f64;
        ms.sqrt()
    }

    /// The candidate causes for this record: the fixed seven, and friction where the record
    /// has a position whose velocity the friction force follows (the simulator's states).
    pub fn candidates(&self) -> Vec<Cause> {
        let mut c = Cause::CANDIDATES.to_vec();
        let dynamic = matches!(&self.baseline, Baseline::StateSpace(ss) if ss.order() > 0);
        if dynamic || !self.velocities().is_empty() {
            c.push(Cause::Friction);
        }
        c
    }

    /// Velocity sources of the friction extension: (name, velocity, smoothing scale `v0` of its
    /// sign). The velocity is a central difference over +-2 samples (quantised positions); `v0`
    /// is 5 % of the 95th percentile of `|v|` on the training rows, so the sign switches within
    /// a few percent of the typical speed.
    pub fn velocities(&self) -> Vec<(String, Vec<f64>, f64)> {
        let rec = self.rec;
        rec.states
            .iter()
            .filter_map(|s| {
                let v = signal::central_rate(&s.values, &rec.time_s, &rec.segment_starts, 2);
                let mut a: Vec<f64> = (0..v.len())
                    .filter(|&i| self.train[i])
                    .map(|i| v[i].abs())
                    .collect();
                if a.is_empty() {
                    return None;
                }
                let k = (a.len() * 95 / 100).min(a.len() - 1);
                let (_, p95, _) = a.select_nth_unstable_by(k, |x, y| x.total_cmp(y));
                let v0 = 0.05 * *p95;
                (v0 > 0.0 && v0.is_finite()).then(|| (s.name.clone(), v, v0))
            })
            .collect()
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
    pub(super) fn column_terms(&self, c: usize) -> Vec<(usize, &[f64], &[f64])> {
        match &self.pose {
            Some(ps) => (0..ps.strains.len())
                .map(|k| (k, ps.strains[k].as_slice(), ps.sens[c][k].as_slice()))
                .collect(),
            None => Vec::new(),
        }
    }
}

/// Range of a series (1 when flat or empty).
pub(super) fn span(x: &[f64]) -> f64 {
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

/// Share of the simulated output's variance on the training rows that a cubic in the
/// simulator's states must explain for the states to count as determining it. A kinematic map
/// (a tip from the column lengths) is fitted to 1e-6 or better; a simulator whose output also
/// depends on what the states do not carry (a force from a pressure, with the displacement as
/// its state) falls far short, and its states then only feed friction.
pub const STATES_DETERMINE_R2: f64 = 0.9999;

/// Per state `x_j` of a simulator record, `d sim_c / d x_j` row by row: as the simulator logs
/// them (`dsim_` columns), or else, when the states
/// determine the simulated output of channel `c` (a cubic in them explains at least
/// [`STATES_DETERMINE_R2`] of its training variance; at most four states, the most a cubic
/// map is fitted in); empty otherwise. An effect inside the
/// simulator then acts on its states: memory in a state, a state off by a constant or a
/// factor, each reaching the output through this sensitivity.
fn state_sensitivities(rec: &Record, c: usize, train: &[bool]) -> Vec<Vec<f64>> {
    if let Some(logged) = rec.logged_sensitivities(c) {
        // the simulator knows them exactly, also across the curve the record's states lie on
        return logged.into_iter().map(<[f64]>::to_vec).collect();
    }
    match states_map(rec, c, train) {
        Some(map) => (0..rec.states.len()).map(|j| map.derivative(j)).collect(),
        None => Vec::new(),
    }
}

/// The simulated output of channel `c` as a cubic in the states, when the states determine it
/// (the cubic explains at least [`STATES_DETERMINE_R2`] of its training variance; at most four
/// states); `None` otherwise.
fn states_map(rec: &Record, c: usize, train: &[bool]) -> Option<SimulatorMap> {
    if rec.states.is_empty() || rec.states.len() > 4 {
        return None;
    }
    let cols: Vec<&[f64]> = rec.states.iter().map(|s| s.values.as_slice()).collect();
    let mut means = Vec::new();
    let mut ranges = Vec::new();
    for x in &cols {
        let tr: Vec<f64> = (0..x.len()).filter(|&i| train[i]).map(|i| x[i]).collect();
        means.push(signal::mean_std(&tr).0);
        ranges.push(span(&tr));
    }
    let sim = &rec.simulated[c].values;
    SimulatorMap::fit(&cols, sim, &means, &ranges)
        .filter(|map| map.r2(sim, train) >= STATES_DETERMINE_R2)
}

/// Share of a state's training variance that a cubic in one input alone must explain for the
/// state to count as following that input. A column's elongation follows its own chamber's
/// command through the regulator's lag at 99.7 % (the lag is what the cubic misses); a state
/// driven by several inputs falls well short against each of them.
pub const STATE_FOLLOWS_INPUT_R2: f64 = 0.99;

/// Per state, the input it follows alone (a cubic in that input explains at least
/// [`STATE_FOLLOWS_INPUT_R2`] of the state's training variance) and `d x_j / d u_k` row by row,
/// read off that cubic; `None` when a state follows no single input.
fn states_following_inputs(rec: &Record, train: &[bool]) -> Option<Vec<(usize, Vec<f64>)>> {
    let n = rec.len();
    rec.states
        .iter()
        .map(|st| {
            let x = st.values.as_slice();
            let mut best: Option<(f64, usize, SimulatorMap)> = None;
            for (k, inp) in rec.inputs.iter().enumerate() {
                let u = inp.values.as_slice();
                let tr: Vec<f64> = (0..n).filter(|&i| train[i]).map(|i| u[i]).collect();
                let (mean, _) = signal::mean_std(&tr);
                let Some(map) = SimulatorMap::fit(&[u], x, &[mean], &[span(&tr)]) else {
                    continue;
                };
                let r2 = map.r2(x, train);
                if best.as_ref().is_none_or(|(b, _, _)| r2 > *b) {
                    best = Some((r2, k, map));
                }
            }
            let (r2, k, map) = best?;
            (r2 >= STATE_FOLLOWS_INPUT_R2).then(|| (k, map.derivative(0)))
        })
        .collect()
}

/// On a simulator record that logs its sensitivities (`state_jac`), whose states determine its
/// output, and where each state follows one input alone (`followed`, from
/// [`states_following_inputs`]): `d sim / d u_k` per input, row by row, as the chain
/// `sum_j d sim / d x_j * d x_j / d u_k` over the states that follow `u_k`; `None` when the
/// chain is zero.
///
/// Why: a simulator's inputs often lie on one curve in their space (a circle's three pressure
/// commands), where a polynomial of the output in all inputs at once has its derivatives across
/// the curve extrapolated. Each state as a function of its own input is a curve in one
/// variable, which the record covers; an input offset then moves each state by its local
/// slope, the shape a regulator's constant offset gives.
fn input_sensitivities_through_states(
    inputs: usize,
    followed: &[(usize, Vec<f64>)],
    state_jac: &[Vec<f64>],
) -> Option<Vec<Vec<f64>>> {
    let n = state_jac.first().map_or(0, Vec::len);
    let mut through = vec![vec![0.0; n]; inputs];
    for ((k, dx), jx) in followed.iter().zip(state_jac) {
        for ((t, d), j) in through[*k].iter_mut().zip(dx).zip(jx) {
            *t += j * d;
        }
    }
    through
        .iter()
        .any(|t| t.iter().any(|v| *v != 0.0))
        .then_some(through)
}

/// A simulator's output as a complete polynomial in normalised columns (its inputs or its
/// states), fitted on every row: cubic up to 4 columns, quadratic up to 8, linear beyond. A
/// simulator that responds to its inputs with a delay or dynamics is read as its best static
/// map; the map only orients and scales the extensions that act through those columns (an
/// offset, a gain, memory), it never enters the baseline.
struct SimulatorMap {
    /// Exponent tuple of each monomial (total degree 1 to the degree).
    exps: Vec<Vec<u32>>,
    /// Coefficients: the constant, then one per monomial.
    coef: Vec<f64>,
    /// Normalised columns, `(x - mean) / range`.
    z: Vec<Vec<f64>>,
    /// Ranges the columns were normalised by.
    ranges: Vec<f64>,
}

impl SimulatorMap {
    /// Fits the polynomial; `None` when the fit is not finite.
    fn fit(cols: &[&[f64]], sim: &[f64], means: &[f64], ranges: &[f64]) -> Option<SimulatorMap> {
        let m = cols.len();
        let n = sim.len();
        let degree = match m {
            0..=4 => 3,
            5..=8 => 2,
            _ => 1,
        };
        // exponent tuples of every monomial of total degree 1..=degree
        fn tuples(m: usize, left: usize, prefix: &mut Vec<u32>, out: &mut Vec<Vec<u32>>) {
            if prefix.len() == m {
                if prefix.iter().any(|e| *e > 0) {
                    out.push(prefix.clone());
                }
                return;
            }
            for e in 0..=left {
                prefix.push(e as u32);
                tuples(m, left - e, prefix, out);
                prefix.pop();
            }
        }
        let mut exps = Vec::new();
        tuples(m, degree, &mut Vec::new(), &mut exps);
        let z: Vec<Vec<f64>> = (0..m)
            .map(|j| cols[j].iter().map(|u| (u - means[j]) / ranges[j]).collect())
            .collect();
        let mut map = SimulatorMap {
            exps,
            coef: Vec::new(),
            z,
            ranges: ranges.to_vec(),
        };
        let mut basis: Vec<Vec<f64>> = vec![vec![1.0; n]];
        basis.extend(
            map.exps
                .iter()
                .map(|e| (0..n).map(|i| map.mono(e, i)).collect()),
        );
        let refs: Vec<&[f64]> = basis.iter().map(|c| c.as_slice()).collect();
        let fit = lsq::fit(&refs, sim, &vec![true; n], &[]);
        if fit.coef.iter().any(|c| !c.is_finite()) {
            return None;
        }
        map.coef = fit.coef;
        Some(map)
    }

    /// One monomial at row `i`.
    fn mono(&self, e: &[u32], i: usize) -> f64 {
        self.z
            .iter()
            .zip(e)
            .map(|(z, p)| z[i].powi(*p as i32))
            .product()
    }

    /// The map's value at row `i`.
    fn value(&self, i: usize) -> f64 {
        self.coef[0]
            + self
                .exps
                .iter()
                .zip(&self.coef[1..])
                .map(|(e, c)| c * self.mono(e, i))
                .sum::<f64>()
    }

    /// Share of the variance of `sim` on the rows in `rows` that the map explains.
    fn r2(&self, sim: &[f64], rows: &[bool]) -> f64 {
        let idx: Vec<usize> = (0..sim.len()).filter(|&i| rows[i]).collect();
        let vals: Vec<f64> = idx.iter().map(|&i| sim[i]).collect();
        let (m, _) = signal::mean_std(&vals);
        let tot: f64 = vals.iter().map(|v| (v - m) * (v - m)).sum();
        let res: f64 = idx.iter().map(|&i| (sim[i] - self.value(i)).powi(2)).sum();
        if tot > 0.0 { 1.0 - res / tot } else { 0.0 }
    }

    /// Derivative of the map in column `k`, row by row, in the column's own units.
    fn derivative(&self, k: usize) -> Vec<f64> {
        let n = self.z.first().map_or(0, |z| z.len());
        (0..n)
            .map(|i| {
                self.exps
                    .iter()
                    .zip(&self.coef[1..])
                    .filter(|(e, _)| e[k] > 0)
                    .map(|(e, c)| {
                        let mut d = e.to_vec();
                        d[k] -= 1;
                        c * f64::from(e[k]) * self.mono(&d, i)
                    })
                    .sum::<f64>()
                    / self.ranges[k]
            })
            .collect()
    }
}
