//! The identification pipeline end to end: record in, report out.

use serde::Serialize;

use crate::baseline::Baseline;
use crate::cause::Cause;
use crate::data::{Kind, Record};
use crate::diagnostics::{self, Diagnostic, Hotspot};
use crate::error::IdentError;
use crate::extension::Prepared;
use crate::select::{self, Candidate, Config};
use crate::split;

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
    /// Held-out RMSE of the linear-dynamic reference (series only).
    pub dynamic_baseline_rmse: Option<f64>,
    /// Extensions fitted for the named causes.
    pub extensions: Vec<String>,
    /// Their fitted parameters.
    pub extension_params: Vec<Param>,
    /// Residual diagnostics of the baseline, per output channel.
    pub diagnostics: Vec<Diagnostic>,
    /// Where the baseline residual is largest, per output channel.
    pub hotspots: Vec<Hotspot>,
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
    /// Diagnostic variable (values, label) of each named cause, for channel `plot_channel`.
    pub variables: Vec<(Cause, Vec<f64>, String)>,
    /// The output channel plotted: the one whose held-out squared error the extension
    /// reduces most (0 for single-output records).
    pub plot_channel: usize,
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
    let baseline = Baseline::for_record(rec, &train)?;
    let prep = Prepared::new(rec, baseline.clone(), test.clone());
    let sel = select::select(&prep, cfg);
    let baseline_rmse = select::heldout_rmse(&prep, &sel.baseline.pred);
    let extended_rmse = select::heldout_rmse(&prep, &sel.extended.pred);
    let gain_pct = if baseline_rmse > 0.0 {
        100.0 * (1.0 - extended_rmse / baseline_rmse)
    } else {
        0.0
    };
    let dynamic_baseline_rmse = if rec.kind == Kind::Series {
        let taus = vec![3.0 * prep.dt, 10.0 * prep.dt, 30.0 * prep.dt];
        let dp = Prepared::new(rec, Baseline::SeriesDynamic(taus), test.clone());
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
        baseline_params.push(Param {
            name: "stiffness scale".into(),
            value: *stiffness_scale,
            std_err: f64::NAN,
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
    let residual_before = prep
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
    let report = Report {
        causes: sel.causes.clone(),
        baseline_rmse,
        extended_rmse,
        gain_pct,
        candidates: sel.candidates.clone(),
        additions: sel.steps.clone(),
        kind: rec.kind,
        source: rec.source.clone(),
        unit,
        rows: [rec.len(), rec.len() - n_test, n_test],
        split: split::describe(rec),
        baseline: baseline.describe(),
        baseline_params,
        dynamic_baseline_rmse,
        extensions: named.iter().map(|c| c.extension().to_string()).collect(),
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
        config: *cfg,
    };
    Ok(Identification {
        report,
        outputs: rec.outputs.iter().map(|o| o.name.clone()).collect(),
        residual_before,
        residual_after,
        test,
        variables,
        plot_channel,
    })
}
