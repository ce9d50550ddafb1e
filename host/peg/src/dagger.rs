//! DAgger (Ross, Gordon and Bagnell 2011): a cloned policy drifts into states its expert never
//! visited (a search that stalls where the expert slides on), so its own rollouts are labelled
//! with what the privileged expert would do there and added to the data.

use crate::bc::{BcConfig, BcTraining, DaggerConfig, DaggerRecord, DaggerRound, train_bc};
use crate::demos::DemoSet;
use crate::encoder::TactileEncoder;
use crate::error::{PegError, Result};
use crate::eval::{TrialSpec, label_policy_states};

/// Most DAgger rounds (each clones the policy afresh on all rows so far).
pub const MAX_ROUNDS: usize = 20;

impl DaggerConfig {
    /// Refuses no rounds, too many, and rounds without trials.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_ROUNDS).contains(&self.rounds) {
            return Err(PegError::Invalid(format!(
                "dagger rounds = {}: need 1 to {MAX_ROUNDS}",
                self.rounds
            )));
        }
        if self.trials == 0 {
            return Err(PegError::Invalid(
                "dagger trials per round must be positive".into(),
            ));
        }
        Ok(())
    }
}

/// Clones a policy from `demos` (`touch` selects its inputs), then runs `cfg.rounds` rounds of
/// DAgger in the demonstrations' scene, randomisation and expert: the policy runs on the
/// round's trials, every state it visits is labelled with the expert's action, and a policy
/// is cloned afresh (same settings and seeds) on the demonstrations and all labelled rows.
/// Returns the last round's policy, its meta recording the rounds. `progress(round)` is called
/// before each round's rollouts.
pub fn dagger(
    demos: &DemoSet,
    touch: bool,
    bc: &BcConfig,
    cfg: &DaggerConfig,
    encoder: &dyn TactileEncoder,
    progress: &mut dyn FnMut(usize),
) -> Result<BcTraining> {
    cfg.validate()?;
    if encoder.name() != demos.encoder || encoder.dim() != demos.latent_dim {
        return Err(PegError::Invalid(format!(
            "the demonstrations' latents come from {} ({} values), the encoder is {} ({})",
            demos.encoder,
            demos.latent_dim,
            encoder.name(),
            encoder.dim()
        )));
    }
    let settings = &demos.settings;
    let spec = TrialSpec {
        scene: &settings.scene,
        randomisation: &settings.randomisation,
        seed: cfg.seed,
        trials: cfg.trials,
    };
    let mut data = demos.clone();
    // Labelled rows get episode ids after the demonstrations' (one per rolled-out trial).
    let mut next_episode = data.episode.iter().max().map_or(0, |e| e + 1);
    let mut training = train_bc(&data, touch, bc)?;
    let mut rounds = Vec::with_capacity(cfg.rounds);
    for round in 1..=cfg.rounds {
        progress(round);
        let start = std::time::Instant::now();
        let first = ((round - 1) * cfg.trials) as u64;
        let (ev, rows) = label_policy_states(
            &training.policy,
            &settings.expert,
            spec,
            first,
            encoder,
            &mut |_| {},
        )?;
        debug_assert_eq!(rows.obs.len(), rows.trial.len() * data.obs_dim());
        data.obs.extend(&rows.obs);
        data.actions.extend(&rows.actions);
        data.episode
            .extend(rows.trial.iter().map(|&t| next_episode + t));
        next_episode += cfg.trials;
        data.outcomes.extend(ev.outcomes.iter().copied());
        training = train_bc(&data, touch, bc)?;
        rounds.push(DaggerRound {
            round,
            success_rate: ev.success_rate(),
            rows_added: rows.trial.len(),
            rows: data.rows(),
            best_loss: training.policy.meta.best_loss,
            wall_time_s: start.elapsed().as_secs_f64(),
        });
    }
    // The demonstrations' count stays the experts' runs; the rows include the labelled ones.
    training.policy.meta.dagger = Some(DaggerRecord {
        config: cfg.clone(),
        rounds,
    });
    Ok(training)
}
