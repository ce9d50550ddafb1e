//! Errors of the tactile crate.

use thiserror::Error;

/// Everything that can go wrong while setting up or running an indentation.
#[derive(Debug, Error)]
pub enum TactileError {
    /// The FEM core failed (mesh file, model, linear solve).
    #[error(transparent)]
    Fem(#[from] ocm_fem::FemError),
    /// An indenter surface cannot bound a solid.
    #[error("indenter {name}: {msg}")]
    Indenter {
        /// Indenter name or file.
        name: String,
        /// What is wrong.
        msg: String,
    },
    /// A set-up file is malformed or names something that does not exist.
    #[error("set-up {setup}: {msg}")]
    Setup {
        /// Set-up name or file.
        setup: String,
        /// What is wrong.
        msg: String,
    },
    /// The indenter does not press on the gel where it was placed.
    #[error("indentation {setup} leaves the gel: {msg}")]
    OffGel {
        /// Set-up name.
        setup: String,
        /// What is off.
        msg: String,
    },
    /// Newton failed at an indentation step even after cutting the step.
    #[error(
        "no convergence at step {step} (depth {depth_mm:.3} mm): {why}; largest residual {residual_n:.3e} N at node {node}"
    )]
    NoConvergence {
        /// Indentation step (1-based).
        step: usize,
        /// Depth reached, mm.
        depth_mm: f64,
        /// Why it stopped.
        why: String,
        /// Largest nodal residual, N.
        residual_n: f64,
        /// Node carrying it.
        node: usize,
    },
    /// Bad argument or array shape.
    #[error("invalid input: {0}")]
    Input(String),
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// An image could not be read or written.
    #[error("image {path}: {msg}")]
    Image {
        /// The file.
        path: String,
        /// The cause.
        msg: String,
    },
    /// An optical calibration file is missing, malformed or inconsistent.
    #[error("optical calibration {path}: {msg}")]
    Calibration {
        /// The file (or array inside it).
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// Training, evaluating or loading a network failed.
    #[error(transparent)]
    Learn(#[from] ocm_learn::LearnError),
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, TactileError>;

impl TactileError {
    /// I/O error on `path`.
    pub fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        TactileError::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }
}
