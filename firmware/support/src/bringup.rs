//! A closed-form OCM LUT for bring-up and tests, before (or without) the
//! physics generator `ocm-lutgen`.
//!
//! The model is monotone and affine in pressure, like the real maps:
//! `F_A(eps, P) = K (eps + eps^3 / 2) - A P (1 + 0.3 eps)` with `K = 20 N`
//! and `A = 2.86e-4 m^2`; `M(phi, s, P) = k_b (l0 / s) phi (1 + 0.2 phi^2)`
//! plus `1e-6 P phi`, with `k_b = 0.3 N*m/rad`. It is NOT the origami
//! physics; it only gives the firmware a valid image of the right shape.

use ocm_shared::lut::pressure_grid_pa;
use ocm_shared::lut::{
    AxialTableSpec, BendingTableSpec, EncodeError, encode, length_grid_m, strain_grid,
};
use ocm_shared::params::OcmParams;

const N_EPS: u16 = 65;
const N_P: u16 = 12;
const N_S: u16 = 9;
const N_U: u16 = 33;
const EPS_MIN: f64 = -0.6;
const EPS_MAX: f64 = 0.6;
const P_MIN_PA: f64 = -22_000.0;
const P_MAX_PA: f64 = 38_000.0;
const K_N: f64 = 20.0;
const AREA_M2: f64 = 2.86e-4;
const KB_NM_PER_RAD: f64 = 0.3;
const PHI_MAX_RAD: f64 = 0.8;

/// Axial force of the closed-form model, N.
pub fn axial_force_n(eps: f64, p_pa: f64) -> f64 {
    K_N * (eps + 0.5 * eps * eps * eps) - AREA_M2 * p_pa * (1.0 + 0.3 * eps)
}

/// Bending moment of the closed-form model, N*m (`l0` the OCM rest length).
pub fn bending_moment_nm(phi: f64, s_m: f64, p_pa: f64, l0_m: f64) -> f64 {
    KB_NM_PER_RAD * (l0_m / s_m) * phi * (1.0 + 0.2 * phi * phi) + 1e-6 * p_pa * phi
}

/// Writes the image for `params` into `out`; returns its length.
pub fn write_image(params: &OcmParams, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut force = [0.0f64; (N_EPS as usize) * (N_P as usize)];
    for j in 0..N_P {
        let p = pressure_grid_pa(P_MIN_PA, P_MAX_PA, N_P, j);
        for i in 0..N_EPS {
            let eps = strain_grid(EPS_MIN, EPS_MAX, N_EPS, i);
            force[usize::from(j) * usize::from(N_EPS) + usize::from(i)] = axial_force_n(eps, p);
        }
    }
    let l0 = params.rest_length_m;
    let (s_min, s_max) = (l0 * (1.0 + EPS_MIN), l0 * (1.0 + EPS_MAX));
    let phi_max = [PHI_MAX_RAD; N_S as usize];
    let mut m0 = [0.0f64; (N_S as usize) * (N_U as usize)];
    let mut m1 = [0.0f64; (N_S as usize) * (N_U as usize)];
    for k in 0..N_S {
        let s = length_grid_m(s_min, s_max, N_S, k);
        for i in 0..N_U {
            let phi = PHI_MAX_RAD * f64::from(i) / f64::from(N_U - 1);
            let at = usize::from(k) * usize::from(N_U) + usize::from(i);
            m0[at] = bending_moment_nm(phi, s, 0.0, l0);
            m1[at] = 1e-6 * phi;
        }
    }
    encode(
        params.hash(),
        &AxialTableSpec {
            eps_min: EPS_MIN,
            eps_max: EPS_MAX,
            n_eps: N_EPS,
            p_min_pa: P_MIN_PA,
            p_max_pa: P_MAX_PA,
            n_p: N_P,
            force_n: &force,
        },
        &BendingTableSpec {
            s_min_m: s_min,
            s_max_m: s_max,
            n_s: N_S,
            n_u: N_U,
            phi_max_rad: &phi_max,
            m0_nm: &m0,
            m1_nm_per_pa: &m1,
        },
        out,
    )
}
