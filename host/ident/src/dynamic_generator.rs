//! Hidden-effect records of dynamic systems, for the state-space baseline: a one- or
//! two-degree-of-freedom oscillator driven by a force and measured in displacement, with an
//! effect inside the dynamics generated in a form other than the extensions (Bouc-Wen
//! restoring force of random shape, LuGre friction, a transport delay interpolated between
//! samples, cubic stiffening), or two of them at once. Everything follows from the seed.

use ocm_lutgen::hysteresis::{BoucWen, BoucWenShape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::cause::Cause;
use crate::data::{Channel, Kind, Record};
use crate::signal;

/// Sampling interval, seconds.
pub const DT_S: f64 = 0.01;
/// Integration substeps per sample.
const SUBSTEPS: usize = 20;

/// The dynamic systems of the battery.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum System {
    /// Mass-spring-damper, force in, displacement out.
    Oscillator1,
    /// Two masses in series; force on the first, displacement of the second measured.
    Oscillator2,
}

/// What to generate.
#[derive(Debug, Clone)]
pub struct DynSpec {
    /// The system.
    pub system: System,
    /// The hidden effects, acting together (empty or `[None]` for a clean control); a
    /// cause given twice acts once.
    pub effects: Vec<Cause>,
    /// Seed.
    pub seed: u64,
    /// Rows.
    pub rows: usize,
}

/// A generated record with what was hidden.
#[derive(Debug, Clone)]
pub struct DynGenerated {
    /// The record (`series`: `u_force_n`, `y_x_m`).
    pub record: Record,
    /// Effect RMS on the output over noise RMS (all effects together).
    pub ratio: f64,
    /// Per hidden effect, in the order given: its RMS on the output when it acts alone, over
    /// the noise RMS.
    pub ratios: Vec<f64>,
    /// Parameters drawn, in words.
    pub details: String,
}

/// The effects the battery hides. A transport delay can be generated too
/// ([`Cause::Latency`]), but a linear state-space baseline absorbs it (a delay is linear
/// dynamics): ident names nothing, see the README.
pub const EFFECTS: [Cause; 3] = [Cause::Hysteresis, Cause::Friction, Cause::Nonlinearity];

/// Generates one record.
pub fn generate(spec: &DynSpec) -> DynGenerated {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let n = spec.rows.max(500);
    // natural frequencies 0.5-2 Hz, damping ratio 0.05-0.2, unit masses
    let wn: f64 = 2.0 * std::f64::consts::PI * rng.random_range(0.5..2.0);
    let zeta: f64 = rng.random_range(0.05..0.2);
    let (k, c) = (wn * wn, 2.0 * zeta * wn);
    // input: random steps held 0.5-3 s, smoothed over 0.05 s, plus a slow multisine
    let mut u = vec![0.0; n];
    let mut level = 0.0;
    let mut next = 0;
    let ph: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..6.3));
    for (i, ui) in u.iter_mut().enumerate() {
        if i >= next {
            level = rng.random_range(-1.0..1.0) * k;
            next = i + rng.random_range(50..300);
        }
        let t = i as f64 * DT_S;
        *ui = level
            + 0.4
                * k
                * ((0.31 * t + ph[0]).sin() + (1.3 * t + ph[1]).sin() + (3.7 * t + ph[2]).sin());
    }
    let u = signal::lowpass(&u, &time(n), &[0], 0.05);
    let clean = simulate(spec.system, k, c, &u, &[]);
    let span = signal::mean_std(&clean).1;
    let draw = |cause: Cause, rng: &mut ChaCha8Rng| -> (Effect, String) {
        match cause {
            Cause::Hysteresis => {
                let beta = rng.random_range(0.2..0.8);
                let z0 = span * rng.random_range(0.05..0.3);
                let alpha = rng.random_range(0.1..0.4);
                (
                    Effect::BoucWen {
                        force: alpha * k * z0,
                        z0,
                        shape: BoucWenShape {
                            beta,
                            gamma: 1.0 - beta,
                        },
                    },
                    format!(
                        "Bouc-Wen restoring force, beta {beta:.2}, travel {z0:.3e}, {alpha:.2} k z0"
                    ),
                )
            }
            Cause::Friction => {
                let fc = k * span * rng.random_range(0.05..0.2);
                let fs = fc * rng.random_range(1.1..1.6);
                let vs = wn * span * rng.random_range(0.05..0.2);
                (
                    Effect::LuGre {
                        fc,
                        fs,
                        vs,
                        sigma0: fc / (1e-2 * span),
                        sigma1: 2.0 * (fc / (1e-2 * span)).sqrt(),
                        sigma2: 0.0,
                    },
                    format!("LuGre friction Fc {fc:.3e}, Fs {fs:.3e}, vs {vs:.3e}"),
                )
            }
            Cause::Latency => {
                let d = rng.random_range(2.3..12.7);
                (
                    Effect::Delay(d),
                    format!("transport delay {:.3} s (interpolated)", d * DT_S),
                )
            }
            Cause::Nonlinearity => {
                let k3 = k / (span * span) * rng.random_range(0.1..0.4);
                (Effect::Cubic(k3), format!("cubic stiffening k3 {k3:.3e}"))
            }
            _ => (Effect::None, "clean".into()),
        }
    };
    let mut effects = Vec::new();
    let mut details = Vec::new();
    let mut seen = Vec::new();
    for &cause in &spec.effects {
        if cause == Cause::None || seen.contains(&cause) {
            continue;
        }
        seen.push(cause);
        let (e, d) = draw(cause, &mut rng);
        if !matches!(e, Effect::None) {
            effects.push(e);
            details.push(d);
        }
    }
    let details = if details.is_empty() {
        "clean".to_string()
    } else {
        details.join("; ")
    };
    let y = simulate(spec.system, k, c, &u, &effects);
    let diff: Vec<f64> = y.iter().zip(&clean).map(|(a, b)| a - b).collect();
    let alone: Vec<f64> = if effects.len() > 1 {
        effects
            .iter()
            .map(|e| {
                let y1 = simulate(spec.system, k, c, &u, std::slice::from_ref(e));
                signal::rms(
                    &y1.iter()
                        .zip(&clean)
                        .map(|(a, b)| a - b)
                        .collect::<Vec<_>>(),
                )
            })
            .collect()
    } else {
        vec![signal::rms(&diff); effects.len()]
    };
    // noise: 0.3-1 % of the response's spread (a good displacement sensor)
    let noise = span * rng.random_range(0.003..0.01);
    let nd = Normal::new(0.0, noise).expect("positive noise");
    let y: Vec<f64> = y.iter().map(|v| v + nd.sample(&mut rng)).collect();
    let record = Record {
        kind: Kind::Series,
        source: format!(
            "{:?} {} seed {}",
            spec.system,
            spec.effects
                .iter()
                .map(|c| c.name())
                .collect::<Vec<_>>()
                .join("+"),
            spec.seed
        ),
        time_s: time(n),
        segment_starts: vec![0],
        inputs: vec![Channel::new("force_n", "N", u)],
        outputs: vec![Channel::new("x_m", "m", y)],
        drives: vec![0],
        held_out: None,
        simulated: Vec::new(),
        states: Vec::new(),
    };
    DynGenerated {
        record,
        ratio: signal::rms(&diff) / noise,
        ratios: alone.iter().map(|r| r / noise).collect(),
        details,
    }
}

fn time(n: usize) -> Vec<f64> {
    (0..n).map(|i| i as f64 * DT_S).collect()
}

/// An effect inside the dynamics.
enum Effect {
    None,
    BoucWen {
        force: f64,
        z0: f64,
        shape: BoucWenShape,
    },
    LuGre {
        fc: f64,
        fs: f64,
        vs: f64,
        sigma0: f64,
        sigma1: f64,
        sigma2: f64,
    },
    Delay(f64),
    Cubic(f64),
}

/// Semi-implicit Euler on substeps; returns the measured displacement (the last mass). The
/// effects act together (their forces add; a delay shifts the input).
fn simulate(system: System, k: f64, c: f64, u: &[f64], effects: &[Effect]) -> Vec<f64> {
    let n = u.len();
    let h = DT_S / SUBSTEPS as f64;
    let mut input = u.to_vec();
    for e in effects {
        if let Effect::Delay(d) = *e {
            input = (0..n)
                .map(|i| {
                    let t = i as f64 - d;
                    if t <= 0.0 {
                        u[0]
                    } else {
                        let a = t.floor() as usize;
                        let f = t - t.floor();
                        u[a] * (1.0 - f) + u[(a + 1).min(n - 1)] * f
                    }
                })
                .collect();
        }
    }
    let (mut x1, mut v1, mut x2, mut v2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    // one Bouc-Wen and one LuGre state per effect (unused by the others)
    let mut bw = vec![BoucWen::default(); effects.len()];
    let mut z = vec![0.0f64; effects.len()];
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        out.push(match system {
            System::Oscillator1 => x1,
            System::Oscillator2 => x2,
        });
        for _ in 0..SUBSTEPS {
            // the effects act on the first mass (where the force is applied)
            let mut extra = 0.0;
            for (j, effect) in effects.iter().enumerate() {
                extra += match *effect {
                    Effect::BoucWen { force, .. } => force * bw[j].z,
                    Effect::LuGre {
                        fc,
                        fs,
                        vs,
                        sigma0,
                        sigma1,
                        sigma2,
                    } => {
                        let g = fc + (fs - fc) * (-(v1 / vs).powi(2)).exp();
                        let dz = v1 - sigma0 * v1.abs() / g * z[j];
                        let f = sigma0 * z[j] + sigma1 * dz + sigma2 * v1;
                        z[j] += h * dz;
                        // the bristle state relaxes within a substep at high stiffness
                        z[j] = z[j].clamp(-fs / sigma0, fs / sigma0);
                        f
                    }
                    Effect::Cubic(k3) => k3 * x1.powi(3),
                    _ => 0.0,
                };
            }
            let (a1, a2) = match system {
                System::Oscillator1 => (input[i] - c * v1 - k * x1 - extra, 0.0),
                System::Oscillator2 => (
                    input[i] - c * v1 - k * x1 - k * (x1 - x2) - c * (v1 - v2) - extra,
                    k * (x1 - x2) + c * (v1 - v2) - 0.5 * k * x2 - 0.5 * c * v2,
                ),
            };
            v1 += h * a1;
            v2 += h * a2;
            let dx = h * v1;
            x1 += dx;
            x2 += h * v2;
            for (j, effect) in effects.iter().enumerate() {
                if let Effect::BoucWen { z0, shape, .. } = effect {
                    bw[j].step(dx / z0, *shape);
                }
            }
        }
    }
    out
}
