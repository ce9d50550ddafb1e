//! `f64` reference twin of `ocm_firmware::kinematics`: the same equations in
//! floating point and SI units, the yardstick of the fixed-point path.
//!
//! The piecewise-constant-curvature geometry (column lengths, eq 3.26, and
//! the arc-to-tip map) is the host's one `f64` PCC map, `ocm_lutgen::pcc`;
//! everything else (forces, strains, bending) is the firmware's own model.

use ocm_lutgen::pcc::{self, COS_BETA as BETA_COS, SIN_BETA as BETA_SIN};
use ocm_shared::protocol::{Geometry, Load, MAX_SEGMENTS, Mount};

use ocm_firmware::kinematics::GRAVITY;

use crate::maps_f64::OcmMapsF64;

/// Manipulator description in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelF64 {
    /// Segments.
    pub segments: usize,
    /// OCMs per column.
    pub ocms: f64,
    /// Rest length of one OCM, m.
    pub l0_m: f64,
    /// Column radius, m.
    pub d_m: f64,
    /// Weight of each segment, N.
    pub weight_n: f64,
    /// +1 hanging, -1 upright.
    pub gravity_sign: f64,
}

impl ModelF64 {
    /// From a geometry (no validation: see `ocm_firmware::kinematics::Model::new`).
    pub fn new(g: &Geometry) -> Self {
        let m = &g.manipulator;
        let ocms = f64::from(m.ocms_per_column);
        Self {
            segments: (m.segments as usize).min(MAX_SEGMENTS),
            ocms,
            l0_m: g.ocm.rest_length_m,
            d_m: m.column_radius_m,
            weight_n: (m.plate_mass_kg + 3.0 * ocms * g.ocm.mass_kg) * GRAVITY,
            gravity_sign: match g.mount {
                Mount::Hanging => 1.0,
                Mount::Upright => -1.0,
            },
        }
    }
}

/// Tip load in SI: axial force (payload weight included), moments.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoadF64 {
    /// Axial force, N, positive stretches.
    pub fz_n: f64,
    /// Moment about x, N*m.
    pub mx_nm: f64,
    /// Moment about y, N*m.
    pub my_nm: f64,
}

impl LoadF64 {
    /// From a wire load.
    pub fn new(load: &Load, model: &ModelF64) -> Self {
        Self {
            fz_n: f64::from(load.force_z_n)
                + model.gravity_sign * f64::from(load.payload_kg) * GRAVITY,
            mx_nm: f64::from(load.moment_x_newton_m),
            my_nm: f64::from(load.moment_y_newton_m),
        }
    }
}

/// A segment configuration in SI: backbone m, bend rad, direction rad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ConfigF64 {
    /// Backbone arc length, m.
    pub backbone_m: f64,
    /// Bending angle, rad.
    pub bend_rad: f64,
    /// Bending direction, rad.
    pub direction_rad: f64,
}

/// Column tensions (eq 3.27-3.29), N.
pub fn column_forces(model: &ModelF64, load: &LoadF64, seg: usize) -> [f64; 3] {
    let above = (model.segments.saturating_sub(seg)) as f64 * model.weight_n;
    let total = load.fz_n + model.gravity_sign * above;
    core::array::from_fn(|i| {
        total / 3.0
            + 2.0 / (3.0 * model.d_m) * (load.mx_nm * BETA_SIN[i] - load.my_nm * BETA_COS[i])
    })
}

fn moment_bending<M: OcmMapsF64>(
    maps: &M,
    model: &ModelF64,
    load: &LoadF64,
    s_ocm: f64,
    p_mean: f64,
) -> Option<[f64; 3]> {
    let m = libm::hypot(load.mx_nm, load.my_nm);
    if m == 0.0 {
        return Some([0.0; 3]);
    }
    let theta = maps.bend_f64(m, s_ocm, p_mean)? * model.ocms;
    Some(core::array::from_fn(|i| {
        model.d_m * theta * (load.my_nm * BETA_COS[i] - load.mx_nm * BETA_SIN[i]) / m
    }))
}

/// Column lengths under pressures (eq 3.30-3.34), m.
pub fn column_lengths<M: OcmMapsF64>(
    maps: &M,
    model: &ModelF64,
    load: &LoadF64,
    seg: usize,
    p_pa: [f64; 3],
) -> Option<[f64; 3]> {
    let f = column_forces(model, load, seg);
    let mut eps = [0.0; 3];
    for i in 0..3 {
        eps[i] = maps.strain_f64(f[i], p_pa[i])?;
    }
    let eps_mean = (eps[0] + eps[1] + eps[2]) / 3.0;
    let p_mean = (p_pa[0] + p_pa[1] + p_pa[2]) / 3.0;
    let bend = moment_bending(maps, model, load, model.l0_m * (1.0 + eps_mean), p_mean)?;
    let column = model.l0_m * model.ocms;
    Some(core::array::from_fn(|i| column * (1.0 + eps[i]) - bend[i]))
}

/// PCC configuration from column lengths (eq 3.26).
pub fn pcc_from_lengths(model: &ModelF64, l: [f64; 3]) -> ConfigF64 {
    let c = pcc::Config::from_column_lengths(l, model.d_m);
    let bend_rad = c.bend_rad();
    ConfigF64 {
        backbone_m: c.backbone_m,
        bend_rad,
        direction_rad: if bend_rad == 0.0 {
            0.0
        } else {
            c.bend_y_rad.atan2(c.bend_x_rad)
        },
    }
}

/// Column lengths of a configuration (inverse of eq 3.26), m.
pub fn lengths_from_pcc(model: &ModelF64, c: &ConfigF64) -> [f64; 3] {
    polar(c).column_lengths(model.d_m)
}

/// The PCC map's configuration of a polar one.
fn polar(c: &ConfigF64) -> pcc::Config {
    pcc::Config::from_polar(c.backbone_m, c.bend_rad, c.direction_rad)
}

/// Rigid transform in SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseF64 {
    /// Rotation matrix, rows.
    pub r: [[f64; 3]; 3],
    /// Translation, m.
    pub p: [f64; 3],
}

impl PoseF64 {
    /// The identity.
    pub const IDENTITY: Self = Self {
        r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        p: [0.0; 3],
    };

    /// `self * other`.
    pub fn compose(&self, o: &PoseF64) -> PoseF64 {
        let mut out = PoseF64::IDENTITY;
        for i in 0..3 {
            out.p[i] = self.p[i] + (0..3).map(|k| self.r[i][k] * o.p[k]).sum::<f64>();
            for j in 0..3 {
                out.r[i][j] = (0..3).map(|k| self.r[i][k] * o.r[k][j]).sum();
            }
        }
        out
    }
}

/// Top-plate pose of one segment under PCC: the arc of length `backbone_m`
/// bent by `bend_rad` towards `direction_rad`, base frame to tip frame.
pub fn segment_pose(c: &ConfigF64) -> PoseF64 {
    let q = polar(c);
    PoseF64 {
        r: q.rotation(),
        p: q.position(),
    }
}

/// Tip pose of stacked segments, base first.
pub fn tip_pose(configs: &[ConfigF64]) -> PoseF64 {
    configs
        .iter()
        .fold(PoseF64::IDENTITY, |acc, c| acc.compose(&segment_pose(c)))
}

/// Forward map (eq 3.35): configuration of each segment, written to `out`.
/// Returns the number of segments, or `None` outside the maps' domain.
pub fn forward<M: OcmMapsF64>(
    maps: &M,
    model: &ModelF64,
    load: &LoadF64,
    p_pa: &[f64],
    out: &mut [ConfigF64; MAX_SEGMENTS],
) -> Option<usize> {
    for (seg, slot) in out.iter_mut().enumerate().take(model.segments) {
        let p = p_pa.get(3 * seg..3 * seg + 3)?;
        let l = column_lengths(maps, model, load, seg, [p[0], p[1], p[2]])?;
        *slot = pcc_from_lengths(model, l);
    }
    Some(model.segments)
}

/// Pressure with `F_A(eps, P) = F` (see [`OcmMapsF64::pressure_for_f64`]).
pub fn pressure_for<M: OcmMapsF64>(
    maps: &M,
    eps: f64,
    force: f64,
    lo: f64,
    hi: f64,
) -> Option<f64> {
    maps.pressure_for_f64(eps, force, lo, hi)
}

/// Inverse map (eq 3.36): pressures for the target configurations, clamped
/// to `[lo, hi]`, written to `out` (three per segment).
pub fn inverse<M: OcmMapsF64>(
    maps: &M,
    model: &ModelF64,
    load: &LoadF64,
    target: &[ConfigF64],
    lo: f64,
    hi: f64,
    out: &mut [f64; 3 * MAX_SEGMENTS],
) -> Option<()> {
    if target.len() != model.segments {
        return None;
    }
    for (seg, c) in target.iter().enumerate() {
        let lt = lengths_from_pcc(model, c);
        let f = column_forces(model, load, seg);
        let s_ocm = c.backbone_m / model.ocms;
        let column = model.l0_m * model.ocms;
        let mut p_mean = 0.0;
        let mut p = [0.0; 3];
        let passes = if load.mx_nm == 0.0 && load.my_nm == 0.0 {
            1
        } else {
            2
        };
        for _ in 0..passes {
            let bend = moment_bending(maps, model, load, s_ocm, p_mean)?;
            for i in 0..3 {
                let eps = (lt[i] + bend[i]) / column - 1.0;
                p[i] = pressure_for(maps, eps, f[i], lo, hi)?;
            }
            p_mean = ((p[0] + p[1] + p[2]) / 3.0).clamp(lo, hi);
        }
        for i in 0..3 {
            out[3 * seg + i] = p[i].clamp(lo, hi);
        }
    }
    Some(())
}
