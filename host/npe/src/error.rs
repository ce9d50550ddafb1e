//! Errors of the neural physics engine.

use thiserror::Error;

/// What can go wrong while training, loading or calling the NPE.
#[derive(Debug, Error)]
pub enum NpeError {
    /// The learning building blocks failed (training, checkpoint).
    #[error(transparent)]
    Learn(#[from] ocm_learn::LearnError),
    /// The tactile crate failed (dataset, gel, masks).
    #[error(transparent)]
    Tactile(#[from] ocm_tactile::TactileError),
    /// An input of a call is not usable (NaN, negative force, a point through the gel).
    #[error("NPE input: {0}")]
    Input(String),
    /// The dataset cannot be used as asked.
    #[error("NPE data: {0}")]
    Data(String),
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, NpeError>;

impl NpeError {
    /// I/O error on `path`.
    pub fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        NpeError::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }
}
