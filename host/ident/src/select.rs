//! Cause selection: every extension is scored against the current model by
//!
//! 1. the Bayesian information criterion on the training rows,
//!    `dBIC = sum_c n ln(RSS_ext,c / RSS_ref,c) + k ln(N)`, which must fall below
//!    `-bic_margin` (strong evidence);
//! 2. the held-out gain `100 (1 - RMSE_ext / RMSE_ref)`, which must reach `min_gain_pct`;
//! 3. a false-discovery guard: the nested-model F test on the training rows must reject "no
//!    improvement" at significance `alpha` divided by the number of candidates (Bonferroni).
//!
//! A held-out Newey-West t statistic of the squared-error reduction is reported as evidence.
//!
//! The cause with the best (most negative) `dBIC` among those passing all three is named
//! (or a passing one whose held-out RMSE is lower by at least `min_extra_gain_pct`);
//! further causes are added greedily while the combined extension passes the same three tests
//! against the current one and gains at least `min_extra_gain_pct` more on held-out data, and
//! does the same against the most flexible variant of the first cause (each inside its own
//! class: hysteresis with a narrower loop, friction with stiffer pre-sliding, stiffening to
//! higher powers), so that the leftovers of an imperfect first extension are not named as a
//! second cause.
//! Finally each named cause is swapped for an unnamed one when that improves the BIC by more
//! than the margin, or when the swapped set has fewer parameters and a BIC within the margin
//! (parsimony when one extension's span contains another's: Occam's window), unless the swap
//! loses held-out accuracy. Last, every named
//! cause must still pass the addition tests against the others, or the weakest is dropped.
//! No passing candidate means `none`.
//!
//! A noise-free record (estimated noise below `noise_free_ratio` of the baseline's held-out
//! RMSE: a simulator's or a virtual lab's log) makes every difference between fits
//! significant, so there relevance decides: the first cause is the one with the fewest
//! parameters among the passing candidates within `relevance_pct` of the baseline's RMSE of
//! the best held-out RMSE, and each further cause must remove `relevance_pct` of the
//! baseline's RMSE.

use serde::Serialize;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use ocm_shared::params::ParamPreset;

use crate::baseline::{Baseline, SeriesModel};
use crate::cause::Cause;
use crate::direction::{DirectionTest, direction_tests};
use crate::extension::{Prepared, SetFit, channel_scale};

/// Selection settings.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Config {
    /// Family-wise significance of the false-discovery guard.
    pub alpha: f64,
    /// Smallest held-out RMSE gain, percent, for a cause to count.
    pub min_gain_pct: f64,
    /// Required BIC improvement.
    pub bic_margin: f64,
    /// Most causes named.
    pub max_causes: usize,
    /// Smallest further held-out gain, percent over the current extension, for each added cause.
    pub min_extra_gain_pct: f64,
    /// Bandwidth (lags) of the Newey-West variance in the held-out t-test.
    pub hac_lags: usize,
    /// On a noise-free record (see `noise_free_ratio`): the smallest share, percent, of the
    /// baseline's held-out RMSE that each further cause must remove. There every difference
    /// between two fits is significant, so significance cannot tell a second cause from what
    /// the first cause's extension, inexact in form, leaves over; relevance decides.
    pub relevance_pct: f64,
    /// A record counts as noise-free when its estimated noise RMS is below this fraction of
    /// the baseline's held-out RMSE (logs of a simulator or a virtual lab, exact positions).
    pub noise_free_ratio: f64,
    /// Baseline of `series` records without `sim_` columns.
    pub series_model: SeriesModel,
    /// Also fit the linear state-space model beside a static `series` baseline and report its
    /// held-out error (a reference for the reader; it does not enter the verdict).
    pub dynamic_reference: bool,
    /// OCM parameter set of the energy-model baselines (`axial`, `bending`, `pose`): Table 3.1
    /// by default; `Calibrated` for the virtual lab's plant and the LUT.
    pub ocm: ParamPreset,
    /// Once a cause is named on a state-space baseline, its structure (lower orders, where the
    /// extensions' forces enter) is searched only when the named set leaves more than this
    /// many times the estimated noise on held-out rows: nearer the noise the searches (up to
    /// five more selections) have never changed a name in the batteries, only the fit. 0
    /// searches always.
    pub structure_search_ratio: f64,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            min_gain_pct: 2.0,
            bic_margin: 10.0,
            max_causes: 3,
            min_extra_gain_pct: 15.0,
            hac_lags: 20,
            relevance_pct: 5.0,
            noise_free_ratio: 1e-3,
            series_model: SeriesModel::Static,
            dynamic_reference: true,
            ocm: ParamPreset::Table31,
            structure_search_ratio: 2.0,
        }
    }
}

/// A candidate's scores against a reference model.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// The cause.
    pub cause: Cause,
    /// Held-out RMSE gain over the reference, percent.
    pub gain_pct: f64,
    /// Score: `-dBIC` (larger is better, positive is an improvement).
    pub score: f64,
    /// Held-out Newey-West t statistic of the squared-error reduction (evidence only).
    pub t_stat: f64,
    /// p-value of the nested-model F test on the training rows.
    pub p_value: f64,
    /// Held-out RMSE of the extended model.
    pub rmse: f64,
    /// True when it passed all three tests.
    pub accepted: bool,
    /// True when its fit was ill-conditioned (cancelling huge terms, or not finite): then it is
    /// never accepted, whatever its scores.
    pub ill_conditioned: bool,
}

/// One line of evidence per candidate, `cause gain%/score` with `+` where accepted, for logs
/// that show why a cause was or was not named.
pub fn evidence(cs: &[Candidate]) -> String {
    cs.iter()
        .map(|c| {
            format!(
                "{} {:.1}%/{:.0}{}",
                c.cause,
                c.gain_pct,
                c.score,
                if c.accepted { "+" } else { "" }
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Pooled held-out RMSE of predictions.
pub fn heldout_rmse(prep: &Prepared, pred: &[Vec<f64>]) -> f64 {
    let mut s = 0.0;
    let mut k = 0usize;
    for (ch, p) in prep.channels.iter().zip(pred) {
        for i in 0..ch.y.len() {
            if prep.test[i] {
                let e = ch.y[i] - p[i];
                s += e * e;
                k += 1;
            }
        }
    }
    if k == 0 { 0.0 } else { (s / k as f64).sqrt() }
}

/// Scores `ext` against `reference`.
pub fn score(
    prep: &Prepared,
    reference: &SetFit,
    ext: &SetFit,
    cfg: &Config,
    candidates: usize,
    cause: Cause,
) -> Candidate {
    let n_train = ext.rows.max(1) as f64;
    let mut dbic = 0.0;
    for (a, b) in ext.rss.iter().zip(&reference.rss) {
        dbic += n_train * ((a.max(1e-300)) / b.max(1e-300)).ln();
    }
    let dk = ext.extra_params as f64 - reference.extra_params as f64;
    dbic += dk * (n_train * prep.channels.len() as f64).ln();
    let r0 = heldout_rmse(prep, &reference.pred);
    let r1 = heldout_rmse(prep, &ext.pred);
    let gain = if r0 > 0.0 {
        100.0 * (1.0 - r1 / r0)
    } else {
        0.0
    };
    let t = heldout_t(prep, &reference.pred, &ext.pred, cfg.hac_lags);
    // Nested-model F test on the training rows, channels weighed by their baseline scale.
    let scales: Vec<f64> = prep
        .channels
        .iter()
        .map(|ch| channel_scale(ch, &prep.train))
        .collect();
    let rss0: f64 = reference.rss.iter().zip(&scales).map(|(r, s)| r / s).sum();
    let rss1: f64 = ext.rss.iter().zip(&scales).map(|(r, s)| r / s).sum();
    let df1 = dk.max(1.0);
    let df2 = (n_train * prep.channels.len() as f64 - ext.extra_params as f64 - 10.0).max(1.0);
    let f = ((rss0 - rss1) / df1) / (rss1 / df2).max(1e-300);
    let p_value = if f > 0.0 {
        FisherSnedecor::new(df1, df2)
            .map(|d| 1.0 - d.cdf(f))
            .unwrap_or(1.0)
    } else {
        1.0
    };
    let ill_conditioned = !ext.ill_conditioned.is_empty() || !r1.is_finite();
    let accepted = !ill_conditioned
        && dbic < -cfg.bic_margin
        && gain >= cfg.min_gain_pct
        && p_value < cfg.alpha / candidates.max(1) as f64;
    Candidate {
        cause,
        gain_pct: gain,
        score: -dbic,
        t_stat: t,
        p_value,
        rmse: r1,
        accepted,
        ill_conditioned,
    }
}

/// Heteroscedasticity- and autocorrelation-consistent t statistic of the held-out reduction in channel-normalised squared error.
fn heldout_t(prep: &Prepared, a: &[Vec<f64>], b: &[Vec<f64>], hac_lags: usize) -> f64 {
    let rows: Vec<usize> = (0..prep.rec.len()).filter(|&i| prep.test[i]).collect();
    if rows.len() < hac_lags * 2 {
        return 0.0;
    }
    let scales: Vec<f64> = prep
        .channels
        .iter()
        .map(|ch| channel_scale(ch, &prep.train))
        .collect();
    let d: Vec<f64> = rows
        .iter()
        .map(|&i| {
            prep.channels
                .iter()
                .enumerate()
                .map(|(c, ch)| {
                    let ea = ch.y[i] - a[c][i];
                    let eb = ch.y[i] - b[c][i];
                    (ea * ea - eb * eb) / scales[c]
                })
                .sum()
        })
        .collect();
    // Newey-West (Bartlett) long-run variance: residuals of a mis-specified model are
    // autocorrelated, so a plain t-test would overstate the evidence.
    let n = d.len() as f64;
    let m = d.iter().sum::<f64>() / n;
    let lags = hac_lags.max(1);
    let gamma = |l: usize| -> f64 {
        d[l..]
            .iter()
            .zip(&d[..d.len() - l])
            .map(|(a, b)| (a - m) * (b - m))
            .sum::<f64>()
            / n
    };
    let mut v = gamma(0);
    for l in 1..=lags.min(d.len() - 1) {
        v += 2.0 * (1.0 - l as f64 / (lags + 1) as f64) * gamma(l);
    }
    if v <= 0.0 {
        return if m > 0.0 { f64::INFINITY } else { 0.0 };
    }
    m / (v / n).sqrt()
}

/// The outcome of selection.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Named causes, in order of discovery (`[None]` when nothing passed).
    pub causes: Vec<Cause>,
    /// Single-cause candidates against the baseline.
    pub candidates: Vec<Candidate>,
    /// The baseline as a set fit.
    pub baseline: SetFit,
    /// The final extended fit (equal to the baseline for `none`).
    pub extended: SetFit,
    /// Scores of every further cause tried against the current extension.
    pub steps: Vec<Candidate>,
    /// The direction tests (friction against a static map of the inputs), records with a
    /// state only.
    pub direction: Vec<DirectionTest>,
    /// On a noise-free record: the other passing single causes whose held-out RMSE lies within
    /// the relevance window of the first named cause's (the record does not tell them apart).
    pub tied: Vec<Cause>,
}

/// Bayesian information criterion of a set fit on its training rows: `N ln(RSS)` per channel
/// plus `ln(N x channels)` per parameter, counting the extensions' parameters and
/// `baseline_params` more (0 when the sets compared share one baseline).
pub fn bic(f: &SetFit, baseline_params: usize) -> f64 {
    let n = f.rows.max(1) as f64;
    f.rss.iter().map(|r| n * r.max(1e-300).ln()).sum::<f64>()
        + (f.extra_params + baseline_params) as f64 * (n * f.rss.len() as f64).ln()
}

/// Runs the candidates and the greedy multi-cause search.
pub fn select(prep: &Prepared, cfg: &Config) -> Selection {
    let base = prep.fit_set(&[]);
    let pool = prep.candidates();
    let m = pool.len();
    let singles: Vec<SetFit> = pool.iter().map(|&c| prep.fit_set(&[c])).collect();
    let candidates: Vec<Candidate> = singles
        .iter()
        .zip(pool.iter().copied())
        .map(|(f, c)| score(prep, &base, f, cfg, m, c))
        .collect();
    let best = candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| c.accepted)
        .max_by(|a, b| a.1.score.total_cmp(&b.1.score));
    // The training criterion picks the first cause, unless another passing candidate is
    // decisively better on held-out rows: its held-out RMSE at least `min_extra_gain_pct`
    // below the criterion's choice (the margin a further cause must earn). Two non-nested
    // extensions can fit the training rows equally well (a one-mass LuGre friction: stop
    // operators 0.6 % better on training RSS, a BIC lead of 33 from 1400 autocorrelated
    // residuals) while one of them generalises far better (friction 86 % against 79 % held
    // out): the training lead is then within what the residuals' autocorrelation inflates.
    // Only where the extensions are refined in the loop (a state-space baseline): there the
    // fits are local optima of a rough cost. On the static baselines (exact least squares) it
    // turned an axial hysteresis+offset mixture into `gain`, so it is left out there.
    let in_loop = matches!(&prep.baseline, Baseline::StateSpace(ss) if ss.order() > 0);
    let best = best.map(|(bi, b)| {
        candidates
            .iter()
            .enumerate()
            .filter(|(_, c)| {
                in_loop && c.accepted && c.rmse <= (1.0 - cfg.min_extra_gain_pct / 100.0) * b.rmse
            })
            .min_by(|a, b| a.1.rmse.total_cmp(&b.1.rmse))
            .unwrap_or((bi, b))
    });
    // On a noise-free record the training criterion measures only how inexact each
    // extension's form is (every difference is "significant"): candidates whose held-out RMSE
    // lies within `relevance_pct` of the baseline's from the best are not told apart, and the
    // one with the fewest parameters among them is named (then the lower held-out RMSE).
    let base_rmse = heldout_rmse(prep, &base.pred);
    let noise_free = prep.noise_rmse() < cfg.noise_free_ratio * base_rmse;
    let window = cfg.relevance_pct / 100.0 * base_rmse;
    let best = if noise_free {
        let r_min = candidates
            .iter()
            .filter(|c| c.accepted)
            .map(|c| c.rmse)
            .fold(f64::INFINITY, f64::min);
        candidates
            .iter()
            .enumerate()
            .filter(|(_, c)| c.accepted && c.rmse <= r_min + window)
            .min_by(|a, b| {
                singles[a.0]
                    .extra_params
                    .cmp(&singles[b.0].extra_params)
                    .then(a.1.rmse.total_cmp(&b.1.rmse))
            })
    } else {
        best
    };
    let direction = direction_tests(prep);
    let Some((mut bi, _)) = best else {
        return Selection {
            causes: vec![Cause::None],
            candidates,
            extended: base.clone(),
            baseline: base,
            steps: Vec::new(),
            direction,
            tied: Vec::new(),
        };
    };
    // The residual flips with the direction of motion at equal inputs: a static map of the
    // inputs cannot be the first cause, friction is (when it passes on its own); the map may
    // still follow as a second cause under the usual tests. Friction is then kept through
    // the swaps and the backward check.
    let flips = direction.iter().any(|t| t.flips);
    let friction_at = pool.iter().position(|&c| c == Cause::Friction);
    if flips
        && pool[bi] == Cause::Nonlinearity
        && let Some(fi) = friction_at
        && candidates[fi].accepted
    {
        bi = fi;
    }
    let pinned = |c: Cause| flips && c == Cause::Friction;
    // Relevance on noise-free records: a further cause must remove `relevance_pct` of the
    // baseline's held-out RMSE (from the set without it to the set with it).
    let relevant = |without: &SetFit, with: &SetFit| {
        !noise_free || heldout_rmse(prep, &without.pred) - heldout_rmse(prep, &with.pred) >= window
    };
    let mut current = singles[bi].clone();
    let mut causes = vec![pool[bi]];
    let mut steps = Vec::new();
    while causes.len() < cfg.max_causes {
        let mut best_add: Option<(Candidate, SetFit)> = None;
        // A further cause must pass against the most flexible variant of the first one (so
        // that what a simpler form of the first leaves over is not named as a second cause);
        // the named set is then fitted in its ordinary form.
        prep.flexible.set(Some(causes[0]));
        let flexible_ref = prep.fit_set(&causes);
        prep.flexible.set(None);
        for &c in &pool {
            if causes.contains(&c) {
                continue;
            }
            let mut set = causes.clone();
            set.push(c);
            prep.flexible.set(Some(causes[0]));
            let flex = prep.fit_set(&set);
            prep.flexible.set(None);
            let against_flexible = score(prep, &flexible_ref, &flex, cfg, m, c);
            let f = prep.fit_set(&set);
            let mut s = score(prep, &current, &f, cfg, m, c);
            s.accepted &= against_flexible.accepted
                && against_flexible.gain_pct >= cfg.min_extra_gain_pct
                && relevant(&current, &f);
            steps.push(s.clone());
            if s.accepted
                && s.gain_pct >= cfg.min_extra_gain_pct
                && best_add.as_ref().is_none_or(|b| s.score > b.0.score)
            {
                best_add = Some((s, f));
            }
        }
        match best_add {
            Some((s, f)) => {
                causes.push(s.cause);
                current = f;
            }
            None => break,
        }
    }
    // Parsimony: a named cause is swapped for an unnamed one when the swapped set has the
    // better information criterion (e.g. an offset that a polynomial also covers).
    let bic = |f: &SetFit| bic(f, 0);
    for _ in 0..2 {
        let mut improved = false;
        for i in 0..causes.len() {
            if pinned(causes[i]) {
                continue;
            }
            let cur_bic = bic(&current);
            let cur_k = current.extra_params;
            let mut best_swap: Option<(f64, Vec<Cause>, SetFit)> = None;
            for &c in &pool {
                if causes.contains(&c) {
                    continue;
                }
                let mut set = causes.clone();
                set[i] = c;
                let f = prep.fit_set(&set);
                let b = bic(&f);
                // the swapped set must itself pass the held-out gain test against the
                // baseline (a flexible extension can win the training criterion by fitting
                // what does not generalise)
                // ... and must not be worse on held-out rows than the set it replaces by more
                // than that gain (a decisive training criterion is no licence to lose held-out
                // accuracy: a damage law won it over hysteresis beside friction, 1066 against
                // 1052 + 299, and was 38 % worse held out than friction alone)
                let r_swap = heldout_rmse(prep, &f.pred);
                let holds = r_swap
                    <= (1.0 - cfg.min_gain_pct / 100.0) * heldout_rmse(prep, &base.pred)
                    && r_swap
                        <= (1.0 + cfg.min_gain_pct / 100.0) * heldout_rmse(prep, &current.pred);
                // on a noise-free record the training criterion is decisive between any two
                // forms; a swap to more parameters must win held out by the relevance window
                // (the first cause's rule: a spread of the lab's column stiffnesses, a gain of
                // 9 parameters, was swapped for the commands' complete cubic of 60 that came
                // 2 % of the baseline closer)
                let relevant_swap = !noise_free
                    || f.extra_params <= cur_k
                    || heldout_rmse(prep, &current.pred) - r_swap >= window;
                let decisive = b < cur_bic - cfg.bic_margin && relevant_swap;
                // Occam's window: when the criterion cannot tell the sets apart (within the
                // margin), the one with fewer parameters is kept
                let simpler = f.extra_params < cur_k && b < cur_bic + cfg.bic_margin;
                if holds && (decisive || simpler) && best_swap.as_ref().is_none_or(|x| b < x.0) {
                    best_swap = Some((b, set, f));
                }
            }
            if let Some((_, set, f)) = best_swap {
                causes = set;
                current = f;
                improved = true;
            }
        }
        if !improved {
            break;
        }
    }
    // Backward check: every named cause must still pass the addition tests against the set
    // of the others (a cause added later can make an earlier one redundant); the weakest
    // failing one is dropped until all pass.
    while causes.len() > 1 {
        let mut failing: Vec<(f64, usize, SetFit)> = Vec::new();
        for i in 0..causes.len() {
            if pinned(causes[i]) {
                continue;
            }
            let mut rest = causes.clone();
            rest.remove(i);
            let f = prep.fit_set(&rest);
            let s = score(prep, &f, &current, cfg, m, causes[i]);
            let earns =
                s.accepted && s.gain_pct >= cfg.min_extra_gain_pct && relevant(&f, &current);
            if !earns {
                failing.push((s.score, i, f));
            }
        }
        // the weakest is dropped, unless dropping another failing cause leaves a set that is
        // decisively better on held-out rows (the first cause's rule, above)
        let weakest = failing
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.0.total_cmp(&b.1.0))
            .map(|(w, x)| {
                let r_weak = heldout_rmse(prep, &x.2.pred);
                failing
                    .iter()
                    .enumerate()
                    .map(|(j, y)| (j, heldout_rmse(prep, &y.2.pred)))
                    .filter(|(_, r)| {
                        in_loop && *r <= (1.0 - cfg.min_extra_gain_pct / 100.0) * r_weak
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map_or(w, |(j, _)| j)
            })
            .map(|j| failing.swap_remove(j));
        match weakest {
            Some((_, i, f)) => {
                causes.remove(i);
                current = f;
            }
            None => break,
        }
    }
    let tied = match causes
        .first()
        .and_then(|f| pool.iter().position(|c| c == f))
    {
        Some(fi) if noise_free => candidates
            .iter()
            .filter(|c| {
                c.accepted
                    && !causes.contains(&c.cause)
                    && (c.rmse - candidates[fi].rmse).abs() <= window
            })
            .map(|c| c.cause)
            .collect(),
        _ => Vec::new(),
    };
    Selection {
        causes,
        candidates,
        baseline: base,
        extended: current,
        steps,
        direction,
        tied,
    }
}
