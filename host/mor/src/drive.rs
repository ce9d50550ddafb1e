//! Seeded random inputs as a user drives the robot: chamber pressures in -20..35 kPa made of steps,
//! ramps and holds, and a tip force of at most 2 N that is held, ramped or released.
//!
//! Sequence `k` of seed `s` draws from the ChaCha8 streams 4k..4k+3 of seed `s`, so any sequence can be
//! generated alone (shards of a dataset) and is the same in every run.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Lowest chamber pressure, kPa (the actuator range of Ch.4.4).
pub const P_MIN_KPA: f64 = -20.0;
/// Highest chamber pressure, kPa.
pub const P_MAX_KPA: f64 = 35.0;

/// Ranges of the random inputs.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct DriveConfig {
    /// Time step, s.
    pub dt_s: f64,
    /// Largest tip-force magnitude, N.
    pub max_tip_force_n: f64,
    /// Shortest segment (step, ramp or hold), s.
    pub min_segment_s: f64,
    /// Longest segment, s.
    pub max_segment_s: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        DriveConfig {
            dt_s: 0.01,
            max_tip_force_n: 2.0,
            min_segment_s: 0.1,
            max_segment_s: 0.8,
        }
    }
}

/// Inputs of one time step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Input {
    /// Chamber pressures, kPa.
    pub pressure_kpa: [f64; 3],
    /// Tip force in the mesh frame, N.
    pub tip_force_n: [f64; 3],
}

fn segment_steps(rng: &mut ChaCha8Rng, cfg: &DriveConfig) -> usize {
    let s = rng.random_range(cfg.min_segment_s..=cfg.max_segment_s);
    ((s / cfg.dt_s).round() as usize).max(1)
}

/// Piecewise path of one scalar channel: steps (jump, then hold), ramps and holds.
fn channel(
    rng: &mut ChaCha8Rng,
    cfg: &DriveConfig,
    steps: usize,
    draw: &mut dyn FnMut(&mut ChaCha8Rng) -> Vec<f64>,
    start: Vec<f64>,
) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(steps);
    let mut cur = start;
    while out.len() < steps {
        let n = segment_steps(rng, cfg);
        let kind = rng.random_range(0..3u8);
        let target = if kind == 2 { cur.clone() } else { draw(rng) };
        for j in 0..n {
            let v: Vec<f64> = match kind {
                // Ramp: linear to the target over the segment.
                1 => cur
                    .iter()
                    .zip(&target)
                    .map(|(a, b)| a + (b - a) * (j + 1) as f64 / n as f64)
                    .collect(),
                // Step (jump) or hold.
                _ => target.clone(),
            };
            out.push(v);
        }
        cur = target;
    }
    out.truncate(steps);
    out
}

/// The input sequence `index` of `seed`, `steps` long.
pub fn sequence(cfg: &DriveConfig, seed: u64, index: u64, steps: usize) -> Vec<Input> {
    // Each channel (three chambers, the force) draws from its own stream, so a longer sequence
    // extends a shorter one.
    let stream = |c: u64| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(4 * index + c);
        rng
    };
    let chambers: Vec<Vec<Vec<f64>>> = (0..3)
        .map(|c| {
            channel(
                &mut stream(c),
                cfg,
                steps,
                &mut |r| vec![r.random_range(P_MIN_KPA..=P_MAX_KPA)],
                vec![0.0],
            )
        })
        .collect();
    let fmax = cfg.max_tip_force_n;
    let force = channel(
        &mut stream(3),
        cfg,
        steps,
        &mut |r| {
            // Half of the targets release the tip; the others push with a uniform direction.
            if r.random_bool(0.5) {
                return vec![0.0; 3];
            }
            let z: f64 = r.random_range(-1.0..=1.0);
            let phi: f64 = r.random_range(0.0..std::f64::consts::TAU);
            let s = (1.0 - z * z).sqrt();
            let m = r.random_range(0.0..=fmax);
            vec![m * s * phi.cos(), m * s * phi.sin(), m * z]
        },
        vec![0.0; 3],
    );
    (0..steps)
        .map(|k| Input {
            pressure_kpa: [chambers[0][k][0], chambers[1][k][0], chambers[2][k][0]],
            tip_force_n: [force[k][0], force[k][1], force[k][2]],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequences_are_seeded_bounded_and_varied() {
        let cfg = DriveConfig::default();
        let a = sequence(&cfg, 7, 3, 500);
        assert_eq!(
            a,
            sequence(&cfg, 7, 3, 500),
            "same seed and index, same inputs"
        );
        assert_ne!(a, sequence(&cfg, 7, 4, 500));
        assert_ne!(a, sequence(&cfg, 8, 3, 500));
        let mut holds = 0;
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for w in a.windows(2) {
            for k in 0..3 {
                let p = w[1].pressure_kpa[k];
                assert!((P_MIN_KPA..=P_MAX_KPA).contains(&p));
                lo = lo.min(p);
                hi = hi.max(p);
                holds += usize::from(w[0].pressure_kpa[k] == p);
            }
            let f = w[1].tip_force_n;
            assert!((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt() <= 2.0 + 1e-12);
        }
        assert!(hi - lo > 30.0, "pressures explore the range: {lo}..{hi}");
        assert!(
            holds > 100 && holds < 3 * 499,
            "holds and changes both occur"
        );
        assert!(a.iter().any(|i| i.tip_force_n != [0.0; 3]));
        // A prefix of a longer sequence is the shorter sequence.
        assert_eq!(&sequence(&cfg, 7, 3, 800)[..500], &a[..]);
    }
}
