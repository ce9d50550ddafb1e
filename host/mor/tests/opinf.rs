//! Operator inference: exact recovery of a known discrete polynomial system, the regularisation
//! path, stability checks and the file contract.

use nalgebra::DMatrix;
use ocm_mor::opinf::{
    self, INPUTS, LeastSquares, OPINF_FORMAT, OpInfModel, OpInfRecord, OpInfTerms, Regularisation,
    Trajectory,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn terms(implicit: bool) -> OpInfTerms {
    OpInfTerms {
        quadratic_modes: 3,
        pressure_bilinear: true,
        bilinear_modes: 3,
        force_bilinear: !implicit,
        input_quadratic: true,
        state_lags: 2,
        input_lags: if implicit { 1 } else { 2 },
        implicit,
        velocity_bilinear: !implicit,
    }
}

/// A stable operator of rank 3: contracting lags, small nonlinear terms.
fn known_operator(t: OpInfTerms, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let r = 3;
    let p = t.len(r);
    DMatrix::from_fn(r, p, |i, j| {
        let noise: f64 = rng.random_range(-1.0..1.0);
        if j < r {
            // A: 0.6 I + 0.05 noise.
            (if i == j { 0.6 } else { 0.0 }) + 0.05 * noise
        } else if j < 2 * r {
            // A2: -0.2 I + 0.05 noise.
            (if i + r == j { -0.2 } else { 0.0 }) + 0.05 * noise
        } else if t.is_linear(r, j) {
            0.3 * noise
        } else {
            0.02 * noise
        }
    })
}

fn trajectories(
    model: &OpInfModel,
    n: usize,
    steps: usize,
    noise: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<Trajectory> {
    (0..n)
        .map(|_| {
            let inputs: Vec<[f64; INPUTS]> = (0..steps)
                .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
                .collect();
            let mut s = model.rest_state();
            let mut phi = vec![0.0; model.terms.len(model.rank())];
            let q = inputs
                .iter()
                .map(|w| {
                    model
                        .step(&mut s, w, &mut phi)
                        .expect("the known system is stable");
                    s.q[0]
                        .iter()
                        .map(|x| x + noise * rng.random_range(-1.0..1.0))
                        .collect()
                })
                .collect();
            Trajectory { q, inputs }
        })
        .collect()
}

#[test]
fn recovers_the_operators_of_a_known_polynomial_system() {
    for implicit in [false, true] {
        let t = terms(implicit);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let op = known_operator(t, &mut rng);
        let truth = OpInfModel::new(t, op.clone(), 1e6, 0.01).unwrap();
        assert!(truth.check_stable().unwrap() < 1.0);
        let trajs = trajectories(&truth, 6, 80, 0.0, &mut rng);
        let ls = LeastSquares::new(&trajs, t, 3).unwrap();
        let fit = ls.solve(0.0).unwrap();
        let err = (&fit - &op).amax() / op.amax();
        assert!(err < 1e-8, "implicit {implicit}: operator error {err:e}");
        assert!(opinf::fit_residual(&trajs, t, &fit) < 1e-10);
        // The refitted model's free run is the system's own trajectory.
        let m = OpInfModel::new(t, fit, 1e6, 0.01).unwrap();
        let mut s = m.rest_state();
        let mut phi = vec![0.0; t.len(3)];
        for (k, w) in trajs[0].inputs.iter().enumerate() {
            m.step(&mut s, w, &mut phi).unwrap();
            for i in 0..3 {
                assert!((s.q[0][i] - trajs[0].q[k][i]).abs() < 1e-8);
            }
        }
    }
}

#[test]
fn the_regularisation_path_is_monotone_in_fit_error() {
    let t = terms(false);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let truth = OpInfModel::new(t, known_operator(t, &mut rng), 1e6, 0.01).unwrap();
    let noisy = trajectories(&truth, 5, 60, 1e-3, &mut rng);
    let lambdas: Vec<Regularisation> = [0.0, 1e-8, 1e-6, 1e-4, 1e-2, 1.0, 100.0]
        .iter()
        .map(|&l| Regularisation {
            linear: l,
            nonlinear: l,
        })
        .collect();
    let clean = trajectories(&truth, 2, 60, 0.0, &mut rng);
    let mut score = |m: &OpInfModel| -> ocm_mor::Result<f64> {
        // Free-run error on clean trajectories of the true system.
        let mut s = m.rest_state();
        let mut phi = vec![0.0; t.len(3)];
        let mut e: f64 = 0.0;
        for (w, q) in clean[0].inputs.iter().zip(&clean[0].q) {
            m.step(&mut s, w, &mut phi)?;
            e = e.max((0..3).map(|i| (s.q[0][i] - q[i]).abs()).fold(0.0, f64::max));
        }
        Ok(e)
    };
    let (path, best) =
        opinf::regularisation_path(&noisy, t, 3, 0.01, &lambdas, &mut score).unwrap();
    for w in path.windows(2) {
        assert!(
            w[1].fit_residual >= w[0].fit_residual * (1.0 - 1e-9),
            "fit residual falls from {:?} to {:?}",
            w[0],
            w[1]
        );
    }
    assert!(path.last().unwrap().fit_residual > 10.0 * path[0].fit_residual);
    // Heavy regularisation pulls the map away from the system: the choice is not the largest.
    let best = best.expect("a stable fit");
    assert!(best.linear < 100.0, "{best:?}");
    assert!(path.iter().all(|p| p.validation_error.is_finite()));
}

#[test]
fn an_unstable_fit_is_refused() {
    let t = terms(false);
    let r = 3;
    // A = 1.05 I: a growing linear part.
    let op = DMatrix::from_fn(r, t.len(r), |i, j| if i == j { 1.05 } else { 0.0 });
    let m = OpInfModel::new(t, op.clone(), 10.0, 0.01).unwrap();
    let e = m.check_stable().unwrap_err().to_string();
    assert!(e.contains("unstable"), "{e}");
    // Its free run under a constant push leaves the training range and is refused.
    let mut s = m.rest_state();
    let mut phi = vec![0.0; t.len(r)];
    let mut op2 = op.clone();
    let last = t.len(r) - 1;
    op2[(0, last)] = 1.0;
    let m2 = OpInfModel::new(t, op2, 10.0, 0.01).unwrap();
    let w = [0.0; INPUTS];
    let failed = (0..200).any(|_| m2.step(&mut s, &w, &mut phi).is_err());
    assert!(failed, "a growing free run is stopped");
    // A path whose every fit is unstable chooses nothing.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let truth = OpInfModel::new(t, known_operator(t, &mut rng), 1e6, 0.01).unwrap();
    let trajs = trajectories(&truth, 3, 40, 0.0, &mut rng);
    let (path, best) = opinf::regularisation_path(
        &trajs,
        t,
        3,
        0.01,
        &[Regularisation {
            linear: 0.0,
            nonlinear: 0.0,
        }],
        &mut |_| Err(ocm_mor::MorError::Solve("unstable".into())),
    )
    .unwrap();
    assert!(best.is_none() && path[0].validation_error.is_nan());
}

#[test]
fn corrupt_or_mismatched_files_are_refused_naming_the_file() {
    let dir = std::env::temp_dir().join(format!("ocm-mor-opinf-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let t = terms(false);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let op = known_operator(t, &mut rng);
    let m = OpInfModel::new(t, op.clone(), 1e6, 0.01).unwrap();
    let basis = DMatrix::from_fn(12, 3, |i, j| ((i * 7 + j * 3) % 5) as f64 - 2.0);
    let rec = OpInfRecord {
        format: OPINF_FORMAT.into(),
        basis_hash: ocm_mor::store::basis_hash(&basis),
        operator_hash: opinf::operator_hash(&op),
        rank: 3,
        terms: t,
        features: t.len(3),
        lambda: Regularisation {
            linear: 1e-6,
            nonlinear: 1e-4,
        },
        dt_s: 0.01,
        state_bound: 1e6,
        spectral_radius: m.spectral_radius().unwrap(),
        training_sequences: 1,
        validation_sequences: 0,
        path: vec![],
    };
    opinf::save(&dir, &m, &rec).unwrap();
    let (back, _) = opinf::load(&dir, &basis).unwrap();
    assert_eq!(back.operator, op);

    // Another basis.
    let mut other = basis.clone();
    other[(0, 0)] += 1.0;
    let e = opinf::load(&dir, &other).unwrap_err().to_string();
    assert!(e.contains("opinf.json") && e.contains("basis"), "{e}");

    // A changed operator value.
    let npy = dir.join("opinf.npy");
    let good = std::fs::read(&npy).unwrap();
    let mut bad = good.clone();
    let n = bad.len();
    bad[n - 3] ^= 0x40;
    std::fs::write(&npy, &bad).unwrap();
    let e = opinf::load(&dir, &basis).unwrap_err().to_string();
    assert!(e.contains("opinf.npy") && e.contains("hash"), "{e}");

    // A truncated file.
    std::fs::write(&npy, &good[..n - 16]).unwrap();
    let e = opinf::load(&dir, &basis).unwrap_err().to_string();
    assert!(e.contains("opinf.npy"), "{e}");
    std::fs::write(&npy, &good).unwrap();

    // A record of another format, and one that is not JSON.
    let jp = dir.join("opinf.json");
    let text = std::fs::read_to_string(&jp).unwrap();
    std::fs::write(&jp, text.replace(OPINF_FORMAT, "ocm-mor-opinf/0")).unwrap();
    let e = opinf::load(&dir, &basis).unwrap_err().to_string();
    assert!(e.contains("opinf.json") && e.contains("format"), "{e}");
    std::fs::write(&jp, "{").unwrap();
    let e = opinf::load(&dir, &basis).unwrap_err().to_string();
    assert!(e.contains("opinf.json"), "{e}");

    // A consistent file holding an unstable operator.
    let unstable = DMatrix::from_fn(3, t.len(3), |i, j| if i == j { 1.2 } else { 0.0 });
    let mu = OpInfModel::new(t, unstable.clone(), 1e6, 0.01).unwrap();
    let rec_u = OpInfRecord {
        operator_hash: opinf::operator_hash(&unstable),
        ..rec
    };
    opinf::save(&dir, &mu, &rec_u).unwrap();
    let e = opinf::load(&dir, &basis).unwrap_err().to_string();
    assert!(e.contains("opinf.npy") && e.contains("unstable"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn regularisations_parse_or_are_refused() {
    let r = Regularisation::parse("1e-5:3e-3").unwrap();
    assert_eq!((r.linear, r.nonlinear), (1e-5, 3e-3));
    let r = Regularisation::parse("0.1").unwrap();
    assert_eq!((r.linear, r.nonlinear), (0.1, 0.1));
    for bad in ["", "x", "-1", "1:2:3", "1:nan", "inf"] {
        let e = Regularisation::parse(bad).unwrap_err().to_string();
        assert!(e.contains("regularisation"), "{bad}: {e}");
    }
}
