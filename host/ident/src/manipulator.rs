//! Quasi-static model of one manipulator segment (dissertation Ch. 3.3.5): three OCM columns
//! at 120 degrees on radius `d`, each a stack of OCMs sharing one pressure. Each column's
//! strain solves `F_A(eps, P_i) = f_i` (eq 3.33) for its share of the axial load (eq 3.29
//! with no external moment), the column lengths give the configuration `(S_c, theta_c,
//! phi_c)` (eq 3.26) and the piecewise-constant-curvature arc gives the tip position.
//! This is the host's float version; the firmware carries its own fixed-point one.

use ocm_lutgen::pcc::Config;
use ocm_shared::params::ManipulatorParams;

use crate::physics::Physics;

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

    /// Configuration from the three column strains (eq 3.26 with `l_i = n l0 (1 + eps_i)`),
    /// in the lab's frame: column 1 at +x, `phi` from column 1 towards column 2.
    pub fn configuration(&self, strains: [f64; 3]) -> Config {
        let n = self.geometry.ocms_per_column as f64;
        let l0 = self.physics.params.rest_length_m;
        let l = strains.map(|e| n * l0 * (1.0 + e));
        Config::from_column_lengths(l, self.geometry.column_radius_m)
    }

    /// Tip position of the constant-curvature arc, metres, z along the unbent backbone.
    pub fn tip(&self, c: Config) -> [f64; 3] {
        c.position()
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
    fn arc_tip_matches_geometry_and_bends_away_from_the_longest_column_in_the_lab_frame() {
        let p = Physics::table_3_1();
        let seg = Segment::new(p, 1.0);
        // Column 1 sits at +x: when it is the longest, the segment bends towards -x.
        let c = seg.configuration([0.3, 0.0, 0.0]);
        let tip = seg.tip(c);
        assert!(tip[0] < -1e-3 && tip[1].abs() < 1e-12, "{tip:?}");
        // arc length check: chord relations of a circle of radius S/theta
        let r = c.backbone_m / c.bend_rad();
        let radial = (tip[0].powi(2) + tip[1].powi(2)).sqrt();
        assert!(((r - radial).powi(2) + tip[2].powi(2) - r * r).abs() < 1e-12);
        // eq 3.26: theta = 2 sqrt(...) / 3d with l2 = l3 gives 2 (l1 - l2) / 3d
        let l = 0.12 * 0.3;
        assert!((c.bend_rad() - 2.0 * l / (3.0 * 0.06)).abs() < 1e-12);
        // Column 2 (at +120 deg) longest: the tip moves away from it, to 120 - 180 = -60 deg.
        let tip2 = seg.tip(seg.configuration([0.0, 0.3, 0.0]));
        let dir = tip2[1].atan2(tip2[0]).to_degrees();
        assert!((dir - (-60.0)).abs() < 1e-9, "{dir}");
    }
}
