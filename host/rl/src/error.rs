//! Errors of the RL crate.

use thiserror::Error;

/// Everything that can go wrong while building, stepping or training on an environment.
#[derive(Debug, Error)]
pub enum RlError {
    /// An action has the wrong length.
    #[error("action has {found} values, expected {expected}")]
    ActionSize {
        /// Values given.
        found: usize,
        /// Values expected.
        expected: usize,
    },
    /// An action value is NaN or infinite.
    #[error("action value {index} is {value}: actions must be finite")]
    NonFiniteAction {
        /// Which component.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// `step` before `reset`, or after the episode ended.
    #[error("{0}")]
    State(String),
    /// A setting or name is invalid; the message names it.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// The surrogate failed.
    #[error("surrogate: {0}")]
    Surrogate(#[from] ocm_surrogate::SurrogateError),
    /// Training or a checkpoint failed.
    #[error("learning: {0}")]
    Learn(#[from] ocm_learn::LearnError),
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
}

impl RlError {
    /// An I/O error on `path`.
    pub fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        RlError::Io {
            path: path.display().to_string(),
            source,
        }
    }
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, RlError>;
