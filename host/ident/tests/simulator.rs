//! Records with a simulator's prediction (`sim_` columns): ident judges the simulator as it is.

use ocm_ident::data::{Channel, Kind, Record};
use ocm_ident::{Cause, Config, identify};
use ocm_lutgen::hysteresis::{BoucWen, BoucWenShape};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// Input steps and ramps, a simulator `sim = 3 u + 0.5 u^2`, measured = sim + `extra` + noise.
fn record(extra: impl Fn(&[f64], &mut rand_chacha::ChaCha8Rng) -> Vec<f64>, seed: u64) -> Record {
    let n = 3000;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut u = Vec::with_capacity(n);
    let (mut x, mut target) = (0.0f64, 0.0f64);
    for i in 0..n {
        if i % 60 == 0 {
            target = rng.random_range(-1.0..1.0);
        }
        x += (target - x).clamp(-0.05, 0.05);
        u.push(x);
    }
    let sim: Vec<f64> = u.iter().map(|v| 3.0 * v + 0.5 * v * v).collect();
    let e = extra(&u, &mut rng);
    let nd = Normal::new(0.0, 0.01).unwrap();
    let y: Vec<f64> = (0..n)
        .map(|i| sim[i] + e[i] + nd.sample(&mut rng))
        .collect();
    Record {
        kind: Kind::Series,
        source: "synthetic".into(),
        time_s: (0..n).map(|i| i as f64 * 0.05).collect(),
        segment_starts: vec![0],
        inputs: vec![Channel::new("u_n", "N", u)],
        outputs: vec![Channel::new("x_mm", "mm", y)],
        drives: vec![0],
        held_out: None,
        simulated: vec![Channel::new("x_mm", "mm", sim)],
        states: Vec::new(),
    }
}

#[test]
fn a_faithful_simulator_gets_none_and_the_noise_is_estimated() {
    let rec = record(|u, _| vec![0.0; u.len()], 1);
    let id = identify(&rec, &Config::default()).unwrap();
    assert_eq!(id.report.causes, [Cause::None], "{}", id.report.verdict);
    assert!(
        (id.report.noise_rmse / 0.01 - 1.0).abs() < 0.1,
        "{}",
        id.report.noise_rmse
    );
    assert_eq!(id.report.unit, "mm");
}

#[test]
fn hysteresis_on_top_of_the_simulator_is_named() {
    let rec = record(
        |u, _| {
            BoucWen::series(u, 0.1, BoucWenShape::ROUNDED)
                .iter()
                .map(|z| 0.8 * z)
                .collect()
        },
        2,
    );
    let id = identify(&rec, &Config::default()).unwrap();
    assert_eq!(
        id.report.causes,
        [Cause::Hysteresis],
        "{}",
        id.report.verdict
    );
    assert!(id.report.gain_pct > 50.0);
}

#[test]
fn a_discrepancy_no_candidate_explains_is_unexplained_never_none() {
    // a random telegraph signal of 20x the noise, independent of the input
    let rec = record(
        |u, rng| {
            let mut level = 0.2;
            (0..u.len())
                .map(|_| {
                    if rng.random::<f64>() < 0.02 {
                        level = -level;
                    }
                    level
                })
                .collect()
        },
        3,
    );
    let id = identify(&rec, &Config::default()).unwrap();
    let r = &id.report;
    assert!(!r.causes.contains(&Cause::None), "{}", r.verdict);
    assert!(r.residual_to_noise > 3.0 || r.causes == [Cause::Unexplained]);
    if r.causes == [Cause::Unexplained] {
        assert!(r.verdict.contains("unexplained"), "{}", r.verdict);
    } else {
        assert!(
            r.warnings.iter().any(|w| w.contains("unexplained")),
            "{:?}",
            r.warnings
        );
    }
}

#[test]
fn the_report_plots_the_held_out_window_first() {
    let rec = record(
        |u, _| {
            BoucWen::series(u, 0.1, BoucWenShape::ROUNDED)
                .iter()
                .map(|z| 0.8 * z)
                .collect()
        },
        4,
    );
    let id = identify(&rec, &Config::default()).unwrap();
    let dir = std::env::temp_dir().join(format!("ocm-ident-sim-{}", std::process::id()));
    let files = ocm_ident::report::write_all(&id, &dir).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert!(names.contains(&"timeline.png".to_string()), "{names:?}");
    assert!(
        names.contains(&"loops_hysteresis.png".to_string()),
        "{names:?}"
    );
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    let t = md.find("timeline.png").unwrap();
    let r = md.find("residual_vs_hysteresis.png").unwrap();
    assert!(t < r, "the timeline comes first");
    assert!(md.contains("Verdict") && md.contains("Noise RMS"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A simulator whose output is a curved function of its state: input steps and ramps, a state
/// `s` that follows `1 + u` through a first-order lag (zero when unloaded), `sim = 2 s + 0.3
/// s^2`; measured = the same function of `s` changed by `effect`, plus noise. The state is
/// given as `x_s_mm`.
fn state_record(effect: impl Fn(&[f64]) -> Vec<f64>, seed: u64) -> Record {
    let base = record(|u, _| vec![0.0; u.len()], seed);
    let u = &base.inputs[0].values;
    let mut s = Vec::with_capacity(u.len());
    let mut v = 1.0 + u[0];
    for &ui in u {
        v += 0.2 * (1.0 + ui - v);
        s.push(v);
    }
    let g = |x: f64| 2.0 * x + 0.3 * x * x;
    let changed = effect(&s);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed + 100);
    let nd = Normal::new(0.0, 0.01).unwrap();
    let y: Vec<f64> = changed
        .iter()
        .map(|x| g(*x) + nd.sample(&mut rng))
        .collect();
    Record {
        outputs: vec![Channel::new("x_mm", "mm", y)],
        simulated: vec![Channel::new(
            "x_mm",
            "mm",
            s.iter().map(|x| g(*x)).collect(),
        )],
        states: vec![Channel::new("s_mm", "mm", s)],
        ..base
    }
}

#[test]
fn effects_on_a_simulators_state_are_named_through_its_sensitivity() {
    // memory in the state: a Bouc-Wen loop on it
    let rec = state_record(
        |s| {
            let z = BoucWen::series(s, 0.1, BoucWenShape::ROUNDED);
            s.iter().zip(&z).map(|(x, z)| x - 0.3 * z).collect()
        },
        3,
    );
    let id = identify(&rec, &Config::default()).unwrap();
    let r = &id.report;
    assert_eq!(r.causes, [Cause::Hysteresis], "{}", r.verdict);
    assert!(r.gain_pct > 80.0, "{}", r.verdict);
    // the state off by a factor (about its zero): a gain, fitted on the state
    let rec = state_record(|s| s.iter().map(|x| 1.06 * x).collect(), 4);
    let id = identify(&rec, &Config::default()).unwrap();
    let r = &id.report;
    assert_eq!(r.causes, [Cause::Gain], "{}", r.verdict);
    assert!(r.gain_pct > 80.0, "{}", r.verdict);
    assert!(
        r.extension_params
            .iter()
            .any(|p| p.name.contains("state s_mm gain") && (p.value - 0.06).abs() < 0.01),
        "{:?}",
        r.extension_params
    );
}
