//! Quasi-static model of one manipulator segment (dissertation Ch. 3.3.5): three OCM columns
//! at 120 degrees on radius `d`, each a stack of OCMs sharing one pressure. Each column's
//! strain solves `F_A(eps, P_i) = f_i` (eq 3.33) for its share of the axial load (eq 3.29
//! with no external moment), the column lengths give the configuration `(S_c, theta_c,
//! phi_c)` (eq 3.26) and the piecewise-constant-curvature arc gives the tip position.
//! This is the host's float version; the firmware carries its own fixed-point one.

use ocm_shared::params::ManipulatorParams;

use crate::physics::Physics;

/// Configuration of a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Configuration {
    /// Backbone length `S_c`, metres.
    pub backbone_m: f64,
    /// Bending angle `theta_c`, radians.
    pub bend_rad: f64,
    /// Direction of the bending axis `phi_c`, radians.
    pub direction_rad: f64,
}

/// A quasi-static segment model with a stiffness scale on both `k_b` and `k_h`.
#[derive(Debug, Clone, Copy)]
pub struct Segment<'a> {
    /// The OCM physics tables.
    pub physics: &'a Physics,
    /// Manipulator geometry.
    pub geometry: ManipulatorParams,
    /// Relative stiffness (1 = Table 3.1).
    pub stiffness_scale: f64,
}

impl<'a> Segment<'a> {
    /// The Table 3.1 segment.
    pub fn new(physics: &'a Physics, stiffness_scale: f64) -> Self {
        Self {
            physics,
            geometry: ManipulatorParams::TABLE_3_1,
            stiffness_scale,
        }
    }

    /// Strain of one OCM carrying tension `force_n` at `pressure_pa` (eq 3.33), from the
    /// inverse axial table; saturates at the table ends.
    pub fn column_strain(&self, force_n: f64, pressure_pa: f64) -> f64 {
        self.physics
            .axial_strain(force_n, pressure_pa, self.stiffness_scale)
    }

    /// Configuration from the three column strains (eq 3.26 with `l_i = n l0 (1 + eps_i)`).
    pub fn configuration(&self, strains: [f64; 3]) -> Configuration {
        let n = self.geometry.ocms_per_column as f64;
        let l0 = self.physics.params.rest_length_m;
        let l = strains.map(|e| n * l0 * (1.0 + e));
        let d = self.geometry.column_radius_m;
        let s = (l[0] + l[1] + l[2]) / 3.0;
        let q = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2] - l[0] * l[1] - l[1] * l[2] - l[0] * l[2])
            .max(0.0);
        let theta = 2.0 * q.sqrt() / (3.0 * d);
        let phi = (l[2] + l[1] - 2.0 * l[0]).atan2(3f64.sqrt() * (l[1] - l[2]));
        Configuration {
            backbone_m: s,
            bend_rad: theta,
            direction_rad: phi,
        }
    }

    /// Tip position of the constant-curvature arc, metres, z along the unbent backbone.
    pub fn tip(&self, c: Configuration) -> [f64; 3] {
        let (s, th, ph) = (c.backbone_m, c.bend_rad, c.direction_rad);
        let (radial, z) = if th.abs() < 1e-9 {
            (0.5 * s * th, s)
        } else {
            (s / th * (1.0 - th.cos()), s / th * th.sin())
        };
        [radial * ph.cos(), radial * ph.sin(), z]
    }

    /// Tip position for pressures (Pa) and total axial tension on the segment (N).
    pub fn tip_for(&self, pressures_pa: [f64; 3], load_n: f64) -> [f64; 3] {
        let share = load_n / 3.0;
        let strains = pressures_pa.map(|p| self.column_strain(share, p));
        self.tip(self.configuration(strains))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_pressures_extend_straight_and_strain_solves_the_force_law() {
        let p = Physics::table_3_1();
        let seg = Segment::new(p, 1.0);
        let e = seg.column_strain(0.3, 2000.0);
        assert!((p.axial_force(e, 2000.0, 1.0, 1.0) - 0.3).abs() < 1e-4);
        let tip = seg.tip_for([3000.0; 3], 0.0);
        let e = seg.column_strain(0.0, 3000.0);
        assert!(tip[0].abs() < 1e-12 && tip[1].abs() < 1e-12);
        assert!((tip[2] - 3.0 * 0.04 * (1.0 + e)).abs() < 1e-12);
        // stiffer columns extend less under the same pressure
        let stiff = Segment::new(p, 1.5).tip_for([3000.0; 3], 0.0);
        assert!(stiff[2] < tip[2]);
    }

    #[test]
    fn arc_tip_matches_geometry_and_bends_away_from_the_longest_column() {
        let p = Physics::table_3_1();
        let seg = Segment::new(p, 1.0);
        // column 1 longest: phi = atan2(-, 0) = -90 deg, the tip moves along -y
        let c = seg.configuration([0.3, 0.0, 0.0]);
        let tip = seg.tip(c);
        // arc length check: chord relations of a circle of radius S/theta
        let r = c.backbone_m / c.bend_rad;
        let radial = (tip[0].powi(2) + tip[1].powi(2)).sqrt();
        assert!(((r - radial).powi(2) + tip[2].powi(2) - r * r).abs() < 1e-12);
        // eq 3.26: theta = 2 sqrt(...) / 3d with l2 = l3 gives 2 (l1 - l2) / 3d
        let l = 0.12 * 0.3;
        assert!((c.bend_rad - 2.0 * l / (3.0 * 0.06)).abs() < 1e-12);
        assert!(tip[0].abs() < 1e-12 && tip[1] < 0.0);
    }
}
