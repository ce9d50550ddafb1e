//! The rewards of eq 4.29-4.30.
//!
//! delta_q is the TCP distance to the step's target point in metres, so R_q halves at 10 mm and
//! is 0.91 at 1 mm; delta_F is the Euclidean norm of the force error in newtons (the norm-2
//! error of Fig 4.25-B), and R_F is not clipped (it falls below zero past 2 N of error).

/// R_q = 1 / (1 + 100 delta_q), delta_q in m.
pub fn position_reward(delta_q_m: f64) -> f64 {
    1.0 / (1.0 + 100.0 * delta_q_m)
}

/// R_F = 1 - 0.5 delta_F, delta_F in N.
pub fn force_reward(delta_f_n: f64) -> f64 {
    1.0 - 0.5 * delta_f_n
}

/// The force error that R_F scores with the approach term (`EnvConfig::approach_n_per_m`):
/// out of contact (gap > 0 along the outward unit normal `n`), the measured force, which is
/// zero there, is replaced by the penalty law continued across the surface with the softer
/// stiffness `k_approach`, a pull of k_approach * gap along -n; in contact (gap <= 0) it is the
/// measured force. The error is continuous at the surface and grows with the distance to it,
/// so eq 4.30 gets a gradient towards the surface where it is otherwise flat.
pub fn approach_force_error(
    force_target_n: &[f64; 3],
    force_n: &[f64; 3],
    normal: &[f64; 3],
    gap_m: f64,
    k_approach_n_per_m: f64,
) -> f64 {
    let pull = if gap_m > 0.0 {
        k_approach_n_per_m * gap_m
    } else {
        0.0
    };
    (0..3)
        .map(|i| (force_target_n[i] - (force_n[i] - pull * normal[i])).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// R = alpha R_q + (1 - alpha) R_F (eq 4.29).
pub fn combined_reward(alpha: f64, delta_q_m: f64, delta_f_n: f64) -> f64 {
    alpha * position_reward(delta_q_m) + (1.0 - alpha) * force_reward(delta_f_n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rewards_on_hand_computed_cases() {
        assert_eq!(position_reward(0.0), 1.0);
        assert!((position_reward(0.01) - 0.5).abs() < 1e-15);
        assert!((position_reward(0.001) - 1.0 / 1.1).abs() < 1e-15);
        assert!((position_reward(0.03) - 0.25).abs() < 1e-15);
        assert_eq!(force_reward(0.0), 1.0);
        assert!((force_reward(0.55) - 0.725).abs() < 1e-15);
        assert!((force_reward(2.0)).abs() < 1e-15);
        assert!((force_reward(3.0) + 0.5).abs() < 1e-15);
        // alpha = 0.5, 10 mm and 1 N: 0.5 * 0.5 + 0.5 * 0.5.
        assert!((combined_reward(0.5, 0.01, 1.0) - 0.5).abs() < 1e-15);
        // alpha = 0.3, 1 mm and 0.2 N: 0.3 / 1.1 + 0.7 * 0.9.
        assert!((combined_reward(0.3, 0.001, 0.2) - (0.3 / 1.1 + 0.63)).abs() < 1e-15);
        assert_eq!(combined_reward(1.0, 0.01, 100.0), 0.5);
        assert_eq!(combined_reward(0.0, 100.0, 1.0), 0.5);
    }

    #[test]
    fn approach_term_on_hand_computed_cases() {
        // Plate normal -z (towards the robot below it), target 1.5 N pushing the TCP down.
        let (n, ft) = ([0.0, 0.0, -1.0], [0.0, 0.0, -1.5]);
        // 5 mm below the plate at 100 N/m: a virtual pull of 0.5 N up, error 1.5 + 0.5.
        let e = approach_force_error(&ft, &[0.0; 3], &n, 0.005, 100.0);
        assert!((e - 2.0).abs() < 1e-12);
        // Touching: the plain error |F_ref|; continuous at the surface.
        assert_eq!(approach_force_error(&ft, &[0.0; 3], &n, 0.0, 100.0), 1.5);
        assert!((approach_force_error(&ft, &[0.0; 3], &n, 1e-9, 100.0) - 1.5).abs() < 1e-6);
        // In contact the measured force is scored as eq 4.30 has it: 1.2 N measured, 0.3 N off.
        let e = approach_force_error(&ft, &[0.0, 0.0, -1.2], &n, -0.0002, 100.0);
        assert!((e - 0.3).abs() < 1e-12);
        // k = 0 is the plain error; with a sideways target the pull (0, 0, 1) adds in quadrature.
        assert_eq!(approach_force_error(&ft, &[0.0; 3], &n, 0.01, 0.0), 1.5);
        let e = approach_force_error(&[1.0, 0.0, 0.0], &[0.0; 3], &n, 0.01, 100.0);
        assert!((e - 2f64.sqrt()).abs() < 1e-12);
    }
}
