//! Non-ideal effects of the real rig, each switchable with a magnitude.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// The switchable effects of the plant. A magnitude of zero switches an
/// effect off.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Effects {
    /// Hysteresis loop width as a fraction of `hysteresis_reference_n`
    /// (eq 3.37; the dissertation measured about 0.05).
    pub hysteresis_fraction: f64,
    /// Force the hysteresis fraction refers to (the largest column force in
    /// use), newtons.
    pub hysteresis_reference_n: f64,
    /// Column elongation over which the hysteresis force reverses, metres.
    pub hysteresis_yield_m: f64,
    /// Standard deviation of the per-OCM stiffness scale (manufacturing
    /// spread), e.g. 0.05 for 5 %.
    pub stiffness_spread: f64,
    /// Largest regulator offset, pascals; each chamber draws one uniformly
    /// from `[-x, x]`.
    pub regulator_offset_pa: f64,
}

impl Effects {
    /// Every effect off: the ideal plant.
    pub const NONE: Self = Self {
        hysteresis_fraction: 0.0,
        hysteresis_reference_n: 2.0,
        hysteresis_yield_m: 1e-3,
        stiffness_spread: 0.0,
        regulator_offset_pa: 0.0,
    };

    /// The magnitudes of the real rig: 5 % hysteresis of a 10 N reference
    /// (the dissertation's axial loop, 4.7 % or 0.48 N, puts its largest
    /// force near 10 N), 5 % stiffness spread, regulator offsets up to 100 Pa.
    pub const RIG: Self = Self {
        hysteresis_fraction: 0.05,
        hysteresis_reference_n: 10.0,
        hysteresis_yield_m: 1e-3,
        stiffness_spread: 0.05,
        regulator_offset_pa: 100.0,
    };

    /// Per-column mean stiffness scale of `ocms` OCMs each (identical strain
    /// along a column, so only the mean matters) drawn from `rng`.
    pub fn column_stiffness(&self, ocms: u32, rng: &mut ChaCha8Rng) -> [f64; 3] {
        std::array::from_fn(|_| {
            let sum: f64 = (0..ocms)
                .map(|_| {
                    let z: f64 = rng.sample(StandardNormal);
                    (1.0 + self.stiffness_spread * z).max(0.2)
                })
                .sum();
            sum / f64::from(ocms.max(1))
        })
    }

    /// Per-chamber regulator offsets drawn from `rng`, pascals.
    pub fn offsets(&self, rng: &mut ChaCha8Rng) -> [f64; 3] {
        std::array::from_fn(|_| self.regulator_offset_pa * (2.0 * rng.random::<f64>() - 1.0))
    }
}

impl Default for Effects {
    fn default() -> Self {
        Self::NONE
    }
}

/// Bouc-Wen hysteresis of one column: a force `F_h z` whose state `z` is driven by the
/// column's elongation over `hysteresis_yield_m`, with the [`COLUMN_LOOP`] shape, so `z`
/// saturates at +-1 after about that much travel and the loop width in force is `2 F_h`.
pub use ocm_lutgen::hysteresis::BoucWen;

/// The loop shape of the columns: half-rate recovery right after a reversal.
pub const COLUMN_LOOP: ocm_lutgen::hysteresis::BoucWenShape =
    ocm_lutgen::hysteresis::BoucWenShape::ROUNDED;
