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
        sensitivities: Vec::new(),
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
        sensitivities: Vec::new(),
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

/// A two-output simulator whose states each follow one input, the inputs on a circle (as the
/// lab's pressures are): states `x_j = g(u_j)`, outputs `a = x1 + x2 + 0.2 x1 x2` and
/// `b = x1 - x2 + 0.1 x1^2`, with their sensitivities logged as `dsim_` columns. The measured
/// run has `effect` applied to the states; returns the record.
fn two_output_record(effect: impl Fn(usize, f64, f64) -> f64, seed: u64) -> Record {
    let n = 3000;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let nd = Normal::new(0.0, 1e-3).unwrap();
    let g = |u: f64| u + 0.3 * u * u;
    let f = |x: [f64; 2]| {
        [
            x[0] + x[1] + 0.2 * x[0] * x[1],
            x[0] - x[1] + 0.1 * x[0] * x[0],
        ]
    };
    let (mut u1, mut u2, mut sa, mut sb, mut ya, mut yb) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut x1, mut x2) = (vec![], vec![]);
    let mut dsim = vec![Vec::new(); 4];
    for i in 0..n {
        let t = i as f64 * 0.01;
        let u = [(0.7 * t).cos(), (0.7 * t).sin()];
        let x = [g(u[0]), g(u[1])];
        let xm = [effect(0, u[0], x[0]), effect(1, u[1], x[1])];
        let (s, m) = (f(x), f(xm));
        u1.push(u[0]);
        u2.push(u[1]);
        x1.push(x[0]);
        x2.push(x[1]);
        sa.push(s[0]);
        sb.push(s[1]);
        ya.push(m[0] + nd.sample(&mut rng));
        yb.push(m[1] + nd.sample(&mut rng));
        // d a / d x, d b / d x
        dsim[0].push(1.0 + 0.2 * x[1]);
        dsim[1].push(1.0 + 0.2 * x[0]);
        dsim[2].push(1.0 + 0.2 * x[0]);
        dsim[3].push(-1.0);
    }
    let sensitivities = dsim
        .into_iter()
        .enumerate()
        .map(|(k, values)| ocm_ident::data::Sensitivity {
            output: k / 2,
            state: k % 2,
            values,
        })
        .collect();
    Record {
        kind: Kind::Series,
        source: "two-output synthetic".into(),
        time_s: (0..n).map(|i| i as f64 * 0.01).collect(),
        segment_starts: vec![0],
        inputs: vec![Channel::new("u1", "-", u1), Channel::new("u2", "-", u2)],
        outputs: vec![
            Channel::new("a_mm", "mm", ya),
            Channel::new("b_mm", "mm", yb),
        ],
        drives: vec![0, 1],
        held_out: None,
        simulated: vec![
            Channel::new("a_mm", "mm", sa),
            Channel::new("b_mm", "mm", sb),
        ],
        states: vec![Channel::new("x1", "-", x1), Channel::new("x2", "-", x2)],
        sensitivities,
    }
}

/// With the sensitivities logged, an input's offset and a state's gain are one parameter for
/// both outputs, and on inputs that lie on a circle the two are told apart: each is named
/// alone, with its parameters recovered (an input offset reaches a state through the state's
/// slope in its own input, a cubic in that input alone).
#[test]
fn logged_sensitivities_tell_an_input_offset_from_a_state_gain() {
    let g = |u: f64| u + 0.3 * u * u;
    let cases: [(Cause, &str, [f64; 2]); 2] = [
        (Cause::Offset, "u1 bias", [0.02, -0.015]),
        (Cause::Gain, "state x1 gain - 1", [0.03, -0.025]),
    ];
    for (cause, first, truth) in cases {
        let rec = two_output_record(
            |j, u, x| match cause {
                Cause::Offset => g(u + truth[j]),
                _ => (1.0 + truth[j]) * x,
            },
            11,
        );
        let id = identify(&rec, &Config::default()).unwrap();
        let r = &id.report;
        assert_eq!(r.causes, [cause], "{}", r.verdict);
        assert!(r.gain_pct > 90.0, "{}", r.verdict);
        let params = &r.extension_params;
        // one parameter for both outputs: named without an output
        let p = params
            .iter()
            .find(|p| p.name == first)
            .unwrap_or_else(|| panic!("{first} not among {params:?}"));
        assert!(
            (p.value / truth[0] - 1.0).abs() < 0.1,
            "{first} = {} against {}",
            p.value,
            truth[0]
        );
        assert!(
            !params
                .iter()
                .any(|p| p.name.starts_with(first) && p.name != first),
            "{params:?}"
        );
    }
}
