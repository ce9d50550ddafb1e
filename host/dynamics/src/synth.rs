//! Trajectories of a known lumped system driven like the robot, for tests and demos while no
//! reduced-FEM data set is at hand.

use ocm_mor::drive::{DriveConfig, sequence};

use crate::lumped::LumpedModel;
use crate::trajectory::Trajectory;

/// `count` trajectories of `steps` steps of `model`, inputs from the reduced-FEM data sets'
/// own random drive (`ocm_mor::drive`) with time step `dt_s`, each starting at rest at the
/// origin; RK4 with 8 substeps per step.
pub fn lumped_trajectories(
    model: &LumpedModel,
    count: usize,
    steps: usize,
    dt_s: f64,
    seed: u64,
) -> Vec<Trajectory> {
    let cfg = DriveConfig {
        dt_s,
        ..DriveConfig::default()
    };
    let n = model.state_dim;
    (0..count)
        .map(|i| {
            let inputs = sequence(&cfg, seed, i as u64, steps);
            let p: Vec<f64> = inputs.iter().flat_map(|u| u.pressure_kpa).collect();
            let f: Vec<f64> = inputs.iter().flat_map(|u| u.tip_force_n).collect();
            model.simulate(dt_s, &vec![0.0; n], &vec![0.0; n], &p, &f, 8)
        })
        .collect()
}
