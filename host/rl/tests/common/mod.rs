//! The robot and the short training settings the tests share.

use ocm_learn::{LrSchedule, TrainConfig};
use ocm_rl::env::PHYSICS_DT_S;
use ocm_rl::robot::Robot;
use ocm_surrogate::chain::ChainGeometry;
use ocm_surrogate::constraints::Limits;
use std::sync::Arc;

/// The chain with the dimensions `ocm surrogate map` measures on the bellows FEM.
pub fn robot() -> Arc<Robot> {
    let chain = ChainGeometry {
        base_height_m: 0.0293,
        segment_length_m: 0.0286,
        tcp_offset_m: 0.0473,
        link_radius_m: 0.0739,
        base_radius_m: 0.0673,
        top_radius_m: 0.0828,
        top_thickness_m: 0.0195,
        link_mass_kg: 0.117,
        dummy_mass_kg: 1e-5,
    };
    Arc::new(Robot::new(&chain, &Limits::default(), PHYSICS_DT_S).unwrap())
}

/// A short behaviour-cloning run: enough to beat a random policy, seconds to train.
// Each test binary compiles this module; the environment tests train nothing.
#[allow(dead_code)]
pub fn quick_train() -> TrainConfig {
    TrainConfig {
        epochs: 80,
        batch_size: 128,
        learning_rate: 3e-3,
        val_fraction: 0.0,
        patience: 0,
        grad_clip_norm: None,
        seed: 0,
        progress: false,
        lr_schedule: LrSchedule::Constant,
    }
}
