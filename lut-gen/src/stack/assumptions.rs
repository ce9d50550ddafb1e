//! Sweeps that compare the full N-layer solve with the uniform model.
//!
//! Pressure: the pressure is ramped with the plate free (no force) and with
//! the plate held at `l0`, and the first pressure without a stable
//! equilibrium (no convergence, divergence or an indefinite Hessian) is
//! located by bisection.
//!
//! Axial: at each pressure the level plate is held at strain `eps`
//! (displacement control passes the limit points that force control cannot),
//! walking outward from `eps = 0`. The plate reaction `F` is the full
//! structure's force; `F - F_A(eps, P)` is the force error at equal strain
//! and `eps - F_A^-1(F, P)` the strain error at equal force.
//!
//! Bending: at each initial strain `eps0` the straight stack is first held
//! at `l0 (1 + eps0)` (plate centre prescribed), which gives the axial force
//! `F0` that sets that strain in the full structure. Then the plate is
//! rotated by `phi` two ways:
//! - on the uniform model's arc: the plate centre prescribed where the
//!   uniform map puts it, so the generalised force `dPi/dphi` along that
//!   path is the same quantity as the model's `M(phi, eps0)`;
//! - under the constant axial force `F0` along the plate normal with the
//!   plate centre free, so the neutral-axis length is free to change: the
//!   test of the claim that it does not depend on the bending angle.

use super::StackError;
use super::solver::{Equilibrium, Load, PlateTranslation, SolverConfig};
use super::structure::{BEND_AXIS, BEND_DIRECTION, Stack, mat_vec, rotation};
use crate::model::OcmModel;

/// What [`measure_assumptions`] sweeps.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AssumptionConfig {
    /// Pressures of the axial sweep, pascals; the highest is also the
    /// target of the stability ramps.
    pub pressures_pa: Vec<f64>,
    /// Further axial-sweep pressures as fractions of the measured stability
    /// limit of the structure held at `l0` (see [`PressureStability`]).
    pub stable_pressure_fractions: Vec<f64>,
    /// Strains at which the plate is held in the axial sweep.
    pub axial_strains: Vec<f64>,
    /// Initial strains of the bending sweep.
    pub bend_strains: Vec<f64>,
    /// Pressure of the bending sweep, pascals.
    pub bend_pressure_pa: f64,
    /// Largest bending angle as a fraction of the feasible `phi_max(eps0)`.
    pub bend_fraction: f64,
    /// Bending angles per initial strain (evenly spaced, zero excluded).
    pub bend_points: usize,
    /// Load increments between consecutive sweep points.
    pub load_steps: usize,
    /// Largest number of pressure increments of the stability ramp up to the
    /// highest of `pressures_pa` (smaller steps are taken where needed).
    pub pressure_ramp_steps: usize,
    /// Resolution of the critical pressure search, pascals.
    pub pressure_resolution_pa: f64,
    /// Newton settings.
    pub solver: SolverConfig,
}

impl Default for AssumptionConfig {
    fn default() -> Self {
        Self {
            pressures_pa: vec![0.0, 10e3, 20e3, 30e3],
            stable_pressure_fractions: vec![0.5, 0.9],
            axial_strains: vec![-0.4, -0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4],
            bend_strains: vec![-0.3, 0.0, 0.3],
            bend_pressure_pa: 0.0,
            bend_fraction: 0.9,
            bend_points: 6,
            load_steps: 4,
            pressure_ramp_steps: 30,
            pressure_resolution_pa: 1.0,
            solver: SolverConfig::default(),
        }
    }
}

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

/// Runs the pressure, axial and bending sweeps of `cfg` on the stack of
/// `model` and compares them with the uniform model. Points where the full
/// structure has no equilibrium are listed in the report's `failures`
/// rather than failing the whole run. The default configuration on the
/// Table 3.1 OCM takes about a minute in a release build.
pub fn measure_assumptions(
    model: &OcmModel,
    cfg: &AssumptionConfig,
) -> Result<AssumptionReport, StackError> {
    check_config(model, cfg)?;
    let stack = Stack::new(model);
    let l0 = stack.rest_length_m();
    let rest = stack.rest_equilibrium();
    let mut failures = Vec::new();

    let target = cfg.pressures_pa.iter().copied().fold(0.0, f64::max);
    let free_plate = PlateTranslation::Free { force_n: [0.0; 3] };
    let held_plate = PlateTranslation::Fixed {
        centre_m: stack.rest_plate_centre_m(),
    };
    let (free_stability, _) = pressure_ramp(&stack, &rest, free_plate, target, cfg);
    let (held_stability, ramp) = pressure_ramp(&stack, &rest, held_plate, target, cfg);

    let mut pressures: Vec<f64> = cfg.pressures_pa.clone();
    pressures.extend(
        cfg.stable_pressure_fractions
            .iter()
            .map(|f| f * held_stability.last_stable_pa),
    );
    pressures.sort_by(f64::total_cmp);
    pressures.dedup();

    let (lo, hi) = model.strain_limits();
    let inverse_range = (lo + 1e-3, hi - 1e-3);
    let mut axial = Vec::new();
    for &p in &pressures {
        if p > held_stability.last_stable_pa {
            failures.push(SweepFailure {
                point: format!("axial sweep at P = {p:.1} Pa"),
                reason: format!(
                    "beyond the pressure stability limit ({:.1} Pa) of the structure held at l0",
                    held_stability.last_stable_pa
                ),
            });
            continue;
        }
        // The pressurised state at l0, continued from the ramp's nearest
        // lower state.
        let below = ramp
            .iter()
            .rev()
            .find(|e| e.load.pressure_pa <= p)
            .unwrap_or(&rest);
        let at_l0 = Load {
            pressure_pa: p,
            bend_angle_rad: 0.0,
            translation: held_plate,
        };
        let base = match stack.continue_to(below, &at_l0, cfg.load_steps, &cfg.solver) {
            Ok(e) => e,
            Err(e) => {
                failures.push(SweepFailure {
                    point: format!("axial sweep at P = {p:.1} Pa, strain 0"),
                    reason: e.to_string(),
                });
                continue;
            }
        };
        // Walk outward from l0 in both directions so that every point is
        // reached along a continuous path.
        let mut upward: Vec<f64> = cfg
            .axial_strains
            .iter()
            .copied()
            .filter(|&e| e >= 0.0)
            .collect();
        let mut downward: Vec<f64> = cfg
            .axial_strains
            .iter()
            .copied()
            .filter(|&e| e < 0.0)
            .collect();
        upward.sort_by(f64::total_cmp);
        downward.sort_by(|a, b| b.total_cmp(a));
        for branch in [upward, downward] {
            let mut from = base.clone();
            for eps in branch {
                let load = Load {
                    translation: PlateTranslation::Fixed {
                        centre_m: stack.uniform_plate_centre_m(eps, 0.0),
                    },
                    ..at_l0
                };
                let eq = match stack.continue_to(&from, &load, cfg.load_steps, &cfg.solver) {
                    Ok(eq) => eq,
                    Err(e) => {
                        failures.push(SweepFailure {
                            point: format!("axial sweep at P = {p:.1} Pa, strain {eps}"),
                            reason: e.to_string(),
                        });
                        break;
                    }
                };
                let force = eq.plate_force_n[2];
                let f_u = model.axial_force_n(eps, p);
                let strain_uniform = model.strain_for_force(force, p, inverse_range).ok();
                let axis = stack.neutral_axis(&eq.positions);
                axial.push(AxialPoint {
                    pressure_pa: p,
                    strain: eps,
                    force_full_n: force,
                    force_uniform_n: f_u,
                    force_deviation_n: force - f_u,
                    strain_uniform_at_full_force: strain_uniform,
                    strain_deviation: strain_uniform.map(|e| eps - e),
                    neutral_axis_m: axis.arc_m,
                    layer_height_spread_mm: (axis.layer_arc_max_m - axis.layer_arc_min_m) * 1e3,
                    stable: eq.stable,
                });
                from = eq;
            }
        }
    }
    axial.sort_by(|a, b| {
        a.pressure_pa
            .total_cmp(&b.pressure_pa)
            .then(a.strain.total_cmp(&b.strain))
    });

    let mut bending = Vec::new();
    let mut uniform_polyline_dev: f64 = 0.0;
    for &eps0 in &cfg.bend_strains {
        let phi_max = cfg.bend_fraction * model.max_bend_angle_rad(eps0);
        let p = cfg.bend_pressure_pa;
        let straight_load = Load {
            pressure_pa: p,
            bend_angle_rad: 0.0,
            translation: PlateTranslation::Fixed {
                centre_m: stack.uniform_plate_centre_m(eps0, 0.0),
            },
        };
        let straight = match stack.continue_to(&rest, &straight_load, cfg.load_steps, &cfg.solver) {
            Ok(e) => e,
            Err(e) => {
                failures.push(SweepFailure {
                    point: format!("bending sweep, straight state at eps0 = {eps0}"),
                    reason: e.to_string(),
                });
                continue;
            }
        };
        let axis0 = stack.neutral_axis(&straight.positions);
        let uniform0 = stack
            .neutral_axis(&stack.uniform_positions(eps0, 0.0))
            .polyline_m;
        let f0 = straight.plate_force_n[2];
        // Under a dead axial force the plate may also translate sideways; a
        // compressed column can buckle that way before any bending.
        let mut force_from = if stack
            .assemble(&straight.positions, p, true)
            .hessian_n_per_m
            .cholesky()
            .is_some()
        {
            Some(straight.clone())
        } else {
            failures.push(SweepFailure {
                point: format!("force-controlled bending at eps0 = {eps0}"),
                reason: format!(
                    "the straight stack under a dead axial force of {f0:.4e} N with the plate \
                     free to translate is unstable (it sways): skipped"
                ),
            });
            None
        };
        let mut arc_from = straight.clone();
        for j in 1..=cfg.bend_points {
            let phi = phi_max * j as f64 / cfg.bend_points as f64;
            let arc_load = Load {
                pressure_pa: p,
                bend_angle_rad: phi,
                translation: PlateTranslation::Fixed {
                    centre_m: stack.uniform_plate_centre_m(eps0, phi),
                },
            };
            let arc = match stack.continue_to(&arc_from, &arc_load, cfg.load_steps, &cfg.solver) {
                Ok(a) => a,
                Err(e) => {
                    failures.push(SweepFailure {
                        point: format!(
                            "bending on the uniform arc at eps0 = {eps0}, phi = {phi:.4} rad"
                        ),
                        reason: e.to_string(),
                    });
                    break;
                }
            };
            let forced = force_from.take().and_then(|from| {
                let normal = mat_vec(&rotation(BEND_AXIS, phi), [0.0, 0.0, 1.0]);
                let load = Load {
                    pressure_pa: p,
                    bend_angle_rad: phi,
                    translation: PlateTranslation::Free {
                        force_n: normal.map(|v| v * f0),
                    },
                };
                match stack.continue_to(&from, &load, cfg.load_steps, &cfg.solver) {
                    Ok(f) => Some(f),
                    Err(e) => {
                        failures.push(SweepFailure {
                            point: format!(
                                "force-controlled bending at eps0 = {eps0}, phi = {phi:.4} rad"
                            ),
                            reason: e.to_string(),
                        });
                        None
                    }
                }
            });
            let m_u = model.bending_moment_nm(phi, eps0, p);
            let m_arc = Stack::generalised_moment_nm(&arc, arc_tangent(l0 * (1.0 + eps0), phi));
            let uniform = stack
                .neutral_axis(&stack.uniform_positions(eps0, phi))
                .polyline_m;
            uniform_polyline_dev = uniform_polyline_dev.max((uniform - uniform0).abs());
            let axis = forced.as_ref().map(|f| stack.neutral_axis(&f.positions));
            let arc_axis = stack.neutral_axis(&arc.positions);
            bending.push(BendPoint {
                strain0: eps0,
                pressure_pa: p,
                bend_angle_rad: phi,
                moment_uniform_nm: m_u,
                moment_arc_nm: m_arc,
                moment_arc_deviation_nm: m_arc - m_u,
                neutral_axis_arc_mode_m: arc_axis.arc_m,
                layer_angle_spread_rad: arc_axis.layer_turn_max_rad - arc_axis.layer_turn_min_rad,
                layer_arc_spread_mm: (arc_axis.layer_arc_max_m - arc_axis.layer_arc_min_m) * 1e3,
                stable_arc_mode: arc.stable,
                axial_force_n: f0,
                moment_force_nm: forced.as_ref().map(|f| f.plate_moment_nm),
                moment_force_deviation_nm: forced.as_ref().map(|f| f.plate_moment_nm - m_u),
                neutral_axis_m: axis.map(|a| a.arc_m),
                neutral_axis_change_mm: axis.map(|a| (a.arc_m - axis0.arc_m) * 1e3),
                neutral_axis_polyline_change_mm: axis
                    .map(|a| (a.polyline_m - axis0.polyline_m) * 1e3),
                stable_force_mode: forced.as_ref().map(|f| f.stable),
            });
            arc_from = arc;
            force_from = forced;
        }
    }

    Ok(AssumptionReport {
        layers: stack.layers(),
        pressure_stability_free: free_stability,
        pressure_stability_held: held_stability,
        strain_deviation: DeviationSummary::of(
            axial
                .iter()
                .filter_map(|a| a.strain_uniform_at_full_force.map(|u| (a.strain - u, u))),
        ),
        force_deviation_n: DeviationSummary::of(
            axial
                .iter()
                .map(|a| (a.force_deviation_n, a.force_uniform_n)),
        ),
        moment_arc_deviation_nm: DeviationSummary::of(
            bending
                .iter()
                .map(|b| (b.moment_arc_deviation_nm, b.moment_uniform_nm)),
        ),
        moment_force_deviation_nm: DeviationSummary::of(
            bending
                .iter()
                .filter_map(|b| Some((b.moment_force_deviation_nm?, b.moment_uniform_nm))),
        ),
        neutral_axis_max_deviation_mm: bending
            .iter()
            .filter_map(|b| b.neutral_axis_change_mm)
            .fold(0.0, |m, v| m.max(v.abs())),
        neutral_axis_polyline_max_deviation_mm: bending
            .iter()
            .filter_map(|b| b.neutral_axis_polyline_change_mm)
            .fold(0.0, |m, v| m.max(v.abs())),
        max_layer_height_spread_mm: axial
            .iter()
            .map(|a| a.layer_height_spread_mm)
            .fold(0.0, f64::max),
        max_layer_angle_spread_rad: bending
            .iter()
            .map(|b| b.layer_angle_spread_rad)
            .fold(0.0, f64::max),
        neutral_axis_arc_mode_max_deviation_mm: bending
            .iter()
            .map(|b| (b.neutral_axis_arc_mode_m - l0 * (1.0 + b.strain0)).abs() * 1e3)
            .fold(0.0, f64::max),
        uniform_polyline_max_deviation_mm: uniform_polyline_dev * 1e3,
        axial,
        bending,
        failures,
    })
}

/// `dc/dphi` of the uniform plate path `c = s (versin(phi)/phi b + sinc(phi) z)`.
fn arc_tangent(s: f64, phi: f64) -> [f64; 3] {
    // Closed-form derivatives of (1 - cos phi)/phi and sin(phi)/phi lose
    // digits near zero, where their Taylor series take over.
    let (dv, dz) = if phi.abs() < 1e-3 {
        (0.5 - phi * phi / 8.0, -phi / 3.0)
    } else {
        let (s_, c_) = phi.sin_cos();
        (
            s_ / phi - (1.0 - c_) / (phi * phi),
            c_ / phi - s_ / (phi * phi),
        )
    };
    [
        BEND_DIRECTION[0] * s * dv,
        BEND_DIRECTION[1] * s * dv,
        s * dz,
    ]
}

fn check_config(model: &OcmModel, cfg: &AssumptionConfig) -> Result<(), StackError> {
    let bad = |what: &'static str, reason: String| Err(StackError::InvalidInput { what, reason });
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !finite(&cfg.pressures_pa) || cfg.pressures_pa.iter().any(|&p| p < 0.0) {
        return bad(
            "pressures_pa",
            format!(
                "must be finite and non-negative, got {:?}",
                cfg.pressures_pa
            ),
        );
    }
    let (lo, hi) = model.strain_limits();
    let in_range = |v: &[f64]| v.iter().all(|&e| e.is_finite() && e > lo && e < hi);
    if !in_range(&cfg.axial_strains) {
        return bad(
            "axial_strains",
            format!("must lie in ({lo}, {hi}), got {:?}", cfg.axial_strains),
        );
    }
    if !in_range(&cfg.bend_strains) {
        return bad(
            "bend_strains",
            format!("must lie in ({lo}, {hi}), got {:?}", cfg.bend_strains),
        );
    }
    if cfg
        .stable_pressure_fractions
        .iter()
        .any(|f| !(f.is_finite() && (0.0..=1.0).contains(f)))
    {
        return bad(
            "stable_pressure_fractions",
            format!(
                "must lie in [0, 1], got {:?}",
                cfg.stable_pressure_fractions
            ),
        );
    }
    if !(cfg.bend_pressure_pa.is_finite() && cfg.bend_pressure_pa >= 0.0) {
        return bad(
            "bend_pressure_pa",
            format!(
                "must be finite and non-negative, got {}",
                cfg.bend_pressure_pa
            ),
        );
    }
    if !(cfg.bend_fraction > 0.0 && cfg.bend_fraction < 1.0) {
        return bad(
            "bend_fraction",
            format!("must lie in (0, 1), got {}", cfg.bend_fraction),
        );
    }
    if cfg.bend_points == 0 || cfg.load_steps == 0 || cfg.pressure_ramp_steps == 0 {
        return bad(
            "bend_points/load_steps/pressure_ramp_steps",
            "must be at least 1".to_string(),
        );
    }
    if cfg.pressure_resolution_pa.is_nan() || cfg.pressure_resolution_pa <= 0.0 {
        return bad(
            "pressure_resolution_pa",
            format!("must be positive, got {}", cfg.pressure_resolution_pa),
        );
    }
    Ok(())
}

/// Ramps the pressure with the plate held as `plate` says, and bisects the
/// first failure (no convergence, divergence or loss of positive
/// definiteness) down to `cfg.pressure_resolution_pa`. Returns the summary
/// and the stable states met on the way.
fn pressure_ramp(
    stack: &Stack,
    rest: &Equilibrium,
    plate: PlateTranslation,
    target_pa: f64,
    cfg: &AssumptionConfig,
) -> (PressureStability, Vec<Equilibrium>) {
    let at = |p: f64| Load {
        pressure_pa: p,
        bend_angle_rad: 0.0,
        translation: plate,
    };
    let mut states = vec![rest.clone()];
    let mut failure = None;
    let mut critical = None;
    let max_step = target_pa / cfg.pressure_ramp_steps as f64;
    let mut dp = max_step;
    let mut p = 0.0;
    while p < target_pa {
        let next = (p + dp).min(target_pa);
        let n = states.len();
        let current = &states[n - 1];
        let secant = (n >= 2).then(|| {
            let prev = &states[n - 2];
            (prev, (next - p) / (p - prev.load.pressure_pa))
        });
        let outcome = match stack.step(current, secant, &at(next), &cfg.solver) {
            Ok(e) if e.stable => Ok(e),
            Ok(_) => Err(format!(
                "the equilibrium at {next:.1} Pa is not positive definite (unstable)"
            )),
            Err(e) => Err(e.to_string()),
        };
        match outcome {
            Ok(e) => {
                states.push(e);
                p = next;
                dp = (dp * 1.5).min(max_step);
            }
            Err(why) => {
                if dp <= cfg.pressure_resolution_pa {
                    critical = Some(next);
                    failure = Some(why);
                    break;
                }
                dp *= 0.5;
            }
        }
    }
    let last = states.last().unwrap_or(rest);
    let max_disp = last
        .positions
        .iter()
        .zip(stack.rest_positions())
        .map(|(a, b)| {
            let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        })
        .fold(0.0, f64::max);
    let summary = PressureStability {
        plate,
        target_pa,
        last_stable_pa: last.load.pressure_pa,
        strain_at_last_stable: last.plate_centre_m[2] / stack.rest_length_m() - 1.0,
        min_stiffness_at_last_stable_n_per_m: stack.min_stiffness_n_per_m(last),
        max_displacement_at_last_stable_mm: max_disp * 1e3,
        critical_pa: critical,
        failure,
    };
    (summary, states)
}
