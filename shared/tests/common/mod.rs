//! A synthetic OCM with closed-form force and moment, sampled into LUT
//! specs, so that the image's lookups can be checked against exact values.
//!
//! Axial: `F(eps, P) = A sinh(B eps) - P C (1 + eps)`, increasing in `eps`
//! for every pressure the lookups accept (`A B - C P > 0` up to 50 kPa), and
//! exactly affine in `P` like the real pressure work.
//! Bending: `M(phi, s, P) = k(s) (phi + phi^3 / 3) - P d(s) sin(phi)` with
//! `phi_max(s)` growing in `s`; also affine in `P` and increasing in `phi`.
#![allow(dead_code)] // each test crate uses its own part of the helpers

use ocm_shared::lut::{
    AxialTableSpec, BendingTableSpec, encode, encoded_len, length_grid_m, pressure_grid_pa,
    strain_grid,
};

/// Axial stiffness scale, N.
pub const A_N: f64 = 5.0;
/// Axial stiffening rate.
pub const B: f64 = 4.0;
/// Effective piston area, m^2.
pub const C_M2: f64 = 3.0e-4;

/// Axial force of the synthetic OCM, N.
pub fn force_n(eps: f64, p_pa: f64) -> f64 {
    A_N * (B * eps).sinh() - p_pa * C_M2 * (1.0 + eps)
}

/// Bending stiffness at length `s`, N*m/rad.
pub fn k_nm(s_m: f64) -> f64 {
    0.05 + 2.0 * (s_m - 0.02)
}

/// Pressure softening of the bending moment at length `s`, N*m/Pa.
pub fn d_nm_per_pa(s_m: f64) -> f64 {
    5.0e-7 * (1.0 + 10.0 * (s_m - 0.02))
}

/// Maximum feasible angle at length `s`, rad.
pub fn phi_max_rad(s_m: f64) -> f64 {
    0.3 + 15.0 * (s_m - 0.02)
}

/// Moment at zero pressure, N*m.
pub fn m0_nm(phi: f64, s_m: f64) -> f64 {
    k_nm(s_m) * (phi + phi.powi(3) / 3.0)
}

/// Moment per pascal, N*m/Pa.
pub fn m1_nm_per_pa(phi: f64, s_m: f64) -> f64 {
    -d_nm_per_pa(s_m) * phi.sin()
}

/// Bending moment of the synthetic OCM, N*m.
pub fn moment_nm(phi: f64, s_m: f64, p_pa: f64) -> f64 {
    m0_nm(phi, s_m) + p_pa * m1_nm_per_pa(phi, s_m)
}

/// Root of an increasing `f` on `[lo, hi]` by bisection to 1e-14.
pub fn solve_increasing(f: impl Fn(f64) -> f64, target: f64, mut lo: f64, mut hi: f64) -> f64 {
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-14 {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Grid bounds and sizes of a synthetic table set.
#[derive(Debug, Clone, Copy)]
pub struct Grids {
    pub eps: (f64, f64, u16),
    pub p_pa: (f64, f64, u16),
    pub s_m: (f64, f64, u16),
    pub n_u: u16,
    /// Round `phi_max` to a multiple of 2^-9 rad so that every angle grid
    /// point of a 129-point grid is exact in `I16F16`.
    pub exact_phi_max: bool,
}

impl Grids {
    /// The default grids of issue 2 (axial 16 x 129, bending 17 x 129).
    pub const DEFAULT: Self = Self {
        eps: (-0.6, 0.6, 129),
        p_pa: (0.0, 30_000.0, 16),
        s_m: (0.02, 0.06, 17),
        n_u: 129,
        exact_phi_max: false,
    };

    /// Grids whose every point is exact in its Q-format, so lookups at grid
    /// points must return the stored bits.
    pub const EXACT: Self = Self {
        eps: (-0.5, 0.5, 129),
        p_pa: (0.0, 30_000.0, 16),
        s_m: (0.031_25, 0.062_5, 17),
        n_u: 129,
        exact_phi_max: true,
    };

    /// A tiny image for exhaustive corruption tests.
    pub const TINY: Self = Self {
        eps: (-0.5, 0.5, 5),
        p_pa: (0.0, 30_000.0, 3),
        s_m: (0.02, 0.06, 2),
        n_u: 4,
        exact_phi_max: false,
    };
}

/// Sampled tables of the synthetic OCM on some grids.
pub struct Tables {
    pub grids: Grids,
    pub force_n: Vec<f64>,
    pub phi_max_rad: Vec<f64>,
    pub m0_nm: Vec<f64>,
    pub m1_nm_per_pa: Vec<f64>,
}

impl Tables {
    /// Samples the synthetic model at the grid points the image will use.
    pub fn sample(grids: Grids) -> Self {
        let (e0, e1, ne) = grids.eps;
        let (p0, p1, np) = grids.p_pa;
        let (s0, s1, ns) = grids.s_m;
        let mut force = Vec::new();
        for j in 0..np {
            let p = pressure_grid_pa(p0, p1, np, j);
            for i in 0..ne {
                force.push(force_n(strain_grid(e0, e1, ne, i), p));
            }
        }
        let mut phi_max = Vec::new();
        let mut m0 = Vec::new();
        let mut m1 = Vec::new();
        for k in 0..ns {
            let s = length_grid_m(s0, s1, ns, k);
            let mut top = phi_max_rad(s);
            if grids.exact_phi_max {
                top = (top * 512.0).round() / 512.0;
            }
            phi_max.push(top);
            for i in 0..grids.n_u {
                let phi = top * f64::from(i) / f64::from(grids.n_u - 1);
                m0.push(m0_nm(phi, s));
                m1.push(m1_nm_per_pa(phi, s));
            }
        }
        Self {
            grids,
            force_n: force,
            phi_max_rad: phi_max,
            m0_nm: m0,
            m1_nm_per_pa: m1,
        }
    }

    /// The axial spec borrowing these tables.
    pub fn axial(&self) -> AxialTableSpec<'_> {
        let g = self.grids;
        AxialTableSpec {
            eps_min: g.eps.0,
            eps_max: g.eps.1,
            n_eps: g.eps.2,
            p_min_pa: g.p_pa.0,
            p_max_pa: g.p_pa.1,
            n_p: g.p_pa.2,
            force_n: &self.force_n,
        }
    }

    /// The bending spec borrowing these tables.
    pub fn bending(&self) -> BendingTableSpec<'_> {
        let g = self.grids;
        BendingTableSpec {
            s_min_m: g.s_m.0,
            s_max_m: g.s_m.1,
            n_s: g.s_m.2,
            n_u: g.n_u,
            phi_max_rad: &self.phi_max_rad,
            m0_nm: &self.m0_nm,
            m1_nm_per_pa: &self.m1_nm_per_pa,
        }
    }

    /// Encodes the tables with `hash` into a fresh buffer of exactly the
    /// image's length.
    pub fn encode(&self, hash: u64) -> Vec<u8> {
        let (axial, bending) = (self.axial(), self.bending());
        let mut out = vec![0u8; encoded_len(&axial, &bending)];
        let n = encode(hash, &axial, &bending, &mut out).expect("synthetic tables encode");
        assert_eq!(n, out.len());
        out
    }
}

/// Deterministic uniform samples (SplitMix64) for off-grid test points.
pub struct Rng(u64);

impl Rng {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Next value uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// Recomputes the CRC trailer of an image after a deliberate edit.
pub fn fix_crc(image: &mut [u8]) {
    let body = image.len() - 4;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&image[..body]);
    image[body..].copy_from_slice(&crc.to_le_bytes());
}
