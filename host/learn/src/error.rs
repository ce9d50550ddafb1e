//! Errors of the learning building blocks.

use std::path::PathBuf;

/// What can go wrong while training, saving or loading a model.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A checkpoint file is damaged, truncated or not a checkpoint at all.
    #[error("{path}: corrupt checkpoint: {reason}")]
    CorruptCheckpoint {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        reason: String,
    },
    /// A checkpoint holds a different architecture or configuration than the model it is loaded into.
    #[error("{path}: checkpoint mismatch: {reason}")]
    CheckpointMismatch {
        /// The file.
        path: PathBuf,
        /// What differs.
        reason: String,
    },
    /// Data handed to a model or a scaler has the wrong shape or bad values.
    #[error("bad data: {0}")]
    Data(String),
    /// A configuration value is out of its valid range.
    #[error("bad configuration: {0}")]
    Config(String),
    /// Training produced a non-finite loss.
    #[error("training diverged at epoch {epoch}: loss {loss}")]
    Diverged {
        /// Epoch (1-based) at which the loss stopped being finite.
        epoch: usize,
        /// The offending loss value.
        loss: f64,
    },
    /// A plot could not be drawn.
    #[error("plot {path}: {reason}")]
    Plot {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// Result with [`LearnError`].
pub type Result<T> = std::result::Result<T, LearnError>;

impl LearnError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
