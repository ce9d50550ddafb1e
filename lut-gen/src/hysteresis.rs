//! Bouc-Wen hysteresis (n = 1), the one implementation used by the virtual lab's columns and
//! by `ocm ident`'s generators: a normalised state `z` in `[-1, 1]` driven by increments of
//! a normalised input `dx` (input over the travel that saturates the loop),
//!
//! `dz = dx (1 - (beta sgn(dx z) + gamma) |z|)`,
//!
//! with `beta + gamma = 1` so that `z` saturates at exactly +-1 while loading. `gamma - beta`
//! sets how fast `z` recovers after a reversal: 0 is the classic symmetric loop (the state
//! moves one-for-one with the input after a reversal), 0.5 a rounder one.

/// The shape of a Bouc-Wen loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoucWenShape {
    /// `beta`, the part of the decay that depends on the direction of travel.
    pub beta: f64,
    /// `gamma`, the part that does not.
    pub gamma: f64,
}

impl BoucWenShape {
    /// `beta = gamma = 1/2`: one-for-one after a reversal.
    pub const SYMMETRIC: Self = Self {
        beta: 0.5,
        gamma: 0.5,
    };
    /// `beta = 1/4, gamma = 3/4`: half-rate right after a reversal (the virtual lab's columns).
    pub const ROUNDED: Self = Self {
        beta: 0.25,
        gamma: 0.75,
    };
}

/// The evolving state of one Bouc-Wen element.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BoucWen {
    /// Internal state in `[-1, 1]`.
    pub z: f64,
}

impl BoucWen {
    /// Advances by a normalised input increment `dx`.
    pub fn step(&mut self, dx: f64, shape: BoucWenShape) {
        let same_direction = if dx * self.z > 0.0 { 1.0 } else { -1.0 };
        let dz = dx * (1.0 - (shape.beta * same_direction + shape.gamma) * self.z.abs());
        self.z = (self.z + dz).clamp(-1.0, 1.0);
    }

    /// The state along a whole input series, saturating at `+-z0` after about `z0` of travel
    /// (the state is in the input's units, scaled by `z0`), starting from zero.
    pub fn series(x: &[f64], z0: f64, shape: BoucWenShape) -> Vec<f64> {
        let mut state = Self::default();
        let mut out = Vec::with_capacity(x.len());
        for (i, &xi) in x.iter().enumerate() {
            if i > 0 {
                state.step((xi - x[i - 1]) / z0, shape);
            }
            out.push(z0 * state.z);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loading_saturates_at_one_and_follows_the_closed_form() {
        // While loading from z = 0, dz/dx = 1 - z, so z(x) = 1 - exp(-x) in the limit of small
        // steps.
        let mut b = BoucWen::default();
        let n = 100_000;
        let dx = 3.0 / n as f64;
        for _ in 0..n {
            b.step(dx, BoucWenShape::SYMMETRIC);
        }
        let exact = 1.0 - (-3.0f64).exp();
        assert!((b.z - exact).abs() < 1e-4, "{} vs {exact}", b.z);
        for _ in 0..10 * n {
            b.step(dx, BoucWenShape::ROUNDED);
        }
        assert!(b.z <= 1.0 && b.z > 0.999_999);
    }

    #[test]
    fn a_reversal_moves_one_for_one_for_the_symmetric_shape_and_at_half_rate_for_the_rounded() {
        let mut a = BoucWen { z: 0.8 };
        a.step(-1e-3, BoucWenShape::SYMMETRIC);
        assert!((a.z - (0.8 - 1e-3)).abs() < 1e-15);
        let mut b = BoucWen { z: 0.8 };
        b.step(-1e-3, BoucWenShape::ROUNDED);
        assert!((b.z - (0.8 - 1e-3 * (1.0 - 0.5 * 0.8))).abs() < 1e-15);
    }

    #[test]
    fn a_cycle_leaves_a_loop_whose_width_grows_with_amplitude() {
        let x: Vec<f64> = (0..4001)
            .map(|i| (i as f64 / 1000.0 * std::f64::consts::PI).sin())
            .collect();
        let z = BoucWen::series(&x, 0.2, BoucWenShape::SYMMETRIC);
        // at x = 0 the state lags the input: positive going up (i = 2000), negative going down (3000)
        let up = z[2000];
        let down = z[3000];
        assert!(up > 0.1 && down < -0.1, "up {up} down {down}");
        assert!(z.iter().all(|v| v.abs() <= 0.2 + 1e-15));
    }
}
