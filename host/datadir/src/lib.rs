//! Where the toolkit finds the data it is given: meshes, measurements, calibrations and real
//! sensor frames that live outside the repository (`shared/data` beside the checkout).
//!
//! One rule for every command and test, so that an installed binary never carries a path of the
//! machine it was built on:
//! 1. an explicit directory (a command's `--data DIR`),
//! 2. else the environment variable `OCM_DATA_DIR`,
//! 3. else the first `shared/data` (holding `SOURCES.md`) found beside the current directory or
//!    any of its ancestors, which is `../shared/data` from the repository root and also works
//!    from a crate's directory, where `cargo test` runs.
//!
//! Tests ask through [`test_data`] / [`require_tool`]: when something is missing they print that
//! they skip, and with `OCM_REQUIRE_DATA=1` (set by CI) they fail instead.

use std::path::{Path, PathBuf};

/// The environment variable naming the data directory.
pub const DATA_DIR_ENV: &str = "OCM_DATA_DIR";
/// The environment variable that turns a missing data file or tool into a test failure.
pub const REQUIRE_DATA_ENV: &str = "OCM_REQUIRE_DATA";

/// Why the data directory or a file in it could not be found.
#[derive(Debug, thiserror::Error)]
pub enum DataDirError {
    /// The directory named by `--data` or `OCM_DATA_DIR` does not exist.
    #[error("data directory {path} (from {source_name}) does not exist")]
    Missing {
        /// The directory that was named.
        path: PathBuf,
        /// Where the name came from (`--data` or `OCM_DATA_DIR`).
        source_name: &'static str,
    },
    /// No directory was named and none was found beside the current directory.
    #[error(
        "no data directory: pass --data DIR or set OCM_DATA_DIR to the folder holding the given \
         data (the repository expects it at ../shared/data); searched upward from {start}"
    )]
    NotFound {
        /// The directory the search started from.
        start: PathBuf,
    },
    /// The data directory exists but lacks the requested file.
    #[error("{file} is not in the data directory {dir}")]
    FileMissing {
        /// The file, relative to the data directory.
        file: String,
        /// The data directory.
        dir: PathBuf,
    },
}

/// The data directory: `explicit` (from `--data`), else `OCM_DATA_DIR`, else the nearest
/// `shared/data` beside the current directory or one of its ancestors.
pub fn data_dir(explicit: Option<&Path>) -> Result<PathBuf, DataDirError> {
    if let Some(p) = explicit {
        return existing(p.to_path_buf(), "--data");
    }
    if let Some(p) = std::env::var_os(DATA_DIR_ENV).filter(|v| !v.is_empty()) {
        return existing(PathBuf::from(p), DATA_DIR_ENV);
    }
    let start = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
    search_from(&start).ok_or(DataDirError::NotFound { start })
}

/// A file inside the data directory (`rel` like `digit/DIGIT_v8.vtk`), checked to exist.
pub fn data_file(explicit: Option<&Path>, rel: &str) -> Result<PathBuf, DataDirError> {
    let dir = data_dir(explicit)?;
    let path = dir.join(rel);
    if path.exists() {
        Ok(path)
    } else {
        Err(DataDirError::FileMissing {
            file: rel.to_string(),
            dir,
        })
    }
}

/// Whether missing data or tools must fail the test run (`OCM_REQUIRE_DATA=1`).
pub fn data_required() -> bool {
    std::env::var(REQUIRE_DATA_ENV).is_ok_and(|v| v == "1" || v.eq_ignore_ascii_case("true"))
}

/// For tests: the data file `rel`, or `None` after printing why the test skips.
///
/// # Panics
/// When the file cannot be found and `OCM_REQUIRE_DATA=1`: CI must not pass silently.
pub fn test_data(rel: &str) -> Option<PathBuf> {
    match data_file(None, rel) {
        Ok(p) => Some(p),
        Err(e) => skip_or_fail(&format!("data {rel}: {e}")),
    }
}

/// For tests: the path of the executable `name` on `PATH`, or `None` after printing why the
/// test skips.
///
/// # Panics
/// When the tool is missing and `OCM_REQUIRE_DATA=1`.
pub fn require_tool(name: &str) -> Option<PathBuf> {
    match find_on_path(name) {
        Some(p) => Some(p),
        None => skip_or_fail(&format!("tool {name} is not on PATH")),
    }
}

/// The environment variable naming the Python interpreter for interop tests (the README's
/// test command points it at the virtual environment it makes).
pub const PYTHON_ENV: &str = "OCM_PYTHON";

/// For tests: a Python interpreter (`OCM_PYTHON`, else `python3` on `PATH`) that can import
/// every module in `modules`, or `None` after printing why the test skips.
///
/// # Panics
/// When no such interpreter is found and `OCM_REQUIRE_DATA=1`.
pub fn require_python(modules: &[&str]) -> Option<PathBuf> {
    let python = std::env::var_os(PYTHON_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| find_on_path("python3"));
    let Some(python) = python else {
        return skip_or_fail("no python3 (set OCM_PYTHON)");
    };
    let script = modules
        .iter()
        .map(|m| format!("import {m}"))
        .collect::<Vec<_>>()
        .join("; ");
    let ok = std::process::Command::new(&python)
        .args(["-c", &script])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        Some(python)
    } else {
        skip_or_fail(&format!(
            "{} cannot import {} (the README's test command installs them in .venv)",
            python.display(),
            modules.join(", ")
        ))
    }
}

/// The executable `name` on `PATH`, if any.
pub fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

fn skip_or_fail<T>(why: &str) -> Option<T> {
    if data_required() {
        panic!("{why} (required: {REQUIRE_DATA_ENV}=1)");
    }
    eprintln!("skipping: {why}; set {REQUIRE_DATA_ENV}=1 to make this a failure");
    None
}

fn existing(path: PathBuf, source_name: &'static str) -> Result<PathBuf, DataDirError> {
    if path.is_dir() {
        Ok(path)
    } else {
        Err(DataDirError::Missing { path, source_name })
    }
}

fn search_from(start: &Path) -> Option<PathBuf> {
    start
        .ancestors()
        .map(|a| a.join("shared").join("data"))
        .find(|c| c.join("SOURCES.md").is_file())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn search_finds_a_data_dir_beside_an_ancestor_and_not_elsewhere() {
        let root = std::env::temp_dir().join(format!("ocm-datadir-{}", std::process::id()));
        let data = root.join("shared").join("data");
        let deep = root.join("repo").join("host").join("x");
        std::fs::create_dir_all(&data).unwrap();
        std::fs::create_dir_all(&deep).unwrap();
        assert_eq!(search_from(&deep), None, "no SOURCES.md yet");
        std::fs::write(data.join("SOURCES.md"), "x").unwrap();
        assert_eq!(search_from(&deep), Some(data.clone()));
        assert_eq!(search_from(&root.join("repo")), Some(data));
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn an_explicit_directory_that_does_not_exist_is_an_error_naming_it() {
        let e = data_dir(Some(Path::new("/nonexistent/ocm-data"))).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("/nonexistent/ocm-data") && msg.contains("--data"),
            "{msg}"
        );
    }
}
