//! Errors of the peg-in-hole scene, the demonstrations and the policies.

use std::path::PathBuf;

/// What can go wrong in a scene, a data set, a policy or a replay.
#[derive(Debug, thiserror::Error)]
pub enum PegError {
    /// A setting or an input value is out of its valid range (names the value).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A file could not be read or written.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The physics engine refused something.
    #[error("scene: {0}")]
    Scene(String),
    /// Training, checkpoint or network error.
    #[error(transparent)]
    Learn(#[from] ocm_learn::LearnError),
    /// The neural physics engine refused an input or a checkpoint.
    #[error(transparent)]
    Npe(#[from] ocm_npe::NpeError),
    /// The tactile renderer or the gel mesh refused something.
    #[error(transparent)]
    Tactile(#[from] ocm_tactile::TactileError),
}

/// Result with [`PegError`].
pub type Result<T> = std::result::Result<T, PegError>;

impl PegError {
    /// A file error on `path`.
    pub fn file(path: &std::path::Path, reason: impl std::fmt::Display) -> Self {
        Self::File {
            path: path.to_path_buf(),
            reason: reason.to_string(),
        }
    }
}

/// Refuses a non-finite value, naming it.
pub(crate) fn finite(name: &str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PegError::Invalid(format!("{name} = {v} is not finite")))
    }
}

/// Refuses a value that is not a positive number, naming it.
pub(crate) fn positive(name: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(PegError::Invalid(format!("{name} = {v} must be positive")))
    }
}

/// Refuses a value that is negative or not finite, naming it.
pub(crate) fn non_negative(name: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(PegError::Invalid(format!(
            "{name} = {v} must be finite and not negative"
        )))
    }
}
