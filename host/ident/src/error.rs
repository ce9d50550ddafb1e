//! Errors of the identification pipeline.

use thiserror::Error;

/// Everything that can go wrong reading data or identifying a model.
#[derive(Debug, Error)]
pub enum IdentError {
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A malformed data file: the file, 1-based line and the column are named.
    #[error("{file}: line {line}, column `{column}`: {message}")]
    Parse {
        /// The file.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Column name (empty when the whole row is wrong).
        column: String,
        /// What is wrong.
        message: String,
    },
    /// A malformed MATLAB file: byte offset and what is wrong.
    #[error("{file}: byte {offset}: {message}")]
    Mat {
        /// The file.
        file: String,
        /// Byte offset of the element.
        offset: usize,
        /// What is wrong.
        message: String,
    },
    /// Data that parsed but cannot be used.
    #[error("{0}")]
    Invalid(String),
    /// The physics model could not be built.
    #[error("physics model: {0}")]
    Model(String),
}
