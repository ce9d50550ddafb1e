//! The TOML configuration read by `ocm lut build --config` and `ocm model`.
//!
//! ```toml
//! [ocm]                       # the preset's values for anything left out
//! preset = "calibrated"       # default; or "table-3.1" (docs/model.md)
//! base_side_m = 0.030         # L
//! rest_length_m = 0.040       # l0
//! side_angle_rad = 0.3927     # theta_d
//! layers = 10                 # N
//! bar_stiffness_n_per_m = 25.29 # k_b (Table 3.1: 1.3)
//! hinge_stiffness_n_per_m = 1.945 # k_h (Table 3.1: 0.1)
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

use ocm_shared::params::{OcmParams, ParamPreset};
use serde::{Deserialize, Deserializer, Serialize};

use crate::tables::TableConfig;

/// Parameters of one OCM type and its LUT grids.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Design parameters and fitted stiffness ([`ParamPreset::Calibrated`]
    /// by default; an `[ocm]` table starts from its `preset` key).
    #[serde(deserialize_with = "deserialize_ocm")]
    pub ocm: OcmParams,
    /// LUT grids.
    pub table: TableConfig,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            ocm: ParamPreset::default().ocm(),
            table: TableConfig::default(),
        }
    }
}

/// An `[ocm]` table as written: a preset and the keys that override it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct OcmSection {
    #[serde(default)]
    preset: ParamPreset,
    base_side_m: Option<f64>,
    rest_length_m: Option<f64>,
    side_angle_rad: Option<f64>,
    layers: Option<u32>,
    bar_stiffness_n_per_m: Option<f64>,
    hinge_stiffness_n_per_m: Option<f64>,
    mass_kg: Option<f64>,
}

impl OcmSection {
    fn resolve(self) -> OcmParams {
        let p = self.preset.ocm();
        OcmParams {
            base_side_m: self.base_side_m.unwrap_or(p.base_side_m),
            rest_length_m: self.rest_length_m.unwrap_or(p.rest_length_m),
            side_angle_rad: self.side_angle_rad.unwrap_or(p.side_angle_rad),
            layers: self.layers.unwrap_or(p.layers),
            bar_stiffness_n_per_m: self
                .bar_stiffness_n_per_m
                .unwrap_or(p.bar_stiffness_n_per_m),
            hinge_stiffness_n_per_m: self
                .hinge_stiffness_n_per_m
                .unwrap_or(p.hinge_stiffness_n_per_m),
            mass_kg: self.mass_kg.unwrap_or(p.mass_kg),
        }
    }
}

/// Reads an `[ocm]` table: its optional `preset` (default `"calibrated"`,
/// or `"table-3.1"`) gives every key the table leaves out. For
/// `#[serde(deserialize_with)]` on any field holding [`OcmParams`] in a
/// configuration file (the lab's `[plant.ocm]` too).
pub fn deserialize_ocm<'de, D: Deserializer<'de>>(d: D) -> Result<OcmParams, D::Error> {
    OcmSection::deserialize(d).map(OcmSection::resolve)
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
    fn empty_file_gives_the_calibrated_set() {
        assert_eq!(Config::parse("").unwrap(), Config::default());
        assert_eq!(Config::default().ocm, OcmParams::CALIBRATED);
        assert_eq!(Config::parse("[ocm]\n").unwrap().ocm, OcmParams::CALIBRATED);
    }

    #[test]
    fn partial_sections_keep_defaults() {
        let c = Config::parse("[ocm]\nlayers = 12\n[table]\nn_eps = 65\n").unwrap();
        assert_eq!(c.ocm.layers, 12);
        assert_eq!(c.ocm.base_side_m, 0.030);
        assert_eq!(c.ocm.hinge_stiffness_n_per_m, 1.945);
        assert_eq!(c.table.n_eps, 65);
        assert_eq!(c.table.n_p, 16);
    }

    #[test]
    fn the_preset_key_selects_table_3_1_under_overrides() {
        let c = Config::parse("[ocm]\npreset = \"table-3.1\"\n").unwrap();
        assert_eq!(c.ocm, OcmParams::TABLE_3_1);
        let c = Config::parse("[ocm]\npreset = \"table-3.1\"\nmass_kg = 0.02\n").unwrap();
        assert_eq!(c.ocm.mass_kg, 0.02);
        assert_eq!(c.ocm.hinge_stiffness_n_per_m, 0.1);
        let e = Config::parse("[ocm]\npreset = \"table 3.1\"\n").unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
    }

    #[test]
    fn a_written_config_reads_back_unchanged() {
        for preset in ParamPreset::ALL {
            let c = Config {
                ocm: preset.ocm(),
                ..Config::default()
            };
            let text = toml::to_string(&c).unwrap();
            assert_eq!(Config::parse(&text).unwrap(), c, "{text}");
        }
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

    /// `ocm lut build` with no config, then `ocm lut check`: the image of
    /// the calibrated set needs no raised samples and meets the accuracy
    /// goals, as Table 3.1's does.
    #[test]
    fn the_default_image_is_monotone_and_passes_the_check() {
        use crate::OcmModel;
        use crate::tables::{build_tables, check_accuracy};
        let cfg = Config::default();
        assert_eq!((cfg.table.p_min_kpa, cfg.table.p_max_kpa), (0.0, 30.0));
        let model = OcmModel::new(cfg.ocm).unwrap();
        let tables = build_tables(&model, &cfg.table, &|_, _| {}).unwrap();
        assert_eq!(tables.raised_samples, 0);
        let bytes = tables.encode(&model).unwrap();
        let acc = check_accuracy(&model, &bytes, 1000).unwrap();
        assert!(acc.crc_ok);
        assert!(acc.axial_err_max_pct_fs <= 0.01, "{acc:?}");
        assert!(acc.bending_err_max_pct_fs <= 0.1, "{acc:?}");
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = Config::load(Some(Path::new("/nonexistent/ocm.toml"))).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/ocm.toml"));
    }
}
