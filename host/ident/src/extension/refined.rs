//! What an in-loop refinement produces, and the record of finished ones that the selection
//! reuses: the data both the refinement and the prepared record hold, apart from the code.

use super::loop_signal::LoopSignal;
use crate::cause::Cause;

/// The result of an in-loop refinement of one output channel.
#[derive(Debug, Clone)]
pub(super) struct InLoopFit {
    /// Prediction on every row.
    pub pred: Vec<f64>,
    /// Training RSS on every training row.
    pub rss: f64,
    /// Extension weights (per drive, per signal) and their standard errors.
    pub weights: Vec<(f64, f64)>,
    /// Parameters beyond the linear fit's: the internal coordinate's `n` coefficients.
    pub extra: usize,
}

/// A finished refinement, kept for the selection's repeated and growing sets.
#[derive(Debug, Clone)]
pub(super) struct Cached {
    pub(super) channel: usize,
    pub(super) causes: Vec<Cause>,
    pub(super) flexible: Option<Cause>,
    /// `A, B, C, D, d` as laid out in the parameter vector.
    pub(super) shared: Vec<f64>,
    /// Initial-state offsets.
    pub(super) x0: Vec<f64>,
    /// Weights per cause (per drive, per signal).
    pub(super) weights: Vec<Vec<f64>>,
    /// Signals per cause, in the order of `weights`.
    pub(super) signals: Vec<Vec<LoopSignal>>,
    pub(super) fit: InLoopFit,
}
