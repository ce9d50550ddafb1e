//! Errors of the FEM crate.

use thiserror::Error;

/// Everything that can go wrong while reading meshes, building models or solving.
#[derive(Debug, Error)]
pub enum FemError {
    /// A mesh or data file is malformed; `at` names the line or byte offset.
    #[error("{file}: {at}: {msg}")]
    Parse {
        /// Which kind of file (e.g. "VTK", "STL").
        file: &'static str,
        /// Where in the file ("line 12", "byte 4096").
        at: String,
        /// What is wrong.
        msg: String,
    },
    /// A file's contents are unusable; `source` says what and where inside it.
    #[error("{path}: {source}")]
    File {
        /// The file.
        path: String,
        /// What is wrong in it.
        source: Box<FemError>,
    },
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The model description is inconsistent (bad index, bad parameter, empty selection).
    #[error("invalid model: {0}")]
    Model(String),
    /// An element turned inside out (J <= 0) at the current configuration.
    #[error("element {element} inverted (J = {jacobian:.3e})")]
    Inverted {
        /// Element index.
        element: usize,
        /// Its volume ratio.
        jacobian: f64,
    },
    /// The linear solver failed (singular or non-finite matrix).
    #[error("linear solve failed: {0}")]
    Linear(String),
    /// Newton did not converge even after cutting the step down to the minimum.
    #[error(
        "no convergence: {what} (load fraction {load_fraction:.4}, residual {residual:.3e}, step cut to {step:.2e})"
    )]
    NoConvergence {
        /// Which solve failed.
        what: String,
        /// Fraction of the final load reached.
        load_fraction: f64,
        /// Last residual norm.
        residual: f64,
        /// Smallest load or time step tried.
        step: f64,
    },
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, FemError>;

impl FemError {
    /// This error, said of the file `path` (a reader's error names the line, this the file).
    pub fn in_file(self, path: &std::path::Path) -> Self {
        FemError::File {
            path: path.display().to_string(),
            source: Box::new(self),
        }
    }

    /// Builds a parse error.
    pub fn parse(file: &'static str, at: impl Into<String>, msg: impl Into<String>) -> Self {
        FemError::Parse {
            file,
            at: at.into(),
            msg: msg.into(),
        }
    }
}
