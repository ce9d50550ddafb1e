//! Evaluation of policies on randomised trials, all trials stepped in lockstep so that the
//! policy runs once per control step on the whole batch.

use serde::{Deserialize, Serialize};

use crate::bc::BcPolicy;
use crate::encoder::TactileEncoder;
use crate::error::{PegError, Result};
use crate::expert::ExpertConfig;
use crate::rollout::{Outcome, observe, run_trial};
use crate::scene::{PegScene, SceneConfig};
use crate::trial::Randomisation;

/// Outcomes of one controller on a set of trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Controller name.
    pub controller: String,
    /// One outcome per trial.
    pub outcomes: Vec<Outcome>,
    /// Tip path of each trial: rows `[time_s, x_m, y_m, z_m]`.
    pub tip_paths: Vec<Vec<[f64; 4]>>,
}

impl Evaluation {
    /// Fraction of successful trials.
    pub fn success_rate(&self) -> f64 {
        let n = self.outcomes.len().max(1) as f64;
        self.outcomes.iter().filter(|o| o.success).count() as f64 / n
    }

    /// Median time to success over the successful trials, s (NaN without any).
    pub fn median_success_time_s(&self) -> f64 {
        median(
            self.outcomes
                .iter()
                .filter(|o| o.success)
                .map(|o| o.time_s)
                .collect(),
        )
    }

    /// Median over the trials of the largest turn of the peg in the hand, rad (zero with a
    /// rigid grasp; NaN without trials).
    pub fn median_largest_turn_rad(&self) -> f64 {
        median(self.outcomes.iter().map(|o| o.largest_shift[2]).collect())
    }
}

/// The median of `v` (NaN when empty).
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// The trials to evaluate on: trials `0..trials` of stream `seed` of a randomisation.
#[derive(Debug, Clone, Copy)]
pub struct TrialSpec<'a> {
    /// The scene.
    pub scene: &'a SceneConfig,
    /// The randomisation.
    pub randomisation: &'a Randomisation,
    /// Seed of the trial stream.
    pub seed: u64,
    /// Number of trials.
    pub trials: usize,
}

/// Most trials one evaluation runs: the policy's trials are built up front and step together,
/// and the dissertation's figure rests on 100.
pub const MAX_TRIALS: usize = 10_000;

impl TrialSpec<'_> {
    /// Refuses an empty evaluation (its success rate would be 0/0) and one beyond
    /// [`MAX_TRIALS`].
    pub fn validate(&self) -> Result<()> {
        if (1..=MAX_TRIALS).contains(&self.trials) {
            Ok(())
        } else {
            Err(PegError::Invalid(format!(
                "trials = {}: need 1 to {MAX_TRIALS}",
                self.trials
            )))
        }
    }
}

fn tip_row(scene: &PegScene) -> [f64; 4] {
    let (p, _) = scene.peg_tip();
    [scene.time_s(), p[0], p[1], p[2]]
}

/// Runs `policy` on the trials of `spec`; `progress(control_step)` is called once per control
/// step of the batch.
pub fn evaluate_policy(
    name: &str,
    policy: &BcPolicy,
    spec: TrialSpec<'_>,
    encoder: &dyn TactileEncoder,
    progress: &mut dyn FnMut(usize),
) -> Result<Evaluation> {
    run_policy(name, policy, spec, 0, encoder, progress, None)
}

/// What an expert would have done in the states a policy visited: per control step of every
/// trial, the observation the policy read and the expert's action in that state (DAgger's
/// labels).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Labelled {
    /// Observations, rows of the policy's full observation length.
    pub obs: Vec<f64>,
    /// The expert's actions, rows of [`crate::scene::N_ACTION`].
    pub actions: Vec<f64>,
    /// Trial (position in the batch) of each row.
    pub trial: Vec<usize>,
}

/// Runs `policy` on trials `first..first + spec.trials` of `spec`'s stream and labels every
/// state it visits with `expert`'s action there. The policy's own action is executed.
pub fn label_policy_states(
    policy: &BcPolicy,
    expert: &ExpertConfig,
    spec: TrialSpec<'_>,
    first: u64,
    encoder: &dyn TactileEncoder,
    progress: &mut dyn FnMut(usize),
) -> Result<(Evaluation, Labelled)> {
    expert.validate()?;
    let mut labelled = Labelled::default();
    let ev = run_policy(
        "policy",
        policy,
        spec,
        first,
        encoder,
        progress,
        Some((expert, &mut labelled)),
    )?;
    Ok((ev, labelled))
}

/// All trials of a batch stepped in lockstep, the policy called once per control step.
fn run_policy(
    name: &str,
    policy: &BcPolicy,
    spec: TrialSpec<'_>,
    first: u64,
    encoder: &dyn TactileEncoder,
    progress: &mut dyn FnMut(usize),
    mut label: Option<(&ExpertConfig, &mut Labelled)>,
) -> Result<Evaluation> {
    let TrialSpec {
        scene: config,
        randomisation,
        seed,
        trials,
    } = spec;
    randomisation.validate()?;
    spec.validate()?;
    let specs: Vec<_> = (first..first + trials as u64)
        .map(|i| randomisation.trial(config, seed, i))
        .collect();
    let mut scenes = specs
        .iter()
        .map(|t| {
            let mut s = t.scene(config)?;
            s.seed_sensors(t.seed, t.index);
            Ok(s)
        })
        .collect::<Result<Vec<_>>>()?;
    let mut paths: Vec<Vec<[f64; 4]>> = scenes.iter().map(|s| vec![tip_row(s)]).collect();
    let limit = config.max_control_steps();
    for step in 0..limit {
        let active: Vec<usize> = (0..scenes.len())
            .filter(|&i| !scenes[i].inserted())
            .collect();
        if active.is_empty() {
            break;
        }
        let obs = active
            .iter()
            .map(|&i| observe(&mut scenes[i], encoder))
            .collect::<Result<Vec<_>>>()?;
        if let Some((expert, rows)) = label.as_mut() {
            for (&i, o) in active.iter().zip(&obs) {
                rows.obs.extend(o);
                rows.actions.extend(expert.act(&scenes[i]));
                rows.trial.push(i);
            }
        }
        let actions = policy.act_batch(&obs)?;
        for (&i, a) in active.iter().zip(actions) {
            scenes[i].step(a)?;
            paths[i].push(tip_row(&scenes[i]));
        }
        progress(step + 1);
    }
    let outcomes = specs
        .iter()
        .zip(&scenes)
        .map(|(t, s)| Outcome::at_end(t, s))
        .collect();
    Ok(Evaluation {
        controller: name.to_string(),
        outcomes,
        tip_paths: paths,
    })
}

/// Runs the privileged expert (no noise) on the same trials, as the reference.
pub fn evaluate_expert(
    expert: &ExpertConfig,
    spec: TrialSpec<'_>,
    encoder: &dyn TactileEncoder,
) -> Result<Evaluation> {
    let TrialSpec {
        scene: config,
        randomisation,
        seed,
        trials,
    } = spec;
    expert.validate()?;
    randomisation.validate()?;
    spec.validate()?;
    let mut outcomes = Vec::with_capacity(trials);
    let mut tip_paths = Vec::with_capacity(trials);
    for i in 0..trials as u64 {
        let t = randomisation.trial(config, seed, i);
        let mut tips = Vec::new();
        let (o, _, _) = run_trial(
            config,
            &t,
            encoder,
            &mut |scene, _| {
                tips.push(tip_row(scene));
                Ok(expert.act(scene))
            },
            &mut || [0.0; 4],
        )?;
        tips.push([o.time_s, o.tip_m[0], o.tip_m[1], o.tip_m[2]]);
        outcomes.push(o);
        tip_paths.push(tips);
    }
    Ok(Evaluation {
        controller: "expert".into(),
        outcomes,
        tip_paths,
    })
}
