//! The pressure ramp and the bisection of the first unstable pressure.

use super::super::solver::{Equilibrium, Load, PlateTranslation};
use super::super::structure::Stack;
use super::config::AssumptionConfig;
use super::report::PressureStability;

/// Ramps the pressure with the plate held as `plate` says, and bisects the
/// first failure (no convergence, divergence or loss of positive
/// definiteness) down to `cfg.pressure_resolution_pa`. Returns the summary
/// and the stable states met on the way.
pub(super) fn pressure_ramp(
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
