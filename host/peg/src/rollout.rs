//! Observations and rollouts: what a policy sees each control step, and trials run to success
//! or the time limit.

use serde::{Deserialize, Serialize};

use crate::encoder::TactileEncoder;
use crate::error::Result;
use crate::scene::{N_ACTION, N_PROPRIO, PegScene, SceneConfig};
use crate::trial::Trial;

/// The observation `[proprioception, Z_left, Z_right]`: gripper x, y, z (m) and roll (rad) in
/// the hole frame, then each sensor's latent of what it reports (with the scene's sensor
/// errors, through its low-pass when it has one). Call once per control step.
pub fn observe(scene: &mut PegScene, encoder: &dyn TactileEncoder) -> Result<Vec<f64>> {
    let mut latents = Vec::with_capacity(2 * encoder.dim());
    for c in scene.sensed()? {
        latents.extend(
            encoder
                .latent(&c.points_m, c.force_n)?
                .into_iter()
                .map(f64::from),
        );
    }
    let mut obs = scene.gripper().to_array().to_vec();
    obs.extend(scene.low_pass(latents));
    Ok(obs)
}

/// Length of an observation with `latent_dim` values per sensor.
pub fn obs_dim(latent_dim: usize) -> usize {
    N_PROPRIO + 2 * latent_dim
}

/// A controller: the action for the scene (privileged controllers read it) and the
/// observation (policies read only this).
pub type Controller<'a> = dyn FnMut(&PegScene, &[f64]) -> Result<[f64; N_ACTION]> + 'a;

/// How a trial ended.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The trial.
    pub trial: Trial,
    /// The tip reached the success depth before the time limit.
    pub success: bool,
    /// Time at the end (success or time limit), s.
    pub time_s: f64,
    /// The tip at the end (hole frame), m.
    pub tip_m: [f64; 3],
    /// How far the peg slipped in the hand by the end (compliant grasp; zero when rigid):
    /// along the pads' horizontal direction (m), along the fingers (m), turn (rad).
    #[serde(default)]
    pub slip: [f64; 3],
    /// The largest |shift| of the peg in the hand during the trial, per component (elastic
    /// and slipped; compliant grasp).
    #[serde(default)]
    pub largest_shift: [f64; 3],
}

impl Outcome {
    /// The outcome of `trial` as `scene` ends it.
    pub fn at_end(trial: &Trial, scene: &PegScene) -> Self {
        Self {
            trial: *trial,
            success: scene.inserted(),
            time_s: scene.time_s(),
            tip_m: scene.peg_tip().0,
            slip: scene.slipped(),
            largest_shift: scene.largest_shift(),
        }
    }
}

/// One recorded control step.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Time at the observation, s.
    pub time_s: f64,
    /// The observation.
    pub obs: Vec<f64>,
    /// The action the controller chose (before execution noise).
    pub action: [f64; N_ACTION],
}

/// Runs trial `trial` with `controller`: every control step observes, asks the controller for
/// an action, adds `noise` (the executed action; the recorded one stays clean) and steps. Stops
/// at success or at the time limit. Returns the outcome and the recorded steps.
pub fn run_trial(
    config: &SceneConfig,
    trial: &Trial,
    encoder: &dyn TactileEncoder,
    controller: &mut Controller<'_>,
    noise: &mut dyn FnMut() -> [f64; N_ACTION],
) -> Result<(Outcome, Vec<Step>, Vec<[f64; 5]>)> {
    let mut scene = trial.scene(config)?;
    scene.seed_sensors(trial.seed, trial.index);
    let mut steps = Vec::new();
    let mut path = Vec::new();
    let limit = config.max_control_steps();
    while !scene.inserted() && scene.steps() < limit {
        let obs = observe(&mut scene, encoder)?;
        let action = controller(&scene, &obs)?;
        let g = scene.gripper();
        path.push([scene.time_s(), g.x_m, g.y_m, g.z_m, g.roll_rad]);
        let n = noise();
        let exec = std::array::from_fn(|i| action[i] + n[i]);
        steps.push(Step {
            time_s: scene.time_s(),
            obs,
            action,
        });
        scene.step(exec)?;
    }
    let g = scene.gripper();
    path.push([scene.time_s(), g.x_m, g.y_m, g.z_m, g.roll_rad]);
    Ok((Outcome::at_end(trial, &scene), steps, path))
}
