//! Errors of the reduction crate.

use thiserror::Error;

/// What can go wrong while reducing, simulating or reading and writing datasets.
#[derive(Debug, Error)]
pub enum MorError {
    /// The full model failed (mesh, solve).
    #[error(transparent)]
    Fem(#[from] ocm_fem::FemError),
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// A file exists but does not hold what it must (shape, hash, format).
    #[error("{path}: {problem}")]
    File {
        /// The file.
        path: String,
        /// What is wrong with it.
        problem: String,
    },
    /// Inconsistent arguments or data.
    #[error("{0}")]
    Invalid(String),
    /// A reduced solve failed.
    #[error("reduced model: {0}")]
    Solve(String),
}

/// Result alias.
pub type Result<T> = std::result::Result<T, MorError>;

impl MorError {
    /// An I/O error on `path`.
    pub fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        MorError::Io {
            path: path.display().to_string(),
            source,
        }
    }

    /// A problem with the file `path`.
    pub fn file(path: &std::path::Path, problem: impl Into<String>) -> Self {
        MorError::File {
            path: path.display().to_string(),
            problem: problem.into(),
        }
    }
}

/// SHA-256 of `bytes` as lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    let d = sha2::Sha256::digest(bytes);
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of a sequence of float64 values (little-endian bytes), hex.
pub fn sha256_f64(values: &[f64]) -> String {
    use sha2::Digest;
    let mut h = sha2::Sha256::new();
    for v in values {
        h.update(v.to_le_bytes());
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}
