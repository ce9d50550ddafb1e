//! The structure searches of a state-space baseline, run once the first selection is made:
//! lower orders ([`lower_orders`]), where the extensions' forces enter ([`entry_lags`]) and
//! order zero, the static map ([`static_map`], for [`crate::baseline::SeriesModel::Auto`]).

use crate::baseline::Baseline;
use crate::cause::Cause;
use crate::data::Record;
use crate::extension::{Prepared, SetFit};
use crate::select::{self, Config};
use crate::statespace::StateSpace;

/// Where a state-space baseline's extensions name a cause, the selection is run again on the
/// baselines of up to [`LOWER_ORDERS`] lower orders, and the extended model of the lowest
/// training criterion (BIC with the baseline's and the extensions' parameters together) is
/// kept. The baseline's order is chosen on data that contain the effects, and the extra
/// states absorb part of them: every pair record of seed 5000 chose the largest order (5),
/// against 2, 4 and 3 for the one-mass, two-mass and chamber plants, and at their own orders
/// the chamber's friction+stiffening and hysteresis+stiffening pairs are named exactly (87.8
/// and 93.9 %), at order 5 neither. A record where nothing is named keeps its order (no
/// false alarm can come from here).
pub(crate) fn lower_orders<'a>(
    rec: &'a Record,
    test: &[bool],
    cfg: &Config,
    baseline: Baseline,
    prep: Prepared<'a>,
    sel: select::Selection,
) -> (Baseline, Prepared<'a>, select::Selection) {
    let Some((ss, _)) = searched(rec, &baseline, &sel) else {
        return (baseline, prep, sel);
    };
    let n = ss.order();
    let m = rec.inputs.len();
    let p = rec.outputs.len();
    // the baseline's parameters count too: the sets compared have different baselines
    let criterion = |order: usize, f: &SetFit| select::bic(f, state_space_params(order, m, p));
    let mut best_c = criterion(n, &sel.extended);
    let mut best = (baseline.clone(), prep, sel);
    for order in (n.saturating_sub(LOWER_ORDERS).max(1)..n).rev() {
        let Some(alt) = ss.at_lower_order(order) else {
            continue;
        };
        let b = Baseline::StateSpace(Box::new(alt));
        let pr = Prepared::new(rec, b.clone(), test.to_vec());
        let se = select::select(&pr, cfg);
        if se.causes.iter().all(|c| *c == Cause::None) {
            continue;
        }
        let c = criterion(order, &se.extended);
        if c < best_c {
            best_c = c;
            best = (b, pr, se);
        }
    }
    best
}

/// Where the extensions' forces enter a state-space baseline, chosen once a cause is named.
/// By default a force enters where the input does (`B`). Where the input reaches the
/// structure through an actuator's lag (a chamber filled through a restriction), friction,
/// a hysteretic loop or a stiffening acts on the structure itself: entering along `B` they
/// are low-pass filtered by the filling and their reversals come late (chamber pairs gained
/// 16-60 % with both effects at 5-50 times the noise). A lag freed in every candidate's
/// refinement blurred friction against hysteresis (README), so here it is a property of the
/// baseline, like its order: the whole selection runs again with the force entering after
/// each candidate lag (real poles of the baseline and of its lower orders,
/// [`StateSpace::entry_lag_candidates`]), every candidate then compared with the same entry.
/// A lag's model is kept when its training BIC (one parameter more) is the lowest, it loses no
/// held-out accuracy, and the set named without the lag fits better with it. That last rule is
/// asked first, on a fit of the named set that starts cold, so a lag failing it costs one set
/// fit instead of a selection. A record where nothing is named keeps the input's entry.
pub(crate) fn entry_lags<'a>(
    rec: &'a Record,
    test: &[bool],
    cfg: &Config,
    lags: &[f64],
    baseline: Baseline,
    prep: Prepared<'a>,
    sel: select::Selection,
) -> (Baseline, Prepared<'a>, select::Selection) {
    let Some((ss, base)) = searched(rec, &baseline, &sel) else {
        return (baseline, prep, sel);
    };
    let mut best_c = select::bic(&sel.extended, base);
    let own = sel.causes.clone();
    let own_c = best_c;
    let mut best_h = select::heldout_rmse(&prep, &sel.extended.pred);
    let mut best = (baseline.clone(), prep, sel);
    for &lag in lags {
        let b = Baseline::StateSpace(Box::new(ss.with_entry_lag(lag)));
        let pr = Prepared::new(rec, b.clone(), test.to_vec());
        // rule 3 asked first, on a copy whose refinements start cold (the selection's own
        // fits stay untouched): a lag that does not help the named set is not worth a
        // selection, which costs some twenty set fits
        if select::bic(&pr.clone().fit_set(&own), base + 1) >= own_c {
            continue;
        }
        let se = select::select(&pr, cfg);
        if se.causes.iter().all(|c| *c == Cause::None) {
            continue;
        }
        let c = select::bic(&se.extended, base + 1);
        // as for the selection's swaps, a better training criterion is no licence to lose
        // held-out accuracy
        let h = select::heldout_rmse(&pr, &se.extended.pred);
        // the lag must be a property of the record, not a licence for another set: the
        // set named without it must fit better with it
        let same = if se.causes.len() == own.len() && own.iter().all(|k| se.causes.contains(k)) {
            c
        } else {
            select::bic(&pr.fit_set(&own), base + 1)
        };
        if same < own_c && c < best_c && h <= (1.0 + cfg.min_gain_pct / 100.0) * best_h {
            best_c = c;
            best_h = h;
            best = (b, pr, se);
        }
    }
    best
}

/// Order zero of the state-space family, for [`crate::baseline::SeriesModel::Auto`]: the static map `y = A u + b`
/// with its own selection, whose extensions act on the output directly. A record of a static
/// system with a rate-independent loop is fitted by the state-space model as a lag: its
/// dynamics absorb part of the loop, the same loop entering through `B` is filtered by them,
/// and the extended fits lose held-out accuracy (`ocm ident synth --kind series --effect
/// hysteresis --seed 3`: order 3, residual 1.9x the noise, nothing named; the static map names
/// hysteresis and leaves 1.2x). The static map is kept when it names a cause, its training BIC
/// counting its `p (m + 1)` baseline parameters is below the state-space model's with its own
/// (and its entry lag's), and it loses no held-out accuracy; the reason is returned for the
/// report's baseline line. A record of a dynamic system keeps its state-space model: a static
/// map cannot fit its dynamics whatever it names.
pub(crate) fn static_map<'a>(
    rec: &'a Record,
    test: &[bool],
    cfg: &Config,
    baseline: Baseline,
    prep: Prepared<'a>,
    sel: select::Selection,
) -> (Baseline, Prepared<'a>, select::Selection, Option<String>) {
    let Baseline::StateSpace(ss) = &baseline else {
        return (baseline, prep, sel, None);
    };
    let (n, m, p) = (ss.order(), rec.inputs.len(), rec.outputs.len());
    let own = state_space_params(n, m, p) + usize::from(ss.entry_lag > 0.0);
    let own_c = select::bic(&sel.extended, own);
    let own_h = select::heldout_rmse(&prep, &sel.extended.pred);
    let pr = Prepared::new(rec, Baseline::Series, test.to_vec());
    let se = select::select(&pr, cfg);
    if se.causes.iter().all(|c| *c == Cause::None) {
        return (baseline, prep, sel, None);
    }
    let c = select::bic(&se.extended, p * (m + 1));
    let h = select::heldout_rmse(&pr, &se.extended.pred);
    if c < own_c && h <= (1.0 + cfg.min_gain_pct / 100.0) * own_h {
        let named: Vec<&str> = sel
            .causes
            .iter()
            .filter(|k| **k != Cause::None)
            .map(|k| k.name())
            .collect();
        let why = format!(
            "; chosen over the linear state-space model of order {n}{}: with the causes it names the static map's training BIC is {c:.0} against {own_c:.0} (each counting its baseline's parameters) and its held-out RMSE {h:.4e} against {own_h:.4e}, so the record behaves as a static system whose effects the state-space model took for dynamics",
            if named.is_empty() {
                ", which named nothing".to_string()
            } else {
                format!(" with {}", named.join(" + "))
            }
        );
        return (Baseline::Series, pr, se, Some(why));
    }
    (baseline, prep, sel, None)
}

/// The state-space baseline and its parameter count `n (n + m) + p (n + m + 1)` when a cause
/// is named on it: the structure searches ([`lower_orders`], [`entry_lags`]) run only then.
pub(crate) fn searched<'b>(
    rec: &Record,
    baseline: &'b Baseline,
    sel: &select::Selection,
) -> Option<(&'b StateSpace, usize)> {
    let Baseline::StateSpace(ss) = baseline else {
        return None;
    };
    if sel.causes.iter().all(|c| *c == Cause::None) {
        return None;
    }
    let (n, m, p) = (ss.order(), rec.inputs.len(), rec.outputs.len());
    Some((ss, state_space_params(n, m, p)))
}

/// Lower baseline orders tried once a cause is named (see [`lower_orders`]).
const LOWER_ORDERS: usize = 2;

/// Free parameters of an order-`n` state-space baseline with `m` inputs and `p` outputs:
/// `A`, `B` and the output map `C, D, d`.
fn state_space_params(n: usize, m: usize, p: usize) -> usize {
    n * (n + m) + p * (n + m + 1)
}
