//! Hidden-effect records of dynamic systems, for the state-space baseline: a one- or
//! two-degree-of-freedom oscillator driven by a force and measured in displacement, or a
//! pneumatic chamber (polytropic gas fed through a laminar restriction, driving a piston with
//! mass, spring and damper) driven by its supply pressure and measured in piston travel, with an
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
    /// Pneumatic chamber: supply gauge pressure in, piston displacement out (see [`PneumaticChamber`]).
    Chamber,
}

/// The pneumatic chamber's physical parameters, SI. The chamber's gas (polytropic index
/// `n`, gas constant times temperature `rt`) is fed from the supply `p0 + u` through a
/// laminar restriction, mass flow `(p0 + u - p) / r_flow`; with volume `V = V0 + A x`,
/// `dp/dt = n / V (rt mdot - p A dx/dt)`. The piston (area `A`, moving mass `m`, spring `k`,
/// damper `c`) has the pre-charge `p0` on its back side (a large reservoir), so
/// `m d2x/dt2 = (p - p0) A - k x - c dx/dt - F_effect`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PneumaticChamber {
    /// Piston area, m^2.
    pub area_m2: f64,
    /// Chamber volume at `x = 0`, m^3.
    pub volume_m3: f64,
    /// Pre-charge (mean absolute pressure, and the piston's back side), Pa.
    pub p0_pa: f64,
    /// Polytropic index (1 isothermal, 1.4 adiabatic air).
    pub n: f64,
    /// Specific gas constant times the supply temperature, J/kg.
    pub rt_j_per_kg: f64,
    /// Laminar restriction, Pa s/kg.
    pub r_flow_pa_s_per_kg: f64,
    /// Moving mass, kg.
    pub mass_kg: f64,
    /// Spring, N/m.
    pub k_n_per_m: f64,
    /// Damper, N s/m.
    pub c_n_s_per_m: f64,
}

impl PneumaticChamber {
    /// Gas-spring stiffness at the pre-charge, `n p0 A^2 / V0`, N/m.
    pub fn gas_spring_n_per_m(&self) -> f64 {
        self.n * self.p0_pa * self.area_m2 * self.area_m2 / self.volume_m3
    }

    /// Filling time constant at the pre-charge, `V0 r_flow / (n rt)`, s.
    pub fn tau_s(&self) -> f64 {
        self.volume_m3 * self.r_flow_pa_s_per_kg / (self.n * self.rt_j_per_kg)
    }
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
    /// RMS of the clean plant's departure from its own linearisation (the chamber's gas terms
    /// frozen at the pre-charge and `V0`), over the noise RMS; 0 for the oscillators (linear).
    pub intrinsic_ratio: f64,
    /// The chamber's parameters, when the system is the chamber.
    pub chamber: Option<PneumaticChamber>,
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
    // the chamber draws its own parameters after the oscillators' (their records stay as
    // they were); the input's scale is a force for the oscillators, a pressure for the chamber
    let (plant, u_scale) = match spec.system {
        System::Chamber => {
            let ch = draw_chamber(wn, zeta, &mut rng);
            let p_amp = ch.p0_pa * rng.random_range(0.01..0.02);
            (
                Plant {
                    system: spec.system,
                    mass: ch.mass_kg,
                    k: ch.k_n_per_m,
                    c: ch.c_n_s_per_m,
                    chamber: Some(ch),
                },
                p_amp,
            )
        }
        _ => (
            Plant {
                system: spec.system,
                mass: 1.0,
                k,
                c,
                chamber: None,
            },
            k,
        ),
    };
    let k = plant.k;
    // input: random steps held 0.5-3 s, smoothed over 0.05 s, plus a slow multisine
    let mut u = vec![0.0; n];
    let mut level = 0.0;
    let mut next = 0;
    let ph: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..6.3));
    for (i, ui) in u.iter_mut().enumerate() {
        if i >= next {
            level = rng.random_range(-1.0..1.0) * u_scale;
            next = i + rng.random_range(50..300);
        }
        let t = i as f64 * DT_S;
        *ui = level
            + 0.4
                * u_scale
                * ((0.31 * t + ph[0]).sin() + (1.3 * t + ph[1]).sin() + (3.7 * t + ph[2]).sin());
    }
    let u = signal::lowpass(&u, &time(n), &[0], 0.05);
    let clean = simulate(&plant, &u, &[], false);
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
                        sigma1: 2.0 * (plant.mass * fc / (1e-2 * span)).sqrt(),
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
    let y = simulate(&plant, &u, &effects, false);
    let diff: Vec<f64> = y.iter().zip(&clean).map(|(a, b)| a - b).collect();
    let alone: Vec<f64> = if effects.len() > 1 {
        effects
            .iter()
            .map(|e| {
                let y1 = simulate(&plant, &u, std::slice::from_ref(e), false);
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
    let intrinsic = if plant.chamber.is_some() {
        let lin = simulate(&plant, &u, &[], true);
        signal::rms(
            &lin.iter()
                .zip(&clean)
                .map(|(a, b)| a - b)
                .collect::<Vec<_>>(),
        ) / noise
    } else {
        0.0
    };
    let (input, details) = match plant.chamber {
        Some(ch) => (
            Channel::new("supply_pa", "Pa", u),
            format!(
                "chamber A {:.2e} m^2, V0 {:.2e} m^3, p0 {:.0} kPa, n {:.2}, tau {:.3} s, m {:.2} kg, k {:.0} N/m (gas spring {:.0} N/m); {details}",
                ch.area_m2,
                ch.volume_m3,
                ch.p0_pa / 1e3,
                ch.n,
                ch.tau_s(),
                ch.mass_kg,
                ch.k_n_per_m,
                ch.gas_spring_n_per_m()
            ),
        ),
        None => (Channel::new("force_n", "N", u), details),
    };
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
        inputs: vec![input],
        outputs: vec![Channel::new("x_m", "m", y)],
        drives: vec![0],
        held_out: None,
        simulated: Vec::new(),
        states: Vec::new(),
        sensitivities: Vec::new(),
    };
    DynGenerated {
        record,
        ratio: signal::rms(&diff) / noise,
        ratios: alone.iter().map(|r| r / noise).collect(),
        details,
        intrinsic_ratio: intrinsic,
        chamber: plant.chamber,
    }
}

/// Draws a chamber whose mechanical natural frequency and damping ratio are `wn`, `zeta`:
/// moving mass 1-10 kg, volume 0.5-2 l, pre-charge 300-600 kPa absolute, polytropic index
/// 1-1.4, filling time constant 0.05-0.3 s, gas spring 2-5 % of the mechanical spring (which
/// sets the piston's area: bores of about 5-20 mm). The supply swings by 1-2 % of the
/// pre-charge, so the gas terms stay in their small-signal range (the piston sweeps well below
/// 1 % of the volume): the clean chamber is a third-order linear system to within a fraction
/// of the noise (`DynGenerated::intrinsic_ratio`).
fn draw_chamber(wn: f64, zeta: f64, rng: &mut ChaCha8Rng) -> PneumaticChamber {
    let mass_kg = rng.random_range(1.0..10.0);
    let volume_m3 = rng.random_range(0.5e-3..2e-3);
    let p0_pa = rng.random_range(300e3..600e3);
    let n = rng.random_range(1.0..1.4);
    let rt_j_per_kg = 287.0 * 293.15;
    let tau_s = rng.random_range(0.05..0.3);
    let gas_fraction = rng.random_range(0.02..0.05);
    let k_n_per_m = mass_kg * wn * wn;
    let area_m2 = (gas_fraction * k_n_per_m * volume_m3 / (n * p0_pa)).sqrt();
    PneumaticChamber {
        area_m2,
        volume_m3,
        p0_pa,
        n,
        rt_j_per_kg,
        r_flow_pa_s_per_kg: tau_s * n * rt_j_per_kg / volume_m3,
        mass_kg,
        k_n_per_m,
        c_n_s_per_m: 2.0 * zeta * wn * mass_kg,
    }
}

/// The plant the effects act in: the oscillators (unit masses) or the chamber's piston.
struct Plant {
    system: System,
    /// Mass the effects act on, kg.
    mass: f64,
    /// Spring, N/m.
    k: f64,
    /// Damper, N s/m.
    c: f64,
    chamber: Option<PneumaticChamber>,
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

/// Semi-implicit Euler on substeps; returns the measured displacement (the last mass, or the
/// piston). The effects act together (their forces add; a delay shifts the input) on the first
/// mass or the piston. `linearised`: the chamber's gas terms frozen at the pre-charge and `V0`.
fn simulate(plant: &Plant, u: &[f64], effects: &[Effect], linearised: bool) -> Vec<f64> {
    let (k, c, m) = (plant.k, plant.c, plant.mass);
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
    // the chamber's absolute pressure, starting at the pre-charge
    let mut p = plant.chamber.map_or(0.0, |ch| ch.p0_pa);
    // one Bouc-Wen and one LuGre state per effect (unused by the others)
    let mut bw = vec![BoucWen::default(); effects.len()];
    let mut z = vec![0.0f64; effects.len()];
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        out.push(match plant.system {
            System::Oscillator1 | System::Chamber => x1,
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
            let (a1, a2) = match plant.system {
                System::Oscillator1 => (input[i] - c * v1 - k * x1 - extra, 0.0),
                System::Chamber => {
                    let area = plant.chamber.map_or(0.0, |ch| ch.area_m2);
                    let p0 = plant.chamber.map_or(0.0, |ch| ch.p0_pa);
                    (((p - p0) * area - c * v1 - k * x1 - extra) / m, 0.0)
                }
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
            if let Some(ch) = plant.chamber {
                let (volume, p_gas) = if linearised {
                    (ch.volume_m3, ch.p0_pa)
                } else {
                    (ch.volume_m3 + ch.area_m2 * x1, p)
                };
                let mdot = (ch.p0_pa + input[i] - p) / ch.r_flow_pa_s_per_kg;
                p += h * ch.n / volume * (ch.rt_j_per_kg * mdot - p_gas * ch.area_m2 * v1);
            }
            for (j, effect) in effects.iter().enumerate() {
                if let Effect::BoucWen { z0, shape, .. } = effect {
                    bw[j].step(dx / z0, *shape);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chamber_plant(seed: u64) -> Plant {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let ch = draw_chamber(2.0 * std::f64::consts::PI, 0.1, &mut rng);
        Plant {
            system: System::Chamber,
            mass: ch.mass_kg,
            k: ch.k_n_per_m,
            c: ch.c_n_s_per_m,
            chamber: Some(ch),
        }
    }

    #[test]
    fn chamber_settles_where_the_supply_pressure_balances_the_spring() {
        // at rest the restriction carries no flow, so p = p0 + u and k x = u A: the gas
        // spring acts only while the piston moves
        for seed in 0..4 {
            let plant = chamber_plant(seed);
            let ch = plant.chamber.unwrap();
            let u_pa = 0.015 * ch.p0_pa;
            let x = simulate(&plant, &vec![u_pa; 3000], &[], false);
            let expected = u_pa * ch.area_m2 / ch.k_n_per_m;
            let last = *x.last().unwrap();
            assert!(
                (last - expected).abs() < 1e-4 * expected,
                "seed {seed}: {last} against {expected}"
            );
            // the gas and the damper make it overshoot and ring first: it is dynamic
            let peak = x.iter().cloned().fold(f64::MIN, f64::max);
            assert!(peak > 1.05 * expected, "seed {seed}: peak {peak}");
        }
    }

    #[test]
    fn chamber_small_signal_and_clean_records_are_linear_to_below_the_noise() {
        for seed in 0..6 {
            let g = generate(&DynSpec {
                system: System::Chamber,
                effects: vec![Cause::None],
                seed,
                rows: 2000,
            });
            let ch = g.chamber.unwrap();
            assert!(
                g.intrinsic_ratio > 0.0 && g.intrinsic_ratio < 0.2,
                "seed {seed}: {} ({})",
                g.intrinsic_ratio,
                g.details
            );
            // the piston sweeps a small share of the chamber
            let x = &g.record.outputs[0].values;
            let stroke = x.iter().cloned().fold(f64::MIN, f64::max)
                - x.iter().cloned().fold(f64::MAX, f64::min);
            assert!(stroke * ch.area_m2 < 1e-2 * ch.volume_m3, "seed {seed}");
        }
    }
}
