//! Behaviour cloning smoke test: a policy cloned from a few demonstrations inserts the peg
//! more often than a random policy, and the demonstrations and policies round-trip through
//! their files.

use ocm_peg::bc::BcConfig;
use ocm_peg::rollout::run_trial;
use ocm_peg::{
    ActionNoise, BcPolicy, ContactFeatures, DemoSet, DemoSettings, ExpertConfig, Randomisation,
    SceneConfig, TrialSpec, evaluate_policy, train_bc,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("ocm-peg-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn cloned_policy_beats_a_random_policy_and_round_trips() {
    let scene = SceneConfig::default();
    let rand_cfg = Randomisation::default();
    let settings = DemoSettings {
        count: 16,
        seed: 3,
        scene: scene.clone(),
        randomisation: rand_cfg.clone(),
        expert: ExpertConfig::default(),
        noise: ActionNoise::default(),
    };
    let demos = DemoSet::collect(&settings, &ContactFeatures, &mut |_| {}).unwrap();
    assert_eq!(demos.demos(), 16);
    // Same seed, same demonstrations (trials and execution noise are seeded).
    let again = DemoSet::collect(&settings, &ContactFeatures, &mut |_| {}).unwrap();
    assert_eq!(again, demos);
    let other = DemoSet::collect(
        &DemoSettings {
            seed: 4,
            ..settings.clone()
        },
        &ContactFeatures,
        &mut |_| {},
    )
    .unwrap();
    assert_ne!(other.obs, demos.obs);
    let dir = tmp("bc");
    demos.save(&dir).unwrap();
    let back = DemoSet::load(&dir).unwrap();
    assert_eq!(back.obs, demos.obs);
    assert_eq!(back.actions, demos.actions);
    // A stray episode id (it would size the set by itself) is refused with its row.
    let ids_path = dir.join("episodes.npy");
    let good_ids = std::fs::read(&ids_path).unwrap();
    let mut ids = ocm_fem::npy::read_f64_2d(&ids_path).unwrap();
    for (v, row) in [(1e12, 5), (-1.0, 0), (0.5, 3)] {
        let keep = ids.data[row];
        ids.data[row] = v;
        ocm_fem::npy::write_f64_2d_path(&ids_path, &ids.data, ids.rows, 1).unwrap();
        let e = DemoSet::load(&dir).unwrap_err().to_string();
        assert!(
            e.contains("episodes.npy") && e.contains(&format!("row {row}: episode id")),
            "{e}"
        );
        ids.data[row] = keep;
    }
    std::fs::write(&ids_path, good_ids).unwrap();
    DemoSet::load(&dir).unwrap();

    let mut cfg = BcConfig {
        hidden: vec![64, 64],
        ..Default::default()
    };
    cfg.train.epochs = 25;
    let tr = train_bc(&back, true, &cfg).unwrap();
    let path = dir.join("p.ckpt");
    tr.policy.save(&path).unwrap();
    let policy = BcPolicy::load(&path).unwrap();
    let obs: Vec<Vec<f64>> = demos
        .obs
        .chunks_exact(demos.obs_dim())
        .take(5)
        .map(<[f64]>::to_vec)
        .collect();
    // The scalers pass through JSON, which may round the last bit of a float.
    for (a, b) in policy
        .act_batch(&obs)
        .unwrap()
        .iter()
        .zip(tr.policy.act_batch(&obs).unwrap())
    {
        for k in 0..4 {
            assert!(
                (a[k] - b[k]).abs() <= 1e-12 * (1.0 + b[k].abs()),
                "{a:?} {b:?}"
            );
        }
    }

    let spec = |trials| TrialSpec {
        scene: &scene,
        randomisation: &rand_cfg,
        seed: 99,
        trials,
    };
    // No trials, or more than the cap, are refused before any scene is built.
    for trials in [0, ocm_peg::eval::MAX_TRIALS + 1] {
        let e = evaluate_policy("bc", &policy, spec(trials), &ContactFeatures, &mut |_| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains(&format!("trials = {trials}")), "{e}");
    }
    let trials = 8;
    let ev = evaluate_policy("bc", &policy, spec(trials), &ContactFeatures, &mut |_| {}).unwrap();
    // A random policy: uniform velocities within the limits, seeded.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut random_successes = 0;
    for i in 0..trials as u64 {
        let t = rand_cfg.trial(&scene, 99, i);
        let (o, _, _) = run_trial(
            &scene,
            &t,
            &ContactFeatures,
            &mut |_, _| {
                Ok([
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.3..0.3),
                ])
            },
            &mut || [0.0; 4],
        )
        .unwrap();
        random_successes += usize::from(o.success);
    }
    let bc_successes = ev.outcomes.iter().filter(|o| o.success).count();
    assert!(
        bc_successes > random_successes && bc_successes >= 3,
        "bc {bc_successes}/{trials}, random {random_successes}/{trials}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn damaged_demonstrations_and_policies_are_refused() {
    let dir = tmp("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let e = DemoSet::load(&dir).unwrap_err().to_string();
    assert!(e.contains("demos.json"), "{e}");
    std::fs::write(dir.join("p.ckpt"), b"not a checkpoint").unwrap();
    assert!(BcPolicy::load(&dir.join("p.ckpt")).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
