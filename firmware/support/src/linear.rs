//! A linear-spring OCM with closed-form maps in fixed point and in `f64`,
//! so that the kinematics can be checked without any table.

use ocm_firmware::fx;
use ocm_firmware::maps::OcmMaps;

use crate::maps_f64::OcmMapsF64;

/// A linear-spring OCM: `F = k (eps - eps_p P)`, `phi = M / k_b`; strains
/// are limited to `[-0.9, 1.5]`. Closed form in both arithmetics, so the
/// kinematics can be checked without a table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearOcm {
    /// Axial stiffness per unit strain, newtons.
    pub axial_stiffness_n: f64,
    /// Free strain per pascal of pressure.
    pub strain_per_pa: f64,
    /// Bending stiffness, newton metres per radian.
    pub bending_stiffness_nm_per_rad: f64,
}

impl LinearOcm {
    /// A soft OCM of the size of Table 3.1: 0.5 free strain at 35 kPa.
    pub const SOFT: Self = Self {
        axial_stiffness_n: 20.0,
        strain_per_pa: 0.5 / 35_000.0,
        bending_stiffness_nm_per_rad: 0.5,
    };

    const EPS_MIN: f64 = -0.9;
    const EPS_MAX: f64 = 1.5;
}

impl OcmMapsF64 for LinearOcm {
    fn strain_f64(&self, force_n: f64, pressure_pa: f64) -> Option<f64> {
        let eps = force_n / self.axial_stiffness_n + self.strain_per_pa * pressure_pa;
        eps.is_finite()
            .then_some(eps.clamp(Self::EPS_MIN, Self::EPS_MAX))
    }

    fn force_f64(&self, strain: f64, pressure_pa: f64) -> Option<f64> {
        let f = self.axial_stiffness_n * (strain - self.strain_per_pa * pressure_pa);
        f.is_finite().then_some(f)
    }

    fn bend_f64(&self, moment_nm: f64, _s_m: f64, _pressure_pa: f64) -> Option<f64> {
        let phi = moment_nm / self.bending_stiffness_nm_per_rad;
        phi.is_finite().then_some(phi)
    }
}

impl OcmMaps for LinearOcm {
    fn strain(&self, force_q16: i32, pressure_q8: i32) -> Option<i32> {
        // Q16 force / (N) + (1/Pa Q40) * Pa Q8 -> Q16 strain, all in i64.
        let inv_k_q32 = fx::from_f64(1.0 / self.axial_stiffness_n, 32);
        let per_pa_q40 = libm::round(self.strain_per_pa * libm::exp2(40.0)) as i64;
        let from_force = (i64::from(force_q16) * i64::from(inv_k_q32)) >> 32;
        let from_p = (per_pa_q40 * i64::from(pressure_q8)) >> 32;
        let eps = from_force + from_p;
        let lo = fx::from_f64(Self::EPS_MIN, 16);
        let hi = fx::from_f64(Self::EPS_MAX, 16);
        Some(fx::sat(eps).clamp(lo, hi))
    }

    fn force(&self, strain_q16: i32, pressure_q8: i32) -> Option<i32> {
        let k_q16 = i64::from(fx::from_f64(self.axial_stiffness_n, 16));
        let per_pa_q40 = libm::round(self.strain_per_pa * libm::exp2(40.0)) as i64;
        let free_q16 = (per_pa_q40 * i64::from(pressure_q8)) >> 32;
        Some(fx::sat(((i64::from(strain_q16) - free_q16) * k_q16) >> 16))
    }

    fn bend(&self, moment_q24: i32, _s_q24: i32, _pressure_q8: i32) -> Option<i32> {
        let inv_kb_q24 = i64::from(fx::from_f64(1.0 / self.bending_stiffness_nm_per_rad, 24));
        Some(fx::sat((i64::from(moment_q24) * inv_kb_q24) >> 32))
    }
}
