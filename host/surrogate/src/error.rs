//! Errors of the surrogate crate.

use thiserror::Error;

/// Everything that can go wrong while building, loading or driving the surrogate.
#[derive(Debug, Error)]
pub enum SurrogateError {
    /// A file (samples, model, URDF) is malformed; `at` says where.
    #[error("{file}: {at}: {msg}")]
    Parse {
        /// Which file.
        file: String,
        /// Where in the file (field, line, element).
        at: String,
        /// What is wrong.
        msg: String,
    },
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// An input is outside its valid range or not finite; the message names it.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A command or input value outside the range allowed for its channel.
    #[error("{channel} = {value} {unit} is outside the allowed range [{lo}, {hi}] {unit}")]
    OutOfRange {
        /// What was given (a joint with its name, a chamber pressure).
        channel: String,
        /// The value given, in `unit`.
        value: f64,
        /// Lowest allowed value, in `unit`.
        lo: f64,
        /// Highest allowed value, in `unit`.
        hi: f64,
        /// Unit of the values (rad, m, kPa).
        unit: &'static str,
    },
    /// A command or input value that is not a finite number.
    #[error("{channel} is not finite ({value}); allowed range [{lo}, {hi}] {unit}")]
    NotFinite {
        /// What was given.
        channel: String,
        /// The value given (NaN or infinite).
        value: f64,
        /// Lowest allowed value, in `unit`.
        lo: f64,
        /// Highest allowed value, in `unit`.
        hi: f64,
        /// Unit of the values.
        unit: &'static str,
    },
    /// The FEM failed.
    #[error("FEM: {0}")]
    Fem(#[from] ocm_fem::FemError),
    /// The physics engine or optimiser failed.
    #[error("{0}")]
    Solver(String),
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, SurrogateError>;

impl SurrogateError {
    /// Checks one value against its channel's closed range `[lo, hi]` (with `tol` of round-off
    /// allowed): [`SurrogateError::NotFinite`] or [`SurrogateError::OutOfRange`] naming the
    /// channel, the value and the range.
    pub fn check_value(
        channel: impl FnOnce() -> String,
        value: f64,
        [lo, hi]: [f64; 2],
        tol: f64,
        unit: &'static str,
    ) -> Result<()> {
        if !value.is_finite() {
            return Err(SurrogateError::NotFinite {
                channel: channel(),
                value,
                lo,
                hi,
                unit,
            });
        }
        if value < lo - tol || value > hi + tol {
            return Err(SurrogateError::OutOfRange {
                channel: channel(),
                value,
                lo,
                hi,
                unit,
            });
        }
        Ok(())
    }

    /// A parse error of `file` at `at`.
    pub fn parse(file: impl Into<String>, at: impl Into<String>, msg: impl Into<String>) -> Self {
        SurrogateError::Parse {
            file: file.into(),
            at: at.into(),
            msg: msg.into(),
        }
    }
}
