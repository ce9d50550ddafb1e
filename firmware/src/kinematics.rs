//! Fixed-point kinematics of the OCM manipulator (Ch. 3.3.5, App. B).
//!
//! Each segment has three actuator columns at `beta_i = 0, 120, 240` degrees
//! on a circle of radius `d`; a column is `n` OCMs in series sharing one
//! pressure. A segment's PCC configuration is `(S, theta, phi)`: backbone arc
//! length, bending angle, and the direction (from column 1 towards column 2)
//! the segment bends to. With this convention the column lengths are
//! `l_i = S - d theta cos(beta_i - phi)`, whose inverse is eq 3.26
//! (`phi` is measured from column 1 rather than from the column-2/3 bisector
//! of the dissertation's formula; `theta` is identical).
//!
//! Loads follow the statics of the top plate: actuator `i` carries tension
//! `T_i = F/3 + 2/(3d) (M_x sin beta_i - M_y cos beta_i)`, which solves the
//! force and moment balances of eq 3.27-3.28 for this column layout (the
//! role of eq 3.29). `F` is the tip force plus the weights of the segment
//! and of everything above it. The moment also bends each OCM through the
//! bending map (eq 3.30-3.31), which shortens the columns on the concave
//! side as in eq 3.34.
//!
//! The `f64` twin of every function lives in `ocm_firmware_support::reference`.

use heapless::Vec;
use ocm_shared::protocol::{Geometry, Load, MAX_SEGMENTS, Mount, SegmentConfig};

use crate::fx::{
    PI_Q28, Q30_ONE, atan2_q28, div_round, hypot, mul_shr, rshift_round, sat, sin_cos_q28, sinc_q30,
};
use crate::maps::OcmMaps;
use ocm_shared::lut::udiv_u64_by_u32;

/// Standard gravity, m/s^2.
pub const GRAVITY: f64 = 9.806_65;

/// `cos beta_i` of the three columns, Q1.30.
pub const COS_BETA_Q30: [i32; 3] = [Q30_ONE, -(Q30_ONE / 2), -(Q30_ONE / 2)];
/// `sin beta_i` of the three columns, Q1.30.
pub const SIN_BETA_Q30: [i32; 3] = [0, SQRT3_2_Q30, -SQRT3_2_Q30];
const SQRT3_2_Q30: i32 = 929_887_697;
const INV_SQRT3_Q30: i64 = 619_925_131;

/// Fixed-point description of the manipulator, built once from a
/// [`Geometry`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Model {
    /// Segments (1..=[`MAX_SEGMENTS`]).
    pub segments: usize,
    /// OCMs per column.
    pub ocms: i32,
    /// Rest length of one OCM, m Q8.24.
    pub l0_q24: i32,
    /// Rest length of one column (`ocms * l0`), m Q8.24.
    pub column_q24: i32,
    /// Column radius `d`, m Q8.24.
    pub d_q24: i32,
    /// `2 / (3 d)`, 1/m Q16.16.
    pub two_over_3d_q16: i32,
    /// `2^48 / d_q24`: turns a Q8.24 length into a Q3.28 angle by `(x k) >> 20`.
    pub inv_d_k: i64,
    /// `2^48 / column_q24`: turns a Q8.24 column length into a Q16.16
    /// stretch ratio by `(x k) >> 32`.
    pub inv_column_k: i64,
    /// Weight of each segment (plate and its OCMs), N Q16.16.
    pub weight_q16: [i32; MAX_SEGMENTS],
    /// +1 when weights stretch the columns (hanging), -1 when they compress.
    pub gravity_sign: i32,
}

/// Why a [`Geometry`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BadGeometry;

impl Model {
    /// Validates and converts a geometry.
    pub fn new(g: &Geometry) -> Result<Self, BadGeometry> {
        let m = &g.manipulator;
        let o = &g.ocm;
        let segments = m.segments as usize;
        let ok = (1..=MAX_SEGMENTS).contains(&segments)
            && (1..=8).contains(&m.ocms_per_column)
            && in_range(m.column_radius_m, 0.005, 0.5)
            && in_range(m.plate_mass_kg, 0.0, 10.0)
            && in_range(o.rest_length_m, 0.005, 0.5)
            && in_range(o.mass_kg, 0.0, 1.0);
        if !ok {
            return Err(BadGeometry);
        }
        Ok(Self::convert(g))
    }

    /// Converts a geometry without checking it (callers validate, or pass
    /// a known-good constant such as Table 3.1); values out of range
    /// saturate.
    pub fn convert(g: &Geometry) -> Self {
        let m = &g.manipulator;
        let o = &g.ocm;
        let segments = (m.segments as usize).clamp(1, MAX_SEGMENTS);
        let ocms = m.ocms_per_column.clamp(1, 8) as i32;
        let seg_mass = m.plate_mass_kg + 3.0 * f64::from(ocms) * o.mass_kg;
        let w = crate::fx::from_f64(seg_mass * GRAVITY, 16);
        Self {
            segments,
            ocms,
            l0_q24: crate::fx::from_f64(o.rest_length_m, 24),
            column_q24: crate::fx::from_f64(o.rest_length_m * f64::from(ocms), 24),
            d_q24: crate::fx::from_f64(m.column_radius_m, 24),
            two_over_3d_q16: crate::fx::from_f64(2.0 / (3.0 * m.column_radius_m), 16),
            inv_d_k: libm::round(libm::exp2(24.0) / m.column_radius_m) as i64,
            inv_column_k: libm::round(libm::exp2(24.0) / (o.rest_length_m * f64::from(ocms)))
                as i64,
            weight_q16: [w; MAX_SEGMENTS],
            gravity_sign: match g.mount {
                Mount::Hanging => 1,
                Mount::Upright => -1,
            },
        }
    }
}

fn in_range(x: f64, lo: f64, hi: f64) -> bool {
    x.is_finite() && x >= lo && x <= hi
}

/// Tip load in fixed point: axial force N Q16.16 (positive stretches),
/// moments N*m Q8.24.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoadFx {
    /// Axial tip force including the payload weight, N Q16.16.
    pub fz_q16: i32,
    /// Moment about x, N*m Q8.24.
    pub mx_q24: i32,
    /// Moment about y, N*m Q8.24.
    pub my_q24: i32,
}

impl LoadFx {
    /// Converts and range-checks a wire load (|F| <= 200 N, |M| <= 20 N*m,
    /// payload 0..=20 kg).
    pub fn new(load: &Load, model: &Model) -> Option<Self> {
        let payload = f64::from(load.payload_kg);
        let fz = f64::from(load.force_z_n);
        let mx = f64::from(load.moment_x_newton_m);
        let my = f64::from(load.moment_y_newton_m);
        let ok = in_range(payload, 0.0, 20.0)
            && in_range(fz, -200.0, 200.0)
            && in_range(mx, -20.0, 20.0)
            && in_range(my, -20.0, 20.0);
        if !ok {
            return None;
        }
        let total = fz + f64::from(model.gravity_sign) * payload * GRAVITY;
        Some(Self {
            fz_q16: crate::fx::from_f64(total, 16),
            mx_q24: crate::fx::from_f64(mx, 24),
            my_q24: crate::fx::from_f64(my, 24),
        })
    }

    /// Magnitude of the bending moment (eq 3.30), N*m Q8.24.
    pub fn moment_q24(&self) -> i32 {
        if self.mx_q24 == 0 && self.my_q24 == 0 {
            return 0;
        }
        sat(hypot(i64::from(self.mx_q24), i64::from(self.my_q24)))
    }
}

/// Tensions of the three columns of segment `seg` (eq 3.27-3.29), N Q16.16.
pub fn column_forces(model: &Model, load: &LoadFx, seg: usize) -> [i32; 3] {
    let above: i64 = model
        .weight_q16
        .iter()
        .take(model.segments)
        .skip(seg)
        .map(|&w| i64::from(w))
        .sum();
    let total = i64::from(load.fz_q16) + i64::from(model.gravity_sign) * above;
    let third = div_round(total, 3).unwrap_or(0);
    let mut out = [0; 3];
    for (i, f) in out.iter_mut().enumerate() {
        let m_q24 = rshift_round(
            i64::from(load.mx_q24) * i64::from(SIN_BETA_Q30[i])
                - i64::from(load.my_q24) * i64::from(COS_BETA_Q30[i]),
            30,
        );
        let couple = rshift_round(m_q24 * i64::from(model.two_over_3d_q16), 24);
        *f = sat(third + couple);
    }
    out
}

/// Magnitude and direction of a load's bending moment, computed once per
/// load rather than on every use (a square root and a 64-bit division).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MomentFx {
    /// `|M|` (eq 3.30), N*m Q8.24; zero without a moment.
    pub m_q24: i32,
    /// `cos phi_M = M_y / |M|`, Q1.30.
    pub cos_q30: i32,
    /// `sin phi_M = -M_x / |M|`, Q1.30.
    pub sin_q30: i32,
}

impl MomentFx {
    /// The moment of `load`.
    pub fn new(load: &LoadFx) -> Self {
        let m = load.moment_q24();
        // `m > 0` here; `2^52 + m/2 < 2^53` and `m < 2^31`, so the exact
        // 64/32 division (hardware 32-bit divides) gives `round(2^52 / m)`.
        let Some(inv_m) = u32::try_from(m)
            .ok()
            .filter(|&m| m > 0)
            .and_then(|m32| udiv_u64_by_u32((1u64 << 52) + u64::from(m32 / 2), m32))
        else {
            return Self::default();
        };
        // |M_x|, |M_y| <= M bounds the products by 2^52.
        let inv_m = inv_m as i64;
        Self {
            m_q24: m,
            cos_q30: sat(rshift_round(
                i64::from(load.my_q24).saturating_mul(inv_m),
                22,
            )),
            sin_q30: sat(rshift_round(
                -i64::from(load.mx_q24).saturating_mul(inv_m),
                22,
            )),
        }
    }
}

/// A [`LoadFx`] with its moment's magnitude and direction precomputed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PreparedLoad {
    /// The load.
    pub load: LoadFx,
    /// Its moment.
    pub moment: MomentFx,
}

impl PreparedLoad {
    /// Precomputes the moment of `load`.
    pub fn new(load: &LoadFx) -> Self {
        Self {
            load: *load,
            moment: MomentFx::new(load),
        }
    }
}

/// Neutral-axis length of one OCM of a segment with backbone `c`, m Q8.24:
/// the length the inverse map queries the bending map at.
fn ocm_length_q24(model: &Model, c: &SegmentConfig) -> Option<i32> {
    Some(sat(div_round(
        i64::from(c.backbone_q24),
        i64::from(model.ocms),
    )?))
}

/// Column shortening `d theta_B cos(beta_i - phi_M)` caused by the moment's
/// own bending of the OCMs (eq 3.31, 3.34), m Q8.24. Zero without a moment.
fn moment_bending<M: OcmMaps>(
    maps: &M,
    model: &Model,
    moment: &MomentFx,
    s_ocm_q24: i32,
    p_mean_q8: i32,
) -> Option<[i32; 3]> {
    if moment.m_q24 == 0 {
        return Some([0; 3]);
    }
    let phi_ocm_q16 = maps.bend(moment.m_q24, s_ocm_q24, p_mean_q8)?;
    let theta_q28 = sat((i64::from(phi_ocm_q16) * i64::from(model.ocms)) << 12);
    let d_theta_q24 = mul_shr(model.d_q24, theta_q28, 28);
    let mut out = [0; 3];
    for (i, o) in out.iter_mut().enumerate() {
        // cos(beta_i - phi_M).
        let c_q30 = rshift_round(
            i64::from(moment.cos_q30) * i64::from(COS_BETA_Q30[i])
                + i64::from(moment.sin_q30) * i64::from(SIN_BETA_Q30[i]),
            30,
        );
        *o = mul_shr(d_theta_q24, sat(c_q30), 30);
    }
    Some(out)
}

/// Column lengths of segment `seg` under pressures `p` (eq 3.30-3.34),
/// m Q8.24.
pub fn column_lengths<M: OcmMaps>(
    maps: &M,
    model: &Model,
    load: &LoadFx,
    seg: usize,
    p_q8: [i32; 3],
) -> Option<[i32; 3]> {
    column_lengths_prepared(maps, model, &PreparedLoad::new(load), seg, p_q8)
}

/// [`column_lengths`] of a [`PreparedLoad`].
pub fn column_lengths_prepared<M: OcmMaps>(
    maps: &M,
    model: &Model,
    prepared: &PreparedLoad,
    seg: usize,
    p_q8: [i32; 3],
) -> Option<[i32; 3]> {
    let load = &prepared.load;
    let forces = column_forces(model, load, seg);
    let mut eps = [0i32; 3];
    for i in 0..3 {
        eps[i] = maps.strain(forces[i], p_q8[i])?;
    }
    let eps_mean = (i64::from(eps[0]) + i64::from(eps[1]) + i64::from(eps[2])) / 3;
    let s_ocm = sat(rshift_round(
        i64::from(model.l0_q24) * (65_536 + eps_mean),
        16,
    ));
    let p_mean = sat((i64::from(p_q8[0]) + i64::from(p_q8[1]) + i64::from(p_q8[2])) / 3);
    let bend = moment_bending(maps, model, &prepared.moment, s_ocm, p_mean)?;
    let mut l = [0i32; 3];
    for i in 0..3 {
        let axial = rshift_round(
            i64::from(model.column_q24) * (65_536 + i64::from(eps[i])),
            16,
        );
        l[i] = sat(axial - i64::from(bend[i]));
    }
    Some(l)
}

/// A segment's configuration as backbone length and bending vector
/// `theta (cos phi, sin phi)`: linear in the column lengths, so it needs no
/// trigonometry and fuses by plain addition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BendVector {
    /// Backbone arc length, m Q8.24.
    pub backbone_q24: i32,
    /// `theta cos phi`, rad Q3.28.
    pub x_q28: i32,
    /// `theta sin phi`, rad Q3.28.
    pub y_q28: i32,
}

/// Bending vector from the three column lengths (eq 3.26 before the polar
/// form): `d theta cos phi = (l2 + l3 - 2 l1) / 3`, `d theta sin phi =
/// (l3 - l2) / sqrt 3`.
pub fn vector_from_lengths(model: &Model, l_q24: [i32; 3]) -> BendVector {
    let [l1, l2, l3] = l_q24.map(i64::from);
    let s = div_round(l1 + l2 + l3, 3).unwrap_or(0);
    let a = div_round(l2 + l3 - 2 * l1, 3).unwrap_or(0);
    let b = rshift_round((l3 - l2) * INV_SQRT3_Q30, 30);
    BendVector {
        backbone_q24: sat(s),
        x_q28: sat(a.saturating_mul(model.inv_d_k) >> 20),
        y_q28: sat(b.saturating_mul(model.inv_d_k) >> 20),
    }
}

/// Polar form `(S, theta, phi)` of a bending vector.
pub fn config_from_vector(v: &BendVector) -> SegmentConfig {
    let (x, y) = (i64::from(v.x_q28), i64::from(v.y_q28));
    let theta = hypot(x, y);
    SegmentConfig {
        backbone_q24: v.backbone_q24,
        bend_q28: sat(theta),
        direction_q28: if theta == 0 { 0 } else { atan2_q28(y, x) },
    }
}

/// Bending vector of a configuration.
pub fn vector_from_config(c: &SegmentConfig) -> BendVector {
    let (s, co) = sin_cos_q28(c.direction_q28);
    BendVector {
        backbone_q24: c.backbone_q24,
        x_q28: mul_shr(c.bend_q28, co, 30),
        y_q28: mul_shr(c.bend_q28, s, 30),
    }
}

/// Column lengths of a bending vector: `l_i = S - d (cos beta_i vx + sin
/// beta_i vy)`.
pub fn lengths_from_vector(model: &Model, v: &BendVector) -> [i32; 3] {
    let mut l = [0i32; 3];
    for (i, li) in l.iter_mut().enumerate() {
        let proj = rshift_round(
            i64::from(COS_BETA_Q30[i]) * i64::from(v.x_q28)
                + i64::from(SIN_BETA_Q30[i]) * i64::from(v.y_q28),
            30,
        );
        let dl = rshift_round(proj.saturating_mul(i64::from(model.d_q24)), 28);
        *li = sat(i64::from(v.backbone_q24) - dl);
    }
    l
}

/// PCC configuration from the three column lengths (eq 3.26).
pub fn pcc_from_lengths(model: &Model, l_q24: [i32; 3]) -> SegmentConfig {
    config_from_vector(&vector_from_lengths(model, l_q24))
}

/// Column lengths of a PCC configuration (inverse of eq 3.26), m Q8.24.
pub fn lengths_from_pcc(model: &Model, c: &SegmentConfig) -> [i32; 3] {
    lengths_from_vector(model, &vector_from_config(c))
}

/// A rigid transform: rotation Q1.30 and translation m Q8.24.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pose {
    /// Rotation matrix, rows, Q1.30.
    pub r_q30: [[i32; 3]; 3],
    /// Translation, m Q8.24.
    pub p_q24: [i32; 3],
}

impl Pose {
    /// The identity.
    pub const IDENTITY: Self = Self {
        r_q30: [[Q30_ONE, 0, 0], [0, Q30_ONE, 0], [0, 0, Q30_ONE]],
        p_q24: [0; 3],
    };

    /// `self * other`.
    pub fn compose(&self, other: &Pose) -> Pose {
        let mut out = Pose::IDENTITY;
        for i in 0..3 {
            let mut acc = i64::from(self.p_q24[i]) << 30;
            for k in 0..3 {
                acc = acc.saturating_add(i64::from(self.r_q30[i][k]) * i64::from(other.p_q24[k]));
            }
            out.p_q24[i] = sat(rshift_round(acc, 30));
            for j in 0..3 {
                let mut r = 0i64;
                for k in 0..3 {
                    r = r
                        .saturating_add(i64::from(self.r_q30[i][k]) * i64::from(other.r_q30[k][j]));
                }
                out.r_q30[i][j] = sat(rshift_round(r, 30));
            }
        }
        out
    }
}

/// Top-plate position of a segment in its base frame under PCC, m Q8.24
/// (the part of [`segment_pose`] that needs no rotation matrix).
fn segment_position(c: &SegmentConfig) -> [i32; 3] {
    let half = c.bend_q28 / 2;
    let (s_half, c_half) = sin_cos_q28(half);
    let (s_ph, c_ph) = sin_cos_q28(c.direction_q28);
    let sinc_half = i64::from(sinc_q30(half));
    let s = i64::from(c.backbone_q24);
    let r = rshift_round(rshift_round(s * i64::from(s_half), 30) * sinc_half, 30);
    let z = rshift_round(rshift_round(s * sinc_half, 30) * i64::from(c_half), 30);
    [
        sat(rshift_round(r * i64::from(c_ph), 30)),
        sat(rshift_round(r * i64::from(s_ph), 30)),
        sat(z),
    ]
}

/// Tip position of stacked segments, base first, m Q8.24: the translation
/// of [`tip_pose`] without the last segment's rotation.
pub fn tip_position(configs: &[SegmentConfig]) -> [i32; 3] {
    let Some((last, rest)) = configs.split_last() else {
        return [0; 3];
    };
    let base = tip_pose(rest);
    let p = segment_position(last);
    let mut out = [0i32; 3];
    for (i, o) in out.iter_mut().enumerate() {
        let mut acc = i64::from(base.p_q24[i]) << 30;
        for (k, &pk) in p.iter().enumerate() {
            acc = acc.saturating_add(i64::from(base.r_q30[i][k]) * i64::from(pk));
        }
        *o = sat(rshift_round(acc, 30));
    }
    out
}

/// Pose of a segment's top plate in its base frame under PCC.
pub fn segment_pose(c: &SegmentConfig) -> Pose {
    let half = c.bend_q28 / 2;
    let (s_half, c_half) = sin_cos_q28(half);
    let (s_ph, c_ph) = sin_cos_q28(c.direction_q28);
    let (sh, ch) = (i64::from(s_half), i64::from(c_half));
    // Double-angle forms save two CORDIC runs.
    let s_th = rshift_round(2 * sh * ch, 30);
    let c_th = (1i64 << 30) - rshift_round(2 * sh * sh, 30);
    let sinc_half = i64::from(sinc_q30(half));
    let s = i64::from(c.backbone_q24);
    // In-plane offset S (1 - cos theta) / theta = S sin(theta/2) sinc(theta/2),
    // height S sin(theta) / theta = S sinc(theta/2) cos(theta/2).
    let r = rshift_round(rshift_round(s * sh, 30) * sinc_half, 30);
    let z = rshift_round(rshift_round(s * sinc_half, 30) * ch, 30);
    let cm1 = c_th - (1i64 << 30);
    let (cp, sp) = (i64::from(c_ph), i64::from(s_ph));
    let q = |x: i64| sat(rshift_round(x, 30));
    let cp2 = rshift_round(cp * cp, 30);
    let sp2 = rshift_round(sp * sp, 30);
    let cpsp = rshift_round(cp * sp, 30);
    Pose {
        r_q30: [
            [q((1 << 60) + cp2 * cm1), q(cpsp * cm1), q(cp * s_th)],
            [q(cpsp * cm1), q((1 << 60) + sp2 * cm1), q(sp * s_th)],
            [q(-cp * s_th), q(-sp * s_th), sat(c_th)],
        ],
        p_q24: [q(r * cp), q(r * sp), sat(z)],
    }
}

/// Tip pose of stacked segments, base segment first (App. B, eq B.19-B.21).
pub fn tip_pose(configs: &[SegmentConfig]) -> Pose {
    let Some((first, rest)) = configs.split_first() else {
        return Pose::IDENTITY;
    };
    rest.iter()
        .fold(segment_pose(first), |acc, c| acc.compose(&segment_pose(c)))
}

/// Forward map `C = f^-1(P, tau_ext)` (eq 3.35): configuration of every
/// segment under pressures `p` (three per segment, base segment first).
pub fn forward<M: OcmMaps>(
    maps: &M,
    model: &Model,
    load: &LoadFx,
    p_q8: &[i32],
) -> Option<Vec<SegmentConfig, MAX_SEGMENTS>> {
    forward_prepared(maps, model, &PreparedLoad::new(load), p_q8)
}

/// [`forward`] under a [`PreparedLoad`].
pub fn forward_prepared<M: OcmMaps>(
    maps: &M,
    model: &Model,
    load: &PreparedLoad,
    p_q8: &[i32],
) -> Option<Vec<SegmentConfig, MAX_SEGMENTS>> {
    let mut out = Vec::new();
    for seg in 0..model.segments {
        let p = p_q8.get(3 * seg..3 * seg + 3)?;
        let l = column_lengths_prepared(maps, model, load, seg, [p[0], p[1], p[2]])?;
        out.push(pcc_from_lengths(model, l)).ok()?;
    }
    Some(out)
}

/// Pressure with `F_A(eps, P) = F` (see [`OcmMaps::pressure_for`]).
pub fn pressure_for<M: OcmMaps>(
    maps: &M,
    eps_q16: i32,
    force_q16: i32,
    p_lo_q8: i32,
    p_hi_q8: i32,
) -> Option<i32> {
    maps.pressure_for(eps_q16, force_q16, p_lo_q8, p_hi_q8)
}

/// Result of the inverse map for one configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InverseSolution {
    /// Pressures, three per segment, Pa Q24.8, clamped into the limits.
    pub pressures_q8: Vec<i32, { 3 * MAX_SEGMENTS }>,
    /// Whether any pressure had to be clamped.
    pub saturated: bool,
    /// Column lengths of the target, three per segment, m Q8.24.
    pub lengths_q24: Vec<i32, { 3 * MAX_SEGMENTS }>,
}

/// Pressures that hold the target configuration under the load
/// (`P = f^-1-1(tau_ext, C)`, eq 3.36), clamped to `[p_lo, p_hi]`.
///
/// The bending map depends weakly on pressure; under a moment it is
/// evaluated twice, the second time at the mean pressure of the first pass.
pub fn inverse<M: OcmMaps>(
    maps: &M,
    model: &Model,
    load: &LoadFx,
    target: &[SegmentConfig],
    p_lo_q8: i32,
    p_hi_q8: i32,
) -> Option<InverseSolution> {
    inverse_with_hint(maps, model, load, target, p_lo_q8, p_hi_q8, None)
}

/// [`inverse`] with the bending map evaluated at a known mean pressure per
/// segment (the app passes the mean of the target's own solution), in a
/// single pass.
pub fn inverse_with_hint<M: OcmMaps>(
    maps: &M,
    model: &Model,
    load: &LoadFx,
    target: &[SegmentConfig],
    p_lo_q8: i32,
    p_hi_q8: i32,
    p_mean_hint_q8: Option<&[i32]>,
) -> Option<InverseSolution> {
    inverse_prepared(
        maps,
        model,
        &PreparedLoad::new(load),
        target,
        (p_lo_q8, p_hi_q8),
        p_mean_hint_q8,
    )
}

/// [`inverse_with_hint`] under a [`PreparedLoad`], pressure limits
/// `(lo, hi)` Pa Q24.8: what a control tick calls, with the moment's square
/// root and division done once per load.
pub fn inverse_prepared<M: OcmMaps>(
    maps: &M,
    model: &Model,
    prepared: &PreparedLoad,
    target: &[SegmentConfig],
    (p_lo_q8, p_hi_q8): (i32, i32),
    p_mean_hint_q8: Option<&[i32]>,
) -> Option<InverseSolution> {
    let load = &prepared.load;
    if target.len() != model.segments {
        return None;
    }
    let mut out = InverseSolution {
        pressures_q8: Vec::new(),
        saturated: false,
        lengths_q24: Vec::new(),
    };
    let moment = prepared.moment.m_q24;
    for (seg, c) in target.iter().enumerate() {
        let l_target = lengths_from_pcc(model, c);
        for &l in &l_target {
            out.lengths_q24.push(l).ok()?;
        }
        let forces = column_forces(model, load, seg);
        let s_ocm = ocm_length_q24(model, c)?;
        let hint = p_mean_hint_q8.and_then(|h| h.get(seg).copied());
        let (mut p_mean, passes) = match hint {
            _ if moment == 0 => (0, 1),
            Some(h) => (h, 1),
            None => (0, 2),
        };
        let mut p = [0i32; 3];
        for _ in 0..passes {
            let bend = moment_bending(maps, model, &prepared.moment, s_ocm, p_mean)?;
            for i in 0..3 {
                let axial = i64::from(l_target[i]) + i64::from(bend[i]);
                let eps = (axial.saturating_mul(model.inv_column_k) >> 32) - 65_536;
                p[i] = pressure_for(maps, sat(eps), forces[i], p_lo_q8, p_hi_q8)?;
            }
            p_mean = sat((i64::from(p[0]) + i64::from(p[1]) + i64::from(p[2])) / 3)
                .clamp(p_lo_q8, p_hi_q8);
        }
        for &pi in &p {
            let clamped = pi.clamp(p_lo_q8, p_hi_q8);
            out.saturated |= clamped != pi;
            out.pressures_q8.push(clamped).ok()?;
        }
    }
    Some(out)
}

/// Queries the bending map exactly as [`inverse_prepared`] would with the
/// hint `p_mean_hint_q8`, so that a memoizing `maps` (see
/// [`crate::maps::MemoBend`]) answers the next control tick from memory.
/// Does nothing without a moment.
pub fn prime_bending<M: OcmMaps>(
    maps: &M,
    model: &Model,
    prepared: &PreparedLoad,
    target: &[SegmentConfig],
    p_mean_hint_q8: &[i32],
) {
    if prepared.moment.m_q24 == 0 {
        return;
    }
    for (c, &p_mean) in target.iter().zip(p_mean_hint_q8).take(model.segments) {
        if let Some(s_ocm) = ocm_length_q24(model, c) {
            let _ = maps.bend(prepared.moment.m_q24, s_ocm, p_mean);
        }
    }
}

/// Configurations that put the tip at `p` with all segments bent alike
/// (one constant-curvature arc split evenly). `None` when `z <= 0`.
pub fn configs_for_tip(model: &Model, p_q24: [i32; 3]) -> Option<Vec<SegmentConfig, MAX_SEGMENTS>> {
    let [x, y, z] = p_q24.map(i64::from);
    if z <= 0 {
        return None;
    }
    let r = hypot(x, y);
    let chord = hypot(r, z);
    let half_total = atan2_q28(r, z);
    let total = 2 * i64::from(half_total);
    if total >= i64::from(PI_Q28) {
        return None;
    }
    let s_total = div_round(chord << 30, i64::from(sinc_q30(half_total)))?;
    let n = model.segments as i64;
    let phi = if r == 0 { 0 } else { atan2_q28(y, x) };
    let mut out = Vec::new();
    for _ in 0..model.segments {
        out.push(SegmentConfig {
            backbone_q24: sat(div_round(s_total, n)?),
            bend_q28: sat(div_round(total, n)?),
            direction_q28: phi,
        })
        .ok()?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The 64/32 reciprocal equals the 64-bit library division it
        /// replaced, and the direction is a unit vector along (M_y, -M_x).
        #[test]
        fn moment_direction_matches_the_64_bit_division(
            mx in -(20i32 << 24)..=(20 << 24),
            my in -(20i32 << 24)..=(20 << 24),
        ) {
            let load = LoadFx { fz_q16: 0, mx_q24: mx, my_q24: my };
            let mo = MomentFx::new(&load);
            prop_assert_eq!(mo.m_q24, load.moment_q24());
            if mo.m_q24 == 0 {
                prop_assert_eq!(mo, MomentFx::default());
            } else {
                let inv = div_round(1i64 << 52, i64::from(mo.m_q24)).unwrap_or(0);
                prop_assert_eq!(mo.cos_q30, sat(rshift_round(i64::from(my) * inv, 22)));
                prop_assert_eq!(mo.sin_q30, sat(rshift_round(-i64::from(mx) * inv, 22)));
                let angle = f64::atan2(-f64::from(mx), f64::from(my));
                let one = f64::from(Q30_ONE);
                prop_assert!((f64::from(mo.cos_q30) / one - angle.cos()).abs() < 1e-6);
                prop_assert!((f64::from(mo.sin_q30) / one - angle.sin()).abs() < 1e-6);
            }
        }
    }
}
