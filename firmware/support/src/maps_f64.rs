//! The OCM maps of `ocm_firmware::maps` in `f64` SI units (N, Pa, N*m, m,
//! rad), for the reference twin: the LUT image read in floating point, and
//! the firmware's [`FastLut`] answering through its image.

use ocm_firmware::maps::FastLut;
use ocm_shared::lut::LutImage;

/// The same maps in `f64` SI units (N, Pa, N*m, m, rad).
pub trait OcmMapsF64 {
    /// `eps = F_A^-1(F, P)`.
    fn strain_f64(&self, force_n: f64, pressure_pa: f64) -> Option<f64>;
    /// `F = F_A(eps, P)`.
    fn force_f64(&self, strain: f64, pressure_pa: f64) -> Option<f64>;
    /// `phi = F_B^-1(M, s, P)`.
    fn bend_f64(&self, moment_nm: f64, s_m: f64, pressure_pa: f64) -> Option<f64>;

    /// The pressure with `F_A(eps, P) = F` by one secant step between `lo`
    /// and `hi` (exact for a map affine in `P`).
    fn pressure_for_f64(&self, strain: f64, force_n: f64, lo: f64, hi: f64) -> Option<f64> {
        let fa = self.force_f64(strain, lo)?;
        let fb = self.force_f64(strain, hi)?;
        let p = lo + (force_n - fa) * (hi - lo) / (fb - fa);
        p.is_finite().then_some(p)
    }
}

impl OcmMapsF64 for LutImage<'_> {
    fn strain_f64(&self, force_n: f64, pressure_pa: f64) -> Option<f64> {
        self.axial_strain_f64(force_n, pressure_pa)
            .ok()
            .map(|l| l.value)
    }

    fn force_f64(&self, strain: f64, pressure_pa: f64) -> Option<f64> {
        self.axial_force_f64(strain, pressure_pa)
            .ok()
            .map(|l| l.value)
    }

    fn bend_f64(&self, moment_nm: f64, s_m: f64, pressure_pa: f64) -> Option<f64> {
        self.bending_angle_f64(moment_nm, s_m, pressure_pa)
            .ok()
            .map(|l| l.value)
    }
}

impl OcmMapsF64 for FastLut<'_> {
    fn strain_f64(&self, force_n: f64, pressure_pa: f64) -> Option<f64> {
        self.image.strain_f64(force_n, pressure_pa)
    }

    fn force_f64(&self, strain: f64, pressure_pa: f64) -> Option<f64> {
        self.image.force_f64(strain, pressure_pa)
    }

    fn bend_f64(&self, moment_nm: f64, s_m: f64, pressure_pa: f64) -> Option<f64> {
        self.image.bend_f64(moment_nm, s_m, pressure_pa)
    }
}
