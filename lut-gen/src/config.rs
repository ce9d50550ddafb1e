//! The TOML configuration read by `ocm lut build --config` and `ocm model`.
//!
//! ```toml
//! [ocm]                       # Table 3.1 defaults for anything left out
//! base_side_m = 0.030         # L
//! rest_length_m = 0.040       # l0
//! side_angle_rad = 0.3927     # theta_d
//! layers = 10                 # N
//! bar_stiffness_n_per_m = 1.3 # k_b
//! hinge_stiffness_n_per_m = 0.1 # k_h
//! mass_kg = 0.013             # w
//!
//! [table]                     # grids of the LUT
//! eps_min = -0.6
//! eps_max = 0.6
//! n_eps = 129
//! p_min_kpa = 0.0
//! p_max_kpa = 30.0
//! n_p = 16
//! eps0_min = -0.6
//! eps0_max = 0.6
//! n_s = 17
//! n_u = 129
//! ```

use std::path::{Path, PathBuf};

use ocm_shared::params::OcmParams;
use serde::{Deserialize, Serialize};

use crate::tables::TableConfig;

/// Parameters of one OCM type and its LUT grids.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Design parameters and fitted stiffness.
    pub ocm: OcmParams,
    /// LUT grids.
    pub table: TableConfig,
}

/// Errors reading a configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid configuration TOML.
    #[error("invalid config {path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's error, with line and column.
        source: toml::de::Error,
    },
}

impl Config {
    /// Reads a configuration file; `None` gives the defaults.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let Some(path) = path else {
            return Ok(Self::default());
        };
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text).map_err(|source| ConfigError::Parse {
            path: path.to_owned(),
            source,
        })
    }

    /// Parses configuration TOML.
    pub fn parse(text: &str) -> Result<Self, toml::de::Error> {
        toml::from_str(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_gives_table_3_1() {
        assert_eq!(Config::parse("").unwrap(), Config::default());
        assert_eq!(Config::default().ocm, OcmParams::TABLE_3_1);
    }

    #[test]
    fn partial_sections_keep_defaults() {
        let c = Config::parse("[ocm]\nlayers = 12\n[table]\nn_eps = 65\n").unwrap();
        assert_eq!(c.ocm.layers, 12);
        assert_eq!(c.ocm.base_side_m, 0.030);
        assert_eq!(c.table.n_eps, 65);
        assert_eq!(c.table.n_p, 16);
    }

    #[test]
    fn unknown_keys_and_bad_types_are_named_with_their_line() {
        let e = Config::parse("[ocm]\nlayers = 10\nbase_side = 0.03\n").unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("base_side"), "{msg}");
        assert!(msg.contains("line 3"), "{msg}");
        let e = Config::parse("[table]\nn_eps = \"many\"\n").unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = Config::load(Some(Path::new("/nonexistent/ocm.toml"))).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/ocm.toml"));
    }
}
