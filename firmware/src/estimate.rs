//! Configuration estimate from Hall column lengths and the tip IMU
//! (Ch. 3.3.7, App. B.2).
//!
//! The Hall lengths give every segment's PCC configuration through eq 3.26.
//! The IMU quaternion gives the orientation of the tip plate, whose z axis
//! under PCC is `(cos phi sin theta, sin phi sin theta, cos theta)` of the
//! total bend. The bending vectors `theta (cos phi, sin phi)` of the Hall
//! estimate are corrected towards the IMU's by a blend weight, the
//! difference spread evenly over the segments (exact when all segments bend
//! in one plane, as in the equal-split targets).

use heapless::Vec;
use ocm_shared::protocol::{MAX_SEGMENTS, SegmentConfig};

use crate::fx::{atan2_q28, div_round, hypot, rshift_round, sat};
use crate::kinematics::{BendVector, Model, config_from_vector, vector_from_lengths};

/// Tilt of the tip plate from a quaternion `(w, x, y, z)` in Q2.14: the
/// bending vector `theta (cos phi, sin phi)` in Q3.28 and the squared norm
/// of the quaternion in Q4.28.
pub fn imu_tilt(q_q14: [i16; 4]) -> ((i32, i32), i64) {
    let [w, x, y, z] = q_q14.map(i64::from);
    let norm2 = w * w + x * x + y * y + z * z; // Q28
    // Third column of the rotation matrix, Q28 (scaled by the norm).
    let zx = 2 * (x * z + w * y);
    let zy = 2 * (y * z - w * x);
    let zz = norm2 - 2 * (x * x + y * y);
    let lateral = hypot(zx, zy);
    if lateral == 0 {
        return ((0, 0), norm2);
    }
    let theta = i64::from(atan2_q28(lateral, zz));
    // One division: theta / lateral in Q30, then scale both components
    // (|zx|, |zy| <= lateral keeps the products in range).
    let ratio_q30 = div_round(theta << 30, lateral).unwrap_or(0);
    let vx = rshift_round(ratio_q30.saturating_mul(zx), 30);
    let vy = rshift_round(ratio_q30.saturating_mul(zy), 30);
    ((sat(vx), sat(vy)), norm2)
}

/// Fuses Hall lengths (three per segment, m Q8.24) with the IMU bending
/// vector. `imu_weight_q15` is the share of the IMU (0 = Hall only,
/// 32768 = IMU only). Returns the bending vectors and their polar forms.
pub fn estimate(
    model: &Model,
    lengths_q24: &[i32],
    imu: Option<(i32, i32)>,
    imu_weight_q15: i32,
) -> (
    Vec<BendVector, MAX_SEGMENTS>,
    Vec<SegmentConfig, MAX_SEGMENTS>,
) {
    let mut vecs: Vec<BendVector, MAX_SEGMENTS> = Vec::new();
    let (mut sum_x, mut sum_y) = (0i64, 0i64);
    for seg in 0..model.segments {
        let Some(l) = lengths_q24.get(3 * seg..3 * seg + 3) else {
            break;
        };
        let v = vector_from_lengths(model, [l[0], l[1], l[2]]);
        sum_x += i64::from(v.x_q28);
        sum_y += i64::from(v.y_q28);
        let _ = vecs.push(v);
    }
    if let Some((ix, iy)) = imu
        && !vecs.is_empty()
        && imu_weight_q15 > 0
    {
        let w = i64::from(imu_weight_q15.min(1 << 15));
        let n = vecs.len() as i64;
        let dx = rshift_round((i64::from(ix) - sum_x).saturating_mul(w), 15) / n;
        let dy = rshift_round((i64::from(iy) - sum_y).saturating_mul(w), 15) / n;
        for v in vecs.iter_mut() {
            v.x_q28 = sat(i64::from(v.x_q28) + dx);
            v.y_q28 = sat(i64::from(v.y_q28) + dy);
        }
    }
    let configs = vecs.iter().map(config_from_vector).collect();
    (vecs, configs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::{angle_q28_from_rad, angle_q28_to_rad};

    fn quat(theta: f64, phi: f64) -> [i16; 4] {
        // Rotation by theta about the axis (-sin phi, cos phi, 0).
        let (s, c) = ((theta / 2.0).sin(), (theta / 2.0).cos());
        [c, -s * phi.sin(), s * phi.cos(), 0.0].map(|v| (v * 16_384.0).round() as i16)
    }

    #[test]
    fn imu_tilt_recovers_bend_and_direction() {
        for (th, ph) in [(0.3, 0.0), (0.5, 1.0), (0.7, -2.0), (0.05, 3.0)] {
            let ((vx, vy), n2) = imu_tilt(quat(th, ph));
            let (vx, vy) = (angle_q28_to_rad(vx), angle_q28_to_rad(vy));
            assert!((vx.hypot(vy) - th).abs() < 3e-4, "{} vs {th}", vx.hypot(vy));
            assert!((vy.atan2(vx) - ph).abs() < 3e-3);
            assert!((n2 as f64 / 268_435_456.0 - 1.0).abs() < 1e-3);
        }
        assert_eq!(imu_tilt([16_384, 0, 0, 0]).0, (0, 0));
    }

    #[test]
    fn fusion_weights_hall_against_imu() {
        let g = ocm_shared::protocol::Geometry {
            manipulator: ocm_shared::params::ManipulatorParams::TABLE_3_1,
            ocm: ocm_shared::params::OcmParams::TABLE_3_1,
            mount: ocm_shared::protocol::Mount::Upright,
        };
        let model = Model::new(&g).unwrap();
        let target = SegmentConfig {
            backbone_q24: 2_013_266,
            bend_q28: angle_q28_from_rad(0.4),
            direction_q28: angle_q28_from_rad(0.5),
        };
        let l = crate::kinematics::lengths_from_pcc(&model, &target);
        let imu = Some((angle_q28_from_rad(0.2), 0));
        let hall_only = estimate(&model, &l, imu, 0).1;
        assert!((angle_q28_to_rad(hall_only[0].bend_q28) - 0.4).abs() < 1e-5);
        let imu_only = estimate(&model, &l, imu, 1 << 15).1;
        assert!((angle_q28_to_rad(imu_only[0].bend_q28) - 0.2).abs() < 1e-5);
        assert!(angle_q28_to_rad(imu_only[0].direction_q28).abs() < 1e-5);
        // Half way: the mean of the two bending vectors.
        let half = estimate(&model, &l, imu, 1 << 14).1;
        let (hx, hy) = (0.5 * (0.4 * 0.5f64.cos() + 0.2), 0.5 * (0.4 * 0.5f64.sin()));
        assert!((angle_q28_to_rad(half[0].bend_q28) - hx.hypot(hy)).abs() < 1e-5);
        assert_eq!(half[0].backbone_q24, hall_only[0].backbone_q24);
    }
}
