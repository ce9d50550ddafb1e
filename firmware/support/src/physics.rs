//! The default LUT image: the `ocm-lutgen` energy model sampled on its
//! default grids, exactly what `ocm lut build` writes without a config and
//! what a user uploads to a board. Firmware tests and the QEMU bench run on
//! this image so that their figures hold for the firmware as flashed.

use std::sync::OnceLock;

use ocm_lutgen::OcmModel;
use ocm_lutgen::config::Config;
use ocm_lutgen::tables::{TableError, build_tables};

/// The default configuration's LUT image: `ocm-lutgen`'s default OCM
/// parameters and grids.
pub fn build_default_image() -> Result<Vec<u8>, TableError> {
    build_image(&Config::default())
}

/// The LUT image of `config` (OCM parameters and grids), stamped with the
/// parameters' hash.
pub fn build_image(config: &Config) -> Result<Vec<u8>, TableError> {
    let model = OcmModel::new(config.ocm)?;
    let tables = build_tables(&model, &config.table, &|_, _| {})?;
    tables.encode(&model)
}

/// [`build_default_image`], built once per process.
///
/// # Panics
/// If the default model cannot be sampled, which a test of this crate
/// rules out; callers are tests, benches and build scripts.
pub fn default_image() -> &'static [u8] {
    static IMAGE: OnceLock<Vec<u8>> = OnceLock::new();
    IMAGE.get_or_init(|| match build_default_image() {
        Ok(bytes) => bytes,
        Err(e) => panic!("the default LUT image does not build: {e}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ocm_firmware::app::DEFAULT_GEOMETRY;
    use ocm_shared::lut::{LUT_CAPACITY, LutImage, defaults};

    /// The image a user flashes fits the boards' buffer and belongs to the
    /// geometry the firmware boots with, so an app accepts it unchanged.
    #[test]
    fn default_image_fits_the_boards_and_matches_the_boot_geometry() {
        let bytes = default_image();
        assert_eq!(bytes.len(), defaults::IMAGE_LEN);
        assert!(bytes.len() <= LUT_CAPACITY);
        let lut = LutImage::parse(bytes).expect("the default image parses");
        assert_eq!(lut.param_hash(), Config::default().ocm.hash());
        assert_eq!(
            lut.param_hash(),
            DEFAULT_GEOMETRY.ocm.hash(),
            "lut-gen's default OCM differs from the firmware's boot geometry"
        );
        let g = lut.axial_grid();
        assert_eq!(g.n_eps, defaults::N_EPS);
        assert_eq!(g.n_p, defaults::N_P);
    }
}
