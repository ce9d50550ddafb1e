//! The identification pipeline end to end: record in, report out.

use serde::Serialize;

use crate::baseline::{Baseline, SeriesModel};
use crate::cause::Cause;
use crate::conventions::{conventions, schema_warnings};
use crate::data::{Kind, Record};
use crate::diagnostics::{self, Diagnostic, Hotspot};
use crate::error::IdentError;
use crate::extension::Prepared;
use crate::select::{self, Candidate, Config};
use crate::split;
use crate::structure::{entry_lags, lower_orders, searched, static_map};

/// A fitted parameter with its standard error.
#[derive(Debug, Clone, Serialize)]
pub struct Param {
    /// Name.
    pub name: String,
    /// Value.
    pub value: f64,
    /// Standard error (white-residual least-squares estimate; grid half-step for grid values).
    pub std_err: f64,
}

/// The machine-readable report (`--json`).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Named causes (`["none"]` when the residual is noise).
    pub causes: Vec<Cause>,
    /// Held-out RMSE of the fitted baseline.
    pub baseline_rmse: f64,
    /// Held-out RMSE of the extended model.
    pub extended_rmse: f64,
    /// `100 (1 - extended / baseline)`.
    pub gain_pct: f64,
    /// The verdict in words: what is wrong, by how much against the noise, and where.
    pub verdict: String,
    /// Measurement noise RMS estimated from the data (pooled over outputs, RMSE unit).
    pub noise_rmse: f64,
    /// How the noise was estimated.
    pub noise_method: String,
    /// Held-out RMSE of the extended model over the noise RMS (infinite for noise-free logs).
    pub residual_to_noise: f64,
    /// Problems found on the way: ill-conditioned fits kept out of the verdict, records that
    /// contradict the schema's conventions, residuals the named causes leave unexplained.
    pub warnings: Vec<String>,
    /// The schema's conventions for this kind (units, signs, frames, mounting).
    pub conventions: String,
    /// Every single-cause candidate against the baseline (`score` = -dBIC).
    pub candidates: Vec<Candidate>,
    /// Further causes tried against the extension of the causes named before them.
    pub additions: Vec<Candidate>,
    /// Record kind.
    pub kind: Kind,
    /// Source file.
    pub source: String,
    /// Unit of the RMSE figures.
    pub unit: String,
    /// Rows in the record, training rows, held-out rows.
    pub rows: [usize; 3],
    /// How the split was made.
    pub split: String,
    /// The baseline model.
    pub baseline: String,
    /// Its fitted free parameters.
    pub baseline_params: Vec<Param>,
    /// Held-out RMSE of the linear state-space reference (beside a static series baseline).
    pub dynamic_baseline_rmse: Option<f64>,
    /// Extensions fitted for the named causes.
    pub extensions: Vec<String>,
    /// Their fitted parameters.
    pub extension_params: Vec<Param>,
    /// Residual diagnostics of the baseline, per output channel.
    pub diagnostics: Vec<Diagnostic>,
    /// Where the baseline residual is largest, per output channel.
    pub hotspots: Vec<Hotspot>,
    /// Direction tests: does the residual flip with the direction of motion at equal inputs
    /// (friction) or not (a static map of the inputs)? Records with a state only.
    pub direction_tests: Vec<crate::direction::DirectionTest>,
    /// Selection settings.
    pub config: Config,
}

/// A report plus the series needed for plots.
#[derive(Debug, Clone)]
pub struct Identification {
    /// The report.
    pub report: Report,
    /// Output channel names.
    pub outputs: Vec<String>,
    /// Baseline residual per channel, every row.
    pub residual_before: Vec<Vec<f64>>,
    /// Extended-model residual per channel, every row.
    pub residual_after: Vec<Vec<f64>>,
    /// Held-out flags.
    pub test: Vec<bool>,
    /// Sample times, seconds.
    pub time_s: Vec<f64>,
    /// Measured output per channel.
    pub measured: Vec<Vec<f64>>,
    /// Each channel's loop variable for hysteresis and friction plots: (values, label), the
    /// first drive (or the state whose velocity friction follows).
    pub loop_variable: (Vec<f64>, String),
    /// Diagnostic variable (values, label) of each named cause, for channel `plot_channel`.
    pub variables: Vec<(Cause, Vec<f64>, String)>,
    /// The output channel plotted: the one whose held-out squared error the extension
    /// reduces most (0 for single-output records).
    pub plot_channel: usize,
}

/// Held-out RMSE over noise RMS above which a residual is never "consistent with noise".
pub const UNEXPLAINED_RATIO: f64 = 3.0;

/// Held-out RMSE over the output's spread (standard deviation) at or below which the baseline reproduces
/// the record to numerical precision (a least-squares solve in double precision lands near
/// 1e-11 on a noise-free affine record; a measurement's noise is many orders above).
pub const EXACT_FIT: f64 = 1e-8;

/// The measured outputs' standard deviation over all rows, pooled over channels (RMS).
fn output_spread(prep: &Prepared) -> f64 {
    let per: Vec<f64> = prep
        .channels
        .iter()
        .map(|ch| crate::signal::mean_std(&ch.y).1.powi(2))
        .collect();
    (per.iter().sum::<f64>() / per.len().max(1) as f64).sqrt()
}

/// Identifies what the baseline gets wrong in `rec`.
pub fn identify(rec: &Record, cfg: &Config) -> Result<Identification, IdentError> {
    rec.validate()?;
    let test = split::held_out(rec);
    let n_test = test.iter().filter(|t| **t).count();
    if n_test < 2 * cfg.hac_lags || rec.len() - n_test < 2 * cfg.hac_lags {
        return Err(IdentError::Invalid(format!(
            "{}: split leaves {} training and {} held-out rows; at least {} each are needed",
            rec.source,
            rec.len() - n_test,
            n_test,
            2 * cfg.hac_lags
        )));
    }
    let train: Vec<bool> = test.iter().map(|t| !t).collect();
    let baseline = Baseline::for_record(rec, &train, cfg.series_model, cfg.ocm)?;
    let prep = Prepared::new(rec, baseline.clone(), test.clone());
    let sel = select::select(&prep, cfg);
    let lags = match &baseline {
        Baseline::StateSpace(ss) => ss.entry_lag_candidates(),
        _ => Vec::new(),
    };
    // decided once, on the first selection: a lower order that brings the residual near the
    // noise still leaves the force's entry to search (the chamber's records need both)
    let left = select::heldout_rmse(&prep, &sel.extended.pred) / prep.noise_rmse();
    let room = left.is_nan() || left > cfg.structure_search_ratio;
    // the reader learns that a closer fit may exist (the searches' cost is the user's call)
    let skipped = (!room && searched(rec, &baseline, &sel).is_some()).then(|| {
        format!(
            "; the structure searches were skipped: the named causes leave {left:.1}x the noise on held-out rows, within the structure-search ratio of {}",
            cfg.structure_search_ratio
        )
    });
    let unnamed = sel.causes.iter().all(|c| *c == Cause::None);
    let (baseline, prep, sel) = if room {
        let (baseline, prep, sel) = lower_orders(rec, &test, cfg, baseline, prep, sel);
        entry_lags(rec, &test, cfg, &lags, baseline, prep, sel)
    } else {
        (baseline, prep, sel)
    };
    // a static map is cheap to try: where nothing is named it always is, otherwise only where
    // the structure searches were worth their cost
    let (baseline, prep, sel, chosen) =
        if cfg.series_model == SeriesModel::Auto && (unnamed || room) {
            static_map(rec, &test, cfg, baseline, prep, sel)
        } else {
            (baseline, prep, sel, None)
        };
    let baseline_rmse = select::heldout_rmse(&prep, &sel.baseline.pred);
    // a baseline that reproduces the record to rounding leaves nothing for a cause to explain:
    // the extensions would fit the least-squares solve's last digits (a noise-free affine
    // record named `gain`, its rounding-level residual 1000x the rounding-level noise)
    let spread = output_spread(&prep);
    let exact =
        baseline_rmse.is_finite() && spread.is_finite() && baseline_rmse <= EXACT_FIT * spread;
    let mut sel = sel;
    if exact {
        sel.causes = vec![Cause::None];
        sel.extended = sel.baseline.clone();
    }
    let extended_rmse = select::heldout_rmse(&prep, &sel.extended.pred);
    let gain_pct = if baseline_rmse > 0.0 {
        100.0 * (1.0 - extended_rmse / baseline_rmse)
    } else {
        0.0
    };
    // The linear-dynamic reference beside a static series baseline.
    let dynamic_baseline_rmse = if cfg.dynamic_reference && matches!(baseline, Baseline::Series) {
        let dp = Prepared::new(rec, Baseline::state_space(rec, &train), test.clone());
        let f = dp.fit_set(&[]);
        Some(select::heldout_rmse(&dp, &f.pred))
    } else {
        None
    };
    let mut baseline_params = Vec::new();
    for (c, ch) in prep.channels.iter().enumerate() {
        for (j, name) in ch.design.names.iter().enumerate() {
            let label = if prep.channels.len() > 1 {
                format!("{name} [{}]", rec.outputs[c].name)
            } else {
                name.clone()
            };
            baseline_params.push(Param {
                name: label,
                value: ch.theta[j],
                std_err: ch.theta_se[j],
            });
        }
    }
    if let Baseline::Pose {
        stiffness_scale, ..
    } = &baseline
    {
        // the correction regressors are the sensitivity to a relative stiffness change, so
        // their standard errors (pooled over the channels) are the scale's relative error
        let info: f64 = prep
            .channels
            .iter()
            .map(|ch| ch.theta_se[0])
            .filter(|se| *se > 0.0 && se.is_finite())
            .map(|se| 1.0 / (se * se))
            .sum();
        baseline_params.push(Param {
            name: "stiffness scale".into(),
            value: *stiffness_scale,
            std_err: if info > 0.0 {
                stiffness_scale / info.sqrt()
            } else {
                f64::INFINITY
            },
        });
    }
    let named: Vec<Cause> = sel
        .causes
        .iter()
        .copied()
        .filter(|c| *c != Cause::None)
        .collect();
    let heldout_sse = |y: &[f64], p: &[f64]| -> f64 {
        (0..y.len())
            .filter(|&i| test[i])
            .map(|i| (y[i] - p[i]).powi(2))
            .sum()
    };
    let plot_channel = (0..prep.channels.len())
        .map(|c| {
            let ch = &prep.channels[c];
            let drop = heldout_sse(&ch.y, &sel.baseline.pred[c])
                - heldout_sse(&ch.y, &sel.extended.pred[c]);
            (c, drop)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(c, _)| c)
        .unwrap_or(0);
    let variables = sel
        .causes
        .iter()
        .map(|&c| {
            let (v, l) = diagnostics::variable(&prep, c, plot_channel);
            (c, v, l)
        })
        .collect();
    let residual_before: Vec<Vec<f64>> = prep
        .channels
        .iter()
        .map(|ch| ch.y.iter().zip(&ch.yhat).map(|(a, b)| a - b).collect())
        .collect();
    let residual_after = prep
        .channels
        .iter()
        .zip(&sel.extended.pred)
        .map(|(ch, p)| ch.y.iter().zip(p).map(|(a, b)| a - b).collect())
        .collect();
    let unit = rec
        .outputs
        .first()
        .map(|o| o.unit.clone())
        .unwrap_or_default();
    // Every output channel's evidence; with several outputs each statistic names its channel.
    let mut diagnostics = Vec::new();
    let mut hotspots = Vec::new();
    for c in 0..prep.channels.len() {
        let mut d = diagnostics::diagnose(&prep, c);
        let mut h = diagnostics::hotspots(&prep, c);
        if prep.channels.len() > 1 {
            let name = &rec.outputs[c].name;
            d.iter_mut()
                .for_each(|x| x.statistic = format!("{} [{name}]", x.statistic));
            h.iter_mut()
                .for_each(|x| x.input = format!("{} [residual of {name}]", x.input));
        }
        diagnostics.extend(d);
        hotspots.extend(h);
    }
    // Noise from the baseline residual's high-frequency content; a model error that is smooth
    // at the sampling rate does not enter it.
    let noise_rmse = prep.noise_rmse();
    let ratio = |rmse: f64| {
        if noise_rmse > 0.0 {
            rmse / noise_rmse
        } else if rmse > 0.0 {
            f64::INFINITY
        } else {
            0.0
        }
    };
    let mut warnings = schema_warnings(rec, &prep);
    let mut causes = sel.causes.clone();
    let where_ = hotspots
        .iter()
        .max_by(|a, b| a.ratio.total_cmp(&b.ratio))
        .map(|h| {
            format!(
                "largest where {} is in [{:.4}, {:.4}] ({:.2}x the overall RMSE)",
                h.input, h.from, h.to, h.ratio
            )
        })
        .unwrap_or_default();
    let base_ill: Vec<String> = prep
        .channels
        .iter()
        .zip(&rec.outputs)
        .filter(|(ch, _)| ch.ill_conditioned)
        .map(|(_, o)| o.name.clone())
        .collect();
    if !base_ill.is_empty() {
        warnings.push(format!(
            "the baseline's fit of {} is ill-conditioned (huge cancelling coefficients): its free parameters are not identified by this record and are not findings",
            base_ill.join(", ")
        ));
    }
    for c in sel.candidates.iter().filter(|c| c.ill_conditioned) {
        warnings.push(format!(
            "the {} extension's fit is ill-conditioned and was kept out of the verdict",
            c.cause.name()
        ));
    }
    if !sel.tied.is_empty() {
        let others: Vec<&str> = sel.tied.iter().map(|c| c.name()).collect();
        warnings.push(format!(
            "on this noise-free record the single extension(s) {} fit within {} % of the baseline's RMSE of {}'s: the record does not tell them apart (the one with fewer parameters, then the lower held-out error, is named; an excitation that moves the inputs more independently would decide)",
            others.join(", "),
            cfg.relevance_pct,
            causes.first().map_or("the named cause", |c| c.name())
        ));
    }
    let verdict = if causes == [Cause::None] {
        if exact {
            format!(
                "none: the baseline reproduces the record to numerical precision (held-out RMSE {baseline_rmse:.4e} {unit}, {:.1e} of the output's spread {spread:.4e} {unit}, at most {EXACT_FIT:.0e} counts as exact); no cause is named on a rounding-level residual",
                if spread > 0.0 {
                    baseline_rmse / spread
                } else {
                    0.0
                }
            )
        } else if ratio(baseline_rmse) > UNEXPLAINED_RATIO {
            causes = vec![Cause::Unexplained];
            format!(
                "the model is wrong and the discrepancy is unexplained: held-out RMSE {baseline_rmse:.4e} {unit} is {:.1}x the noise ({noise_rmse:.2e} {unit}) and no candidate explains it; {where_}",
                ratio(baseline_rmse)
            )
        } else {
            format!(
                "none: the held-out residual ({baseline_rmse:.4e} {unit}) is {:.1}x the noise ({noise_rmse:.2e} {unit}), consistent with it",
                ratio(baseline_rmse)
            )
        }
    } else {
        let names: Vec<&str> = causes.iter().map(|c| c.name()).collect();
        let left = ratio(extended_rmse);
        if left > UNEXPLAINED_RATIO {
            warnings.push(format!(
                "after the extension the held-out residual ({extended_rmse:.4e} {unit}) is still {left:.1}x the noise: the named causes explain {gain_pct:.1} % of the RMSE, the rest is unexplained"
            ));
        }
        format!(
            "{}: held-out RMSE {baseline_rmse:.4e} -> {extended_rmse:.4e} {unit} ({gain_pct:.1} % gain); residual left {left:.1}x the noise ({noise_rmse:.2e} {unit})",
            names.join(" + ")
        )
    };
    let report = Report {
        causes,
        baseline_rmse,
        extended_rmse,
        gain_pct,
        verdict,
        noise_rmse,
        noise_method: "robust second differences of the baseline's training residual (MAD of x[i+1]-2x[i]+x[i-1], divided by sqrt 6), pooled over outputs".into(),
        residual_to_noise: ratio(extended_rmse),
        warnings,
        conventions: conventions(rec.kind).into(),
        candidates: sel.candidates.clone(),
        additions: sel.steps.clone(),
        kind: rec.kind,
        source: rec.source.clone(),
        unit,
        rows: [rec.len(), rec.len() - n_test, n_test],
        split: split::describe(rec),
        baseline: match chosen {
            Some(why) => baseline.describe() + &why,
            None => baseline.describe() + skipped.as_deref().unwrap_or(""),
        },
        baseline_params,
        dynamic_baseline_rmse,
        extensions: named
            .iter()
            .map(|c| match (c, sel.extended.actuator_lag_s) {
                (Cause::Nonlinearity, Some(lag)) => format!(
                    "actuator nonlinearity with dynamics of its own: each quadratic and cubic \
                     term of the inputs through {} Laguerre filters (time constant {lag:.3} s), \
                     beside the linear state-space model",
                    crate::extension::LAGUERRE_FILTERS
                ),
                _ => c.extension().to_string(),
            })
            .collect(),
        extension_params: sel
            .extended
            .params
            .iter()
            .map(|(n, v, s)| Param {
                name: n.clone(),
                value: *v,
                std_err: *s,
            })
            .collect(),
        diagnostics,
        hotspots,
        direction_tests: sel.direction.clone(),
        config: *cfg,
    };
    Ok(Identification {
        report,
        outputs: rec.outputs.iter().map(|o| o.name.clone()).collect(),
        residual_before,
        residual_after,
        test,
        time_s: rec.time_s.clone(),
        measured: rec.outputs.iter().map(|o| o.values.clone()).collect(),
        loop_variable: match (rec.states.first(), rec.drives.first()) {
            (Some(s), _) => (s.values.clone(), format!("{} [{}]", s.name, s.unit)),
            (None, Some(&k)) => (
                rec.inputs[k].values.clone(),
                format!("{} [{}]", rec.inputs[k].name, rec.inputs[k].unit),
            ),
            _ => (rec.time_s.clone(), "time [s]".into()),
        },
        variables,
        plot_channel,
    })
}
