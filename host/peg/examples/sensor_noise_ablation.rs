//! Which of the perception's errors a cloned touch policy tolerates: the policies of
//! `ocm peg train DIR` evaluated with the real-frame centroid error alone, the rotation error
//! alone and both, at several multiples, on 100 trials of seeds 1000 and 2000, optionally with
//! the latents low-passed (time constant in seconds, the second argument) and the errors
//! correlated in time (correlation time in seconds or `inf`, the third), at the multiples of the
//! real-frame errors given as the fourth (comma-separated; default 0.25,0.5,1,8).
//!
//! `cargo run -p ocm-peg --example sensor_noise_ablation -- out/peg/rigid [0.1 [inf [0.1,0.25]]]`

use ocm_peg::{
    BcPolicy, ContactFeatures, Randomisation, SceneConfig, SensorNoise, TrialSpec, evaluate_policy,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .ok_or("usage: sensor_noise_ablation POLICY_DIR")?;
    let policy = BcPolicy::load(&std::path::Path::new(&dir).join("policy_touch.ckpt"))?;
    let tau: f64 = match std::env::args().nth(2) {
        Some(t) => t.parse()?,
        None => 0.0,
    };
    let correlation_s: f64 = match std::env::args().nth(3) {
        Some(t) => t.parse()?,
        None => 0.0,
    };
    let scales: Vec<f64> = match std::env::args().nth(4) {
        Some(list) => list
            .split(',')
            .map(|v| v.trim().parse())
            .collect::<Result<_, _>>()?,
        None => vec![0.25, 0.5, 1.0, 8.0],
    };
    let real = SensorNoise::perception_on_real_frames();
    println!("| errors | scale | success, seed 1000 / 2000 | median time to insert, s |");
    println!("|---|---|---|---|");
    for (name, base) in [
        (
            "centroid only",
            SensorNoise {
                centroid_m: real.centroid_m,
                ..Default::default()
            },
        ),
        (
            "rotation only",
            SensorNoise {
                rotation_rad: real.rotation_rad,
                ..Default::default()
            },
        ),
        ("centroid and rotation", real),
    ] {
        for &scale in &scales {
            let noise = base.scaled(scale).correlated(correlation_s);
            let scene = SceneConfig {
                sensor_noise: noise,
                touch_filter_s: tau,
                ..policy.meta.scene.clone().unwrap_or_default()
            };
            let mut cells = Vec::new();
            let mut times = Vec::new();
            for seed in [1000, 2000] {
                let ev = evaluate_policy(
                    "touch",
                    &policy,
                    TrialSpec {
                        scene: &scene,
                        randomisation: &Randomisation::default(),
                        seed,
                        trials: 100,
                    },
                    &ContactFeatures,
                    &mut |_| {},
                )?;
                cells.push(format!("{:.0} %", 100.0 * ev.success_rate()));
                times.push(format!("{:.2}", ev.median_success_time_s()));
            }
            println!(
                "| {name} | {scale} | {} | {} |",
                cells.join(" / "),
                times.join(" / ")
            );
        }
    }
    Ok(())
}
