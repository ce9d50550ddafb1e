//! The pose pipeline end to end on records made with the quasi-static segment model: the
//! stiffness scale is recovered on clean data, no cause is named, and a hidden output lag is
//! named as latency.

use ocm_ident::data::{Channel, Kind, Record, parse_csv, write_csv};
use ocm_ident::manipulator::Segment;
use ocm_ident::physics::Physics;
use ocm_ident::signal;
use ocm_ident::{Cause, Config, identify};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn pose_record(seed: u64, stiffness: f64, lag_s: f64) -> Record {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 1500;
    let dt = 0.05;
    let time_s: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    // three pressures stepping between random levels with 0.5 s ramps, varying load
    let mut p = vec![vec![0.0; n]; 3];
    for ch in p.iter_mut() {
        let mut x = 0.0;
        let mut i = 0;
        while i < n {
            let target = rng.random_range(0.0..1500.0);
            for k in 0..10 {
                if i + k < n {
                    ch[i + k] = x + (target - x) * (k + 1) as f64 / 10.0;
                }
            }
            i += 10;
            let hold = rng.random_range(20..60);
            for _ in 0..hold {
                if i < n {
                    ch[i] = target;
                    i += 1;
                }
            }
            x = target;
        }
    }
    let load: Vec<f64> = (0..n).map(|i| 0.3 * (i as f64 * 0.01).sin()).collect();
    let seg = Segment::new(Physics::table_3_1(), stiffness);
    let mut xyz = vec![vec![0.0; n]; 3];
    for i in 0..n {
        let t = seg.tip_for([p[0][i], p[1][i], p[2][i]], load[i]);
        for c in 0..3 {
            xyz[c][i] = t[c];
        }
    }
    let noise = Normal::new(0.0, 2e-4).unwrap();
    let outs: Vec<Vec<f64>> = xyz
        .iter()
        .map(|v| {
            let lagged = if lag_s > 0.0 {
                signal::lowpass(v, &time_s, &[0], lag_s)
            } else {
                v.clone()
            };
            lagged.iter().map(|x| x + noise.sample(&mut rng)).collect()
        })
        .collect();
    Record {
        kind: Kind::Pose,
        source: format!("pose:{seed}"),
        time_s,
        segment_starts: vec![0],
        inputs: vec![
            Channel::new("p1", "Pa", p[0].clone()),
            Channel::new("p2", "Pa", p[1].clone()),
            Channel::new("p3", "Pa", p[2].clone()),
            Channel::new("load", "N", load),
        ],
        outputs: vec![
            Channel::new("x", "m", outs[0].clone()),
            Channel::new("y", "m", outs[1].clone()),
            Channel::new("z", "m", outs[2].clone()),
        ],
        drives: vec![0, 1, 2],
        held_out: None,
        simulated: Vec::new(),
        states: Vec::new(),
        sensitivities: Vec::new(),
    }
}

#[test]
fn clean_pose_data_recovers_stiffness_and_names_nothing() {
    let rec = pose_record(11, 1.3, 0.0);
    // through the CSV schema (mm, kPa) and back
    let dir = std::env::temp_dir().join(format!("ocm-ident-pose-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("pose.csv");
    write_csv(&rec, &path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("time_s,p1_kpa,p2_kpa,p3_kpa,load_n,x_mm,y_mm,z_mm"));
    let back = parse_csv(&text, "pose.csv", Kind::Pose).unwrap();
    let id = identify(&back, &Config::default()).unwrap();
    let scale = id
        .report
        .baseline_params
        .iter()
        .find(|p| p.name == "stiffness scale")
        .unwrap()
        .value;
    assert!((scale - 1.3).abs() < 0.02, "stiffness scale {scale}");
    assert_eq!(
        id.report.causes,
        vec![Cause::None],
        "{:?}",
        id.report.candidates
    );
    // the baseline RMSE is the noise level (0.2 mm)
    assert!(
        id.report.baseline_rmse < 2.6e-4,
        "{}",
        id.report.baseline_rmse
    );
}

#[test]
fn lagged_pose_data_names_latency() {
    let rec = pose_record(12, 0.9, 0.4);
    let id = identify(&rec, &Config::default()).unwrap();
    assert_eq!(
        id.report.causes[0],
        Cause::Latency,
        "{:?}",
        id.report.candidates
    );
    assert!(id.report.gain_pct > 50.0, "{}", id.report.gain_pct);
    let get = |prefix: &str| {
        id.report
            .extension_params
            .iter()
            .find(|p| p.name.starts_with(prefix))
            .unwrap()
            .value
    };
    // The stiffness scale is fitted on the lagged data and not refitted, so the lag splits
    // between dead time and time constant; their sum (the mean delay of the chain) is 0.4 s.
    let delay = get("dead time") + get("lag time constant");
    assert!((delay - 0.4).abs() < 0.1, "mean delay {delay}");
}

/// The diagnostics run on every output channel of a pose record and read the hidden effect's
/// signature: a lagging column strain (hysteresis, viscosity) pulls the tip against its motion,
/// so the residual is negative while the column strains load the tip; a lagged pose peaks later.
#[test]
fn pose_diagnostics_cover_every_channel_and_read_the_signature() {
    use ocm_ident::synth::{Spec, generate};
    let diag = |cause: Cause, of: Cause| -> Vec<f64> {
        let g = generate(&Spec {
            kind: Kind::Pose,
            effects: vec![cause],
            seed: 5,
            rows: 2000,
            ratio: (8.0, 8.0),
        });
        let id = identify(&g.record, &Config::default()).unwrap();
        assert_eq!(id.report.causes, vec![cause], "{:?}", g.details);
        // seven statistics per output channel, each naming its channel
        assert_eq!(id.report.diagnostics.len(), 21);
        for name in ["[x]", "[y]", "[z]"] {
            let n = id
                .report
                .diagnostics
                .iter()
                .filter(|d| d.statistic.ends_with(name) && d.value.is_finite())
                .count();
            assert_eq!(n, 7, "{name}");
        }
        id.report
            .diagnostics
            .iter()
            .filter(|d| d.cause == of)
            .map(|d| d.value)
            .collect()
    };
    let h = diag(Cause::Hysteresis, Cause::Hysteresis);
    assert!(h.iter().all(|v| *v < 0.0), "loading minus unloading {h:?}");
    let r = diag(Cause::RateDependence, Cause::RateDependence);
    assert!(r.iter().all(|v| *v < 0.0), "rate correlation {r:?}");
    let l = diag(Cause::Latency, Cause::Latency);
    assert!(l.iter().any(|v| *v > 0.0), "peak lag {l:?}");
}
