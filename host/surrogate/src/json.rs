//! The crate's JSON files (samples and models): one way to write them and one way to read
//! them, with errors that name the file and where in it.

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::{Result, SurrogateError};

/// Writes `value` as JSON to `path`; `what` names it in errors.
pub(crate) fn write<T: Serialize>(path: &std::path::Path, value: &T, what: &str) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| SurrogateError::Solver(format!("serialising {what}: {e}")))?;
    std::fs::write(path, text).map_err(|source| SurrogateError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Reads JSON from `path`; a parse error names the file, line and column.
pub(crate) fn read<T: DeserializeOwned>(path: &std::path::Path) -> Result<T> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| SurrogateError::Io {
        path: name.clone(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| {
        SurrogateError::parse(
            &name,
            format!("line {} column {}", e.line(), e.column()),
            e.to_string(),
        )
    })
}
