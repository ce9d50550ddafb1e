//! Reading images (PNG, JPEG) as grey levels for the metrics.

use crate::{Result, TactileError};
use std::path::Path;

/// A single-channel image, 0-255, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Gray {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Grey levels, 0-255.
    pub pixels: Vec<f64>,
}

/// Reads an image file and converts it to grey levels (ITU-R 601 luma).
pub fn read_gray(path: impl AsRef<Path>) -> Result<Gray> {
    let path = path.as_ref();
    let img = image::open(path).map_err(|e| TactileError::Image {
        path: path.display().to_string(),
        msg: e.to_string(),
    })?;
    let g = img.to_luma8();
    Ok(Gray {
        rows: g.height() as usize,
        cols: g.width() as usize,
        pixels: g.pixels().map(|p| f64::from(p.0[0])).collect(),
    })
}
