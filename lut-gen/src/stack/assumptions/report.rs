//! What the assumption sweeps report: per-point comparisons and their summaries.

use super::super::solver::PlateTranslation;

/// Where the structure stops having a stable equilibrium under pressure.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PressureStability {
    /// How the plate was held.
    pub plate: PlateTranslation,
    /// Highest pressure asked for, pascals.
    pub target_pa: f64,
    /// Highest pressure with a converged, positive-definite equilibrium, pascals.
    pub last_stable_pa: f64,
    /// Plate strain there.
    pub strain_at_last_stable: f64,
    /// Smallest eigenvalue of the Hessian there, newtons per metre.
    pub min_stiffness_at_last_stable_n_per_m: f64,
    /// Largest nodal displacement from rest there, millimetres.
    pub max_displacement_at_last_stable_mm: f64,
    /// Lowest pressure found without a stable equilibrium on the path,
    /// pascals (`None`: stable up to the target).
    pub critical_pa: Option<f64>,
    /// Why the path ended there.
    pub failure: Option<String>,
}

/// One point of the axial sweep (plate held at the strain, level).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AxialPoint {
    /// Pressure, pascals.
    pub pressure_pa: f64,
    /// Prescribed strain (plate height over `l0`, minus one).
    pub strain: f64,
    /// Axial force the full structure needs there, newtons (tension positive).
    pub force_full_n: f64,
    /// Uniform model's force `F_A(eps, P)`, newtons.
    pub force_uniform_n: f64,
    /// `force_full_n - force_uniform_n`, newtons.
    pub force_deviation_n: f64,
    /// Uniform model's strain at the full solve's force (its inverse);
    /// `None` where that force is outside the model's range.
    pub strain_uniform_at_full_force: Option<f64>,
    /// `strain - strain_uniform_at_full_force`.
    pub strain_deviation: Option<f64>,
    /// Neutral-axis length of the full solve, metres.
    pub neutral_axis_m: f64,
    /// Longest minus shortest layer height (per-layer neutral-axis arc) of
    /// the full solve, millimetres: zero when all layers deform identically.
    pub layer_height_spread_mm: f64,
    /// Whether the full equilibrium is stable.
    pub stable: bool,
}

/// One point of the bending sweep. The force-controlled fields are `None`
/// where that solve failed or was skipped (see the report's failures).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BendPoint {
    /// Initial strain `eps0`.
    pub strain0: f64,
    /// Pressure, pascals.
    pub pressure_pa: f64,
    /// Bending angle `phi`, radians.
    pub bend_angle_rad: f64,
    /// Uniform model moment `M(phi, eps0, P)`, newton-metres.
    pub moment_uniform_nm: f64,
    /// Full solve, plate on the uniform arc: generalised force `dPi/dphi`, newton-metres.
    pub moment_arc_nm: f64,
    /// `moment_arc_nm - moment_uniform_nm`.
    pub moment_arc_deviation_nm: f64,
    /// Neutral-axis arc length, plate on the uniform arc, metres.
    pub neutral_axis_arc_mode_m: f64,
    /// Largest minus smallest per-layer bending angle, plate on the uniform
    /// arc, radians (the uniform model has all equal to `phi / N`).
    pub layer_angle_spread_rad: f64,
    /// Longest minus shortest per-layer arc, plate on the uniform arc, millimetres.
    pub layer_arc_spread_mm: f64,
    /// Whether the plate-on-arc equilibrium is stable.
    pub stable_arc_mode: bool,
    /// Axial force that holds `eps0` in the straight full structure, newtons.
    pub axial_force_n: f64,
    /// Full solve under that constant axial force: moment about the plate centre, newton-metres.
    pub moment_force_nm: Option<f64>,
    /// `moment_force_nm - moment_uniform_nm`.
    pub moment_force_deviation_nm: Option<f64>,
    /// Neutral-axis arc length under constant axial force, metres.
    pub neutral_axis_m: Option<f64>,
    /// Change of the neutral-axis arc length from `phi = 0` under constant
    /// axial force, millimetres.
    pub neutral_axis_change_mm: Option<f64>,
    /// Change of the ring-centroid polyline length from `phi = 0` under
    /// constant axial force, millimetres.
    pub neutral_axis_polyline_change_mm: Option<f64>,
    /// Whether the force-controlled equilibrium is stable.
    pub stable_force_mode: Option<bool>,
}

/// A sweep point where the full solve found no equilibrium.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SweepFailure {
    /// Which sweep and point.
    pub point: String,
    /// The solver's error.
    pub reason: String,
}

/// Absolute and full-scale-relative deviations over a sweep.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DeviationSummary {
    /// Number of points.
    pub count: usize,
    /// Largest absolute deviation.
    pub max_abs: f64,
    /// Mean absolute deviation.
    pub mean_abs: f64,
    /// Largest absolute deviation over the largest absolute reference value.
    pub max_rel_fs: f64,
    /// Mean absolute deviation over the largest absolute reference value.
    pub mean_rel_fs: f64,
}

impl DeviationSummary {
    /// Summarises `(deviation, reference)` pairs.
    pub fn of(pairs: impl IntoIterator<Item = (f64, f64)>) -> Self {
        let (mut count, mut max_abs, mut sum, mut fs) = (0usize, 0.0f64, 0.0, 0.0f64);
        for (dev, reference) in pairs {
            count += 1;
            max_abs = max_abs.max(dev.abs());
            sum += dev.abs();
            fs = fs.max(reference.abs());
        }
        let mean_abs = if count > 0 { sum / count as f64 } else { 0.0 };
        let rel = |v: f64| if fs > 0.0 { v / fs } else { 0.0 };
        Self {
            count,
            max_abs,
            mean_abs,
            max_rel_fs: rel(max_abs),
            mean_rel_fs: rel(mean_abs),
        }
    }
}

/// The measured deviations of the uniform model from the full solve.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AssumptionReport {
    /// Number of layers `N`.
    pub layers: usize,
    /// Pressure stability with the plate free and unloaded.
    pub pressure_stability_free: PressureStability,
    /// Pressure stability with the plate held at `l0`.
    pub pressure_stability_held: PressureStability,
    /// Axial sweep points.
    pub axial: Vec<AxialPoint>,
    /// Bending sweep points.
    pub bending: Vec<BendPoint>,
    /// Points where no equilibrium was found (or the pressure was beyond
    /// the stability limit).
    pub failures: Vec<SweepFailure>,
    /// Strain deviation at equal force (reference: the uniform model's strain).
    pub strain_deviation: DeviationSummary,
    /// Force deviation at equal strain, newtons (reference: the uniform model's force).
    pub force_deviation_n: DeviationSummary,
    /// Moment deviation, plate on the uniform arc, newton-metres.
    pub moment_arc_deviation_nm: DeviationSummary,
    /// Moment deviation under constant axial force, newton-metres.
    pub moment_force_deviation_nm: DeviationSummary,
    /// Largest change of the neutral-axis arc length from its `phi = 0`
    /// value under constant axial force, millimetres (dissertation: 0.183 mm).
    pub neutral_axis_max_deviation_mm: f64,
    /// The same for the ring-centroid polyline, millimetres.
    pub neutral_axis_polyline_max_deviation_mm: f64,
    /// Largest layer-height spread of the axial sweep, millimetres.
    pub max_layer_height_spread_mm: f64,
    /// Largest per-layer bending-angle spread of the plate-on-arc sweep, radians.
    pub max_layer_angle_spread_rad: f64,
    /// Largest difference between the neutral-axis arc length of the
    /// plate-on-arc solve and the plate's arc `l0 (1 + eps0)`, millimetres.
    pub neutral_axis_arc_mode_max_deviation_mm: f64,
    /// Largest change of the ring-centroid polyline of the uniform kinematic
    /// map itself over the same angles, millimetres (the chord shortening of
    /// rigid-ring bending, for scale).
    pub uniform_polyline_max_deviation_mm: f64,
}
