//! The sweeps: pressure stability, axial strain and bending, full solve against the
//! uniform model.

use super::super::StackError;
use super::super::solver::{Load, PlateTranslation};
use super::super::structure::{BEND_AXIS, BEND_DIRECTION, Stack, mat_vec, rotation};
use super::config::{AssumptionConfig, check_config};
use super::pressure::pressure_ramp;
use super::report::{AssumptionReport, AxialPoint, BendPoint, DeviationSummary, SweepFailure};
use crate::model::OcmModel;

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
