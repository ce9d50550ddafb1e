//! DAgger: a cloned search that stalls where its expert slides on is run, its states are
//! labelled with the expert's actions, and the policy cloned again on them inserts more often.

use ocm_peg::bc::BcConfig;
use ocm_peg::rollout::run_trial;
use ocm_peg::{
    ActionNoise, BcPolicy, ContactFeatures, DaggerConfig, DemoSet, DemoSettings, ExpertConfig,
    Randomisation, SceneConfig, SpiralSearch, TrialSpec, dagger, label_policy_states, train_bc,
};

/// A searching expert's demonstrations on a hole up to 1.5 mm from where it is believed, with
/// an 8 s limit.
fn settings(count: usize) -> DemoSettings {
    DemoSettings {
        count,
        seed: 11,
        scene: SceneConfig {
            time_limit_s: 8.0,
            ..SceneConfig::default()
        },
        randomisation: Randomisation {
            hole_xy_m: 0.0015,
            ..Randomisation::default()
        },
        expert: ExpertConfig {
            search: Some(SpiralSearch::default()),
            ..ExpertConfig::default()
        },
        noise: ActionNoise::default(),
    }
}

fn small() -> BcConfig {
    let mut cfg = BcConfig {
        hidden: vec![64, 64],
        ..Default::default()
    };
    cfg.train.epochs = 20;
    cfg
}

/// The labelled rows are, trial by trial, the observation the policy read and the expert's
/// action in that state, as a single trial stepped on its own records them; the policy's own
/// action is what runs.
#[test]
fn labels_are_the_experts_actions_in_the_policys_states() {
    let s = settings(6);
    let demos = DemoSet::collect(&s, &ContactFeatures, &mut |_| {}).unwrap();
    let mut cfg = small();
    cfg.train.epochs = 5;
    let policy = train_bc(&demos, true, &cfg).unwrap().policy;
    let spec = TrialSpec {
        scene: &s.scene,
        randomisation: &s.randomisation,
        seed: 7,
        trials: 3,
    };
    let (ev, rows) =
        label_policy_states(&policy, &s.expert, spec, 2, &ContactFeatures, &mut |_| {}).unwrap();
    let d = demos.obs_dim();
    assert_eq!(rows.obs.len(), rows.trial.len() * d);
    assert_eq!(rows.actions.len(), rows.trial.len() * 4);
    let mut label_differs = false;
    for i in 0..3 {
        let t = s.randomisation.trial(&s.scene, 7, 2 + i as u64);
        assert_eq!(
            ev.outcomes[i].trial,
            t,
            "trial {i} is not trial {} of the stream",
            2 + i
        );
        let mut alone: Vec<(Vec<f64>, [f64; 4], [f64; 4])> = Vec::new();
        let (o, _, _) = run_trial(
            &s.scene,
            &t,
            &ContactFeatures,
            &mut |scene, obs| {
                let a = policy.act_batch(&[obs.to_vec()])?[0];
                alone.push((obs.to_vec(), s.expert.act(scene), a));
                Ok(a)
            },
            &mut || [0.0; 4],
        )
        .unwrap();
        let mine: Vec<usize> = (0..rows.trial.len())
            .filter(|&r| rows.trial[r] == i)
            .collect();
        assert_eq!(mine.len(), alone.len(), "trial {i}: rows");
        assert_eq!(o.success, ev.outcomes[i].success, "trial {i}: outcome");
        for (&r, (obs, label, act)) in mine.iter().zip(&alone) {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + b.abs());
            for (k, (&mine, &alone)) in rows.obs[r * d..(r + 1) * d].iter().zip(obs).enumerate() {
                assert!(close(mine, alone), "trial {i} row {r} obs {k}");
            }
            for k in 0..4 {
                assert!(
                    close(rows.actions[r * 4 + k], label[k]),
                    "trial {i} row {r} label {k}"
                );
                label_differs |= (label[k] - act[k]).abs() > 1e-4;
            }
        }
    }
    // A policy cloned for five epochs is not its expert: the labels are not its own actions.
    assert!(label_differs);
}

/// RMS difference between a policy's velocity and its expert's over the states the policy
/// visits on held-out trials, m/s, and its successes: the quantity DAgger's rounds cut.
fn on_policy_error(p: &BcPolicy, s: &DemoSettings, trials: usize) -> (f64, usize) {
    let spec = TrialSpec {
        scene: &s.scene,
        randomisation: &s.randomisation,
        seed: 77,
        trials,
    };
    let (ev, rows) =
        label_policy_states(p, &s.expert, spec, 0, &ContactFeatures, &mut |_| {}).unwrap();
    let d = rows.obs.len() / rows.trial.len();
    let obs: Vec<Vec<f64>> = rows.obs.chunks_exact(d).map(<[f64]>::to_vec).collect();
    let acts = p.act_batch(&obs).unwrap();
    let se: f64 = acts
        .iter()
        .zip(rows.actions.chunks_exact(4))
        .map(|(a, l)| (0..3).map(|k| (a[k] - l[k]).powi(2)).sum::<f64>())
        .sum();
    let wins = ev.outcomes.iter().filter(|o| o.success).count();
    ((se / acts.len() as f64).sqrt(), wins)
}

/// A search cloned from 16 demonstrations drifts off its expert on its own states; three
/// DAgger rounds of 16 trials cut that drift on held-out trials by a quarter or more (measured:
/// 8.2 to 4.8 mm/s), and the policy records its rounds.
#[test]
fn dagger_cuts_the_error_on_the_policys_own_states_and_records_its_rounds() {
    let s = settings(16);
    let demos = DemoSet::collect(&s, &ContactFeatures, &mut |_| {}).unwrap();
    let cfg = small();
    let plain = train_bc(&demos, true, &cfg).unwrap().policy;
    let rounds = DaggerConfig {
        rounds: 3,
        trials: 16,
        seed: 5000,
    };
    let tr = dagger(&demos, true, &cfg, &rounds, &ContactFeatures, &mut |_| {}).unwrap();
    let record = tr
        .policy
        .meta
        .dagger
        .clone()
        .expect("the rounds are recorded");
    assert_eq!(record.rounds.len(), 3);
    assert_eq!(record.config, rounds);
    // Every round adds rows.
    let mut rows = demos.rows();
    for r in &record.rounds {
        assert!(r.rows_added > 0);
        rows += r.rows_added;
        assert_eq!(r.rows, rows);
    }
    assert_eq!(tr.policy.meta.rows, rows);
    assert_eq!(tr.policy.meta.demos, 16);

    let (before, wins_before) = on_policy_error(&plain, &s, 24);
    let (after, wins_after) = on_policy_error(&tr.policy, &s, 24);
    assert!(
        after < 0.75 * before,
        "on-policy RMS error {:.2} mm/s after DAgger against {:.2} before (inserted {wins_after} \
         and {wins_before} of 24)",
        1e3 * after,
        1e3 * before
    );

    // The record survives the checkpoint; a checkpoint without it reads as plain cloning.
    let dir = std::env::temp_dir().join(format!("ocm-peg-dagger-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    tr.policy.save(&dir.join("p.ckpt")).unwrap();
    // The checkpoint's JSON may round a float's last bit (a wall time did in CI).
    let back = BcPolicy::load(&dir.join("p.ckpt"))
        .unwrap()
        .meta
        .dagger
        .expect("the record is in the checkpoint");
    let bits = |r: &ocm_peg::DaggerRecord| {
        r.rounds
            .iter()
            .map(|x| {
                (
                    x.round,
                    x.rows_added,
                    x.rows,
                    x.success_rate,
                    x.best_loss,
                    x.wall_time_s,
                )
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(back.config, record.config);
    for (a, b) in bits(&back).iter().zip(bits(&record)) {
        assert_eq!((a.0, a.1, a.2), (b.0, b.1, b.2));
        for (u, v) in [(a.3, b.3), (a.4, b.4), (a.5, b.5)] {
            assert!((u - v).abs() <= 1e-12 * v.abs(), "{a:?} against {b:?}");
        }
    }
    assert_eq!(back.rounds.len(), record.rounds.len());
    plain.save(&dir.join("q.ckpt")).unwrap();
    assert_eq!(
        BcPolicy::load(&dir.join("q.ckpt")).unwrap().meta.dagger,
        None
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// No rounds, too many, no trials, and latents from another encoder are refused, each named.
#[test]
fn bad_dagger_settings_are_refused() {
    let s = settings(2);
    let demos = DemoSet::collect(&s, &ContactFeatures, &mut |_| {}).unwrap();
    for (cfg, needle) in [
        (
            DaggerConfig {
                rounds: 0,
                trials: 4,
                seed: 1,
            },
            "dagger rounds = 0",
        ),
        (
            DaggerConfig {
                rounds: ocm_peg::dagger::MAX_ROUNDS + 1,
                trials: 4,
                seed: 1,
            },
            "dagger rounds = 21",
        ),
        (
            DaggerConfig {
                rounds: 1,
                trials: 0,
                seed: 1,
            },
            "dagger trials",
        ),
    ] {
        let e = dagger(&demos, true, &small(), &cfg, &ContactFeatures, &mut |_| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains(needle), "{e}");
    }
    let mut other = demos.clone();
    other.encoder = "npe".into();
    let ok = DaggerConfig {
        rounds: 1,
        trials: 1,
        seed: 1,
    };
    let e = dagger(&other, true, &small(), &ok, &ContactFeatures, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("npe") && e.contains("contact-features"), "{e}");
}
