//! The real soft-arm measurements (Bruder et al., IEEE T-RO 2021; file
//! `softrobot_train-13_val-4.mat` in `shared/data/soft-arm-measured`): two cell arrays,
//! `train` (13 trials) and `val` (4 trials), of structs with fields `t` (time, s), `u`
//! (three pressure commands) and `y` (2-D tip position from motion capture). They become one
//! `series` record whose segments are the trials and whose held-out rows are the `val` trials.

use std::path::{Path, PathBuf};

use crate::data::{Channel, Kind, Record};
use crate::error::IdentError;
use crate::matv5::{self, MatValue};

/// The data file's name.
pub const FILE_NAME: &str = "softrobot_train-13_val-4.mat";

/// The file's path inside the data directory.
pub const DATA_PATH: &str = "soft-arm-measured/softrobot_train-13_val-4.mat";

/// Where the file is expected: in the data directory (`explicit`, else `OCM_DATA_DIR`, else the
/// nearest `shared/data`, see `ocm_datadir`).
pub fn default_path(explicit: Option<&Path>) -> Result<PathBuf, IdentError> {
    ocm_datadir::data_file(explicit, DATA_PATH).map_err(|e| IdentError::Invalid(e.to_string()))
}

/// A numeric matrix as (rows, cols, column-major data).
fn matrix<'a>(
    v: &'a MatValue,
    what: &str,
    file: &str,
) -> Result<(usize, usize, &'a [f64]), IdentError> {
    match v {
        MatValue::Numeric { dims, data } if dims.len() == 2 => Ok((dims[0], dims[1], data)),
        _ => Err(IdentError::Invalid(format!(
            "{file}: {what} is not a numeric matrix"
        ))),
    }
}

/// Loads the file as a `series` record (train trials first, then val trials held out).
pub fn load(path: &Path) -> Result<Record, IdentError> {
    let file = path.display().to_string();
    let vars = matv5::read_file(path)?;
    let mut time_s = Vec::new();
    let mut starts = Vec::new();
    let mut u: Vec<Vec<f64>> = Vec::new();
    let mut y: Vec<Vec<f64>> = Vec::new();
    let mut held = Vec::new();
    for (set, is_val) in [("train", false), ("val", true)] {
        let cell = vars
            .iter()
            .find(|(n, _)| n == set)
            .map(|(_, v)| v)
            .ok_or_else(|| IdentError::Invalid(format!("{file}: no variable `{set}`")))?;
        let MatValue::Cell { items, .. } = cell else {
            return Err(IdentError::Invalid(format!(
                "{file}: `{set}` is not a cell array"
            )));
        };
        for (k, trial) in items.iter().enumerate() {
            let get = |f: &str| {
                trial.field(0, f).ok_or_else(|| {
                    IdentError::Invalid(format!("{file}: {set}{{{}}} has no field `{f}`", k + 1))
                })
            };
            let (tr, tc, t) = matrix(get("t")?, "t", &file)?;
            let (ur, uc, ud) = matrix(get("u")?, "u", &file)?;
            let (yr, yc, yd) = matrix(get("y")?, "y", &file)?;
            let n = tr * tc;
            if ur != n || yr != n {
                return Err(IdentError::Invalid(format!(
                    "{file}: {set}{{{}}}: t has {n} samples, u {ur} rows, y {yr} rows",
                    k + 1
                )));
            }
            if u.is_empty() {
                u = vec![Vec::new(); uc];
                y = vec![Vec::new(); yc];
            }
            if u.len() != uc || y.len() != yc {
                return Err(IdentError::Invalid(format!(
                    "{file}: {set}{{{}}} has {uc} inputs and {yc} outputs, earlier trials {} and {}",
                    k + 1,
                    u.len(),
                    y.len()
                )));
            }
            starts.push(time_s.len());
            time_s.extend_from_slice(&t[..n]);
            for j in 0..uc {
                u[j].extend_from_slice(&ud[j * n..(j + 1) * n]);
            }
            for j in 0..yc {
                y[j].extend_from_slice(&yd[j * n..(j + 1) * n]);
            }
            held.extend(std::iter::repeat_n(is_val, n));
        }
    }
    let inputs: Vec<Channel> = u
        .into_iter()
        .enumerate()
        .map(|(j, v)| Channel::new(&format!("u{}", j + 1), "command", v))
        .collect();
    let outputs = y
        .into_iter()
        .enumerate()
        .map(|(j, v)| Channel::new(&format!("y{}", j + 1), "mocap", v))
        .collect();
    let drives = (0..inputs.len()).collect();
    let rec = Record {
        kind: Kind::Series,
        source: file,
        time_s,
        segment_starts: starts,
        inputs,
        outputs,
        drives,
        held_out: Some(held),
        simulated: Vec::new(),
        states: Vec::new(),
        sensitivities: Vec::new(),
    };
    rec.validate()?;
    Ok(rec)
}

/// The soft arm against its linear-dynamic baseline: held-out (`val`) RMSE of the static map,
/// of the linear state-space model, and of that model with the `nonlinearity` extension (the
/// better on training rows of its two variants, see [`crate::extension::Prepared::fit_set`]),
/// all free-run.
#[derive(Debug, Clone, Copy)]
pub struct DynamicComparison {
    /// Order of the state-space model chosen by its criterion.
    pub order: usize,
    /// Static affine map `y = A u + b`.
    pub static_rmse: f64,
    /// Linear state-space model.
    pub linear_rmse: f64,
    /// Linear state-space model with the `nonlinearity` extension.
    pub extended_rmse: f64,
    /// `100 (1 - extended / linear)`.
    pub gain_pct: f64,
    /// Time constant (s) of the Laguerre filters when the extension kept is the actuator
    /// variant (each nonlinear input term with dynamics of its own); `None` for stiffening.
    pub actuator_lag_s: Option<f64>,
}

/// Fits the static map, the linear state-space model and its nonlinear extension on the
/// training trials of `rec` and scores them on its held-out trials.
pub fn dynamic_comparison(rec: &Record) -> Result<DynamicComparison, IdentError> {
    use crate::baseline::{Baseline, SeriesModel};
    use crate::cause::Cause;
    use crate::extension::Prepared;
    let test = crate::split::held_out(rec);
    let train: Vec<bool> = test.iter().map(|t| !t).collect();
    let preset = ocm_shared::params::ParamPreset::Table31;
    let fixed = Prepared::new(
        rec,
        Baseline::for_record(rec, &train, SeriesModel::Static, preset)?,
        test.clone(),
    );
    let static_rmse = crate::select::heldout_rmse(&fixed, &fixed.fit_set(&[]).pred);
    let baseline = Baseline::for_record(rec, &train, SeriesModel::StateSpace, preset)?;
    let order = match &baseline {
        Baseline::StateSpace(ss) => ss.order(),
        _ => 0,
    };
    let prep = Prepared::new(rec, baseline, test);
    let linear_rmse = crate::select::heldout_rmse(&prep, &prep.fit_set(&[]).pred);
    let ext = prep.fit_set(&[Cause::Nonlinearity]);
    if !ext.ill_conditioned.is_empty() {
        return Err(IdentError::Invalid(format!(
            "{}: the nonlinear extension is ill-conditioned on {:?}",
            rec.source, ext.ill_conditioned
        )));
    }
    let extended_rmse = crate::select::heldout_rmse(&prep, &ext.pred);
    Ok(DynamicComparison {
        order,
        static_rmse,
        linear_rmse,
        extended_rmse,
        gain_pct: 100.0 * (1.0 - extended_rmse / linear_rmse),
        actuator_lag_s: ext.actuator_lag_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_real_soft_arm_file() {
        let Some(path) = ocm_datadir::test_data(DATA_PATH) else {
            eprintln!("SKIP: {DATA_PATH} not found (real soft-arm data absent)");
            return;
        };
        let rec = load(&path).unwrap();
        assert_eq!(rec.segment_starts.len(), 17, "13 train + 4 val trials");
        assert_eq!(rec.inputs.len(), 3);
        assert_eq!(rec.outputs.len(), 2);
        let held = rec.held_out.as_ref().unwrap();
        let n_val = held.iter().filter(|v| **v).count();
        assert!(rec.len() > 40_000, "{} rows", rec.len());
        assert!(n_val > 1000 && n_val < rec.len() / 2, "{n_val}");
        // sampling interval about 0.083 s as documented in SOURCES.md
        let dt = crate::signal::median_dt(&rec.time_s);
        assert!((dt - 0.083).abs() < 0.01, "dt {dt}");
        eprintln!(
            "soft arm: {} rows, {} val, u range {:?}, y1 range {:?}",
            rec.len(),
            n_val,
            rec.inputs
                .iter()
                .map(|c| (
                    c.values.iter().cloned().fold(f64::INFINITY, f64::min),
                    c.values.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                ))
                .collect::<Vec<_>>(),
            (
                rec.outputs[0]
                    .values
                    .iter()
                    .cloned()
                    .fold(f64::INFINITY, f64::min),
                rec.outputs[0]
                    .values
                    .iter()
                    .cloned()
                    .fold(f64::NEG_INFINITY, f64::max)
            )
        );
    }
}
