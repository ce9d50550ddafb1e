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
    /// A parse error of `file` at `at`.
    pub fn parse(file: impl Into<String>, at: impl Into<String>, msg: impl Into<String>) -> Self {
        SurrogateError::Parse {
            file: file.into(),
            at: at.into(),
            msg: msg.into(),
        }
    }
}
