//! Tactile encoders: contact points and normal force of one sensor to a latent vector Z.

use crate::error::{PegError, Result};
use crate::patch::patch;

/// Maps what one sensor feels to a fixed-length latent vector.
pub trait TactileEncoder {
    /// Name stored with the policies trained on this encoder's latents.
    fn name(&self) -> &str;
    /// Length of the latent vector.
    fn dim(&self) -> usize;
    /// The latent of contact points (sensor frame, m, z = depth into the gel) and the normal
    /// force (N). Non-finite inputs are an error naming the value.
    fn latent(&self, points: &[[f64; 3]], force_n: f64) -> Result<Vec<f32>>;
}

/// Hand-made features of the raw contact (no learned model): whether and how many points
/// touch, the patch centroid, mean depth, principal spreads and axis angle, and the force.
///
/// Layout (lengths in mm so that the values are of order one): `[in_contact, count, cx_mm,
/// cy_mm, depth_mm, spread_major_mm, spread_minor_mm, cos 2a, sin 2a, force_n]`; `a` is the
/// angle of the patch's major axis from the sensor's x axis (doubled: the axis has no
/// direction). All zeros without contact.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ContactFeatures;

/// Number of [`ContactFeatures`] values.
pub const CONTACT_FEATURES: usize = 10;

impl TactileEncoder for ContactFeatures {
    fn name(&self) -> &str {
        "contact-features"
    }

    fn dim(&self) -> usize {
        CONTACT_FEATURES
    }

    fn latent(&self, points: &[[f64; 3]], force_n: f64) -> Result<Vec<f32>> {
        if !force_n.is_finite() || force_n < 0.0 {
            return Err(PegError::Invalid(format!(
                "normal force {force_n} N must be finite and not negative"
            )));
        }
        if let Some((i, p)) = points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !v.is_finite()))
        {
            return Err(PegError::Invalid(format!(
                "contact point {i} ({:?}) is not finite",
                p
            )));
        }
        let Some(pa) = patch(points) else {
            return Ok(vec![0.0; CONTACT_FEATURES]);
        };
        let (major, minor, angle) = pa.principal();
        let depth = points.iter().map(|p| p[2]).sum::<f64>() / points.len() as f64;
        let mm = 1e3;
        Ok([
            1.0,
            points.len() as f64,
            pa.centroid_m[0] * mm,
            pa.centroid_m[1] * mm,
            depth * mm,
            major.sqrt() * mm,
            minor.sqrt() * mm,
            (2.0 * angle).cos(),
            (2.0 * angle).sin(),
            force_n,
        ]
        .map(|v| v as f32)
        .to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vertical_strip_gives_its_centroid_spread_and_axis() {
        // A 4 x 12 mm strip along y centred at (1, -2) mm, 0.3 mm deep.
        let pts: Vec<[f64; 3]> = [(-1.0, -8.0), (3.0, -8.0), (3.0, 4.0), (-1.0, 4.0)]
            .iter()
            .map(|&(x, y)| [x * 1e-3, y * 1e-3, 3e-4])
            .collect();
        let z = ContactFeatures.latent(&pts, 2.0).unwrap();
        assert_eq!(z.len(), CONTACT_FEATURES);
        assert_eq!((z[0], z[1]), (1.0, 4.0));
        assert!((z[2] - 1.0).abs() < 1e-5 && (z[3] + 2.0).abs() < 1e-5);
        assert!((z[4] - 0.3).abs() < 1e-6);
        assert!((z[5] - 12.0 / 12f32.sqrt()).abs() < 1e-4);
        assert!((z[6] - 4.0 / 12f32.sqrt()).abs() < 1e-4);
        // Major axis along y: 2a = pi.
        assert!((z[7] + 1.0).abs() < 1e-6 && z[8].abs() < 1e-6);
        assert_eq!(z[9], 2.0);
    }

    #[test]
    fn no_contact_is_zero_and_bad_values_are_errors() {
        assert_eq!(ContactFeatures.latent(&[], 0.0).unwrap(), vec![0.0; 10]);
        let e = ContactFeatures
            .latent(&[[0.0, f64::NAN, 0.0]], 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("contact point 0"), "{e}");
        assert!(ContactFeatures.latent(&[], f64::INFINITY).is_err());
        assert!(ContactFeatures.latent(&[], -1.0).is_err());
    }
}
