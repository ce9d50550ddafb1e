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
}
