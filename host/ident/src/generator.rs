//! Measured-like data with hidden effects, for blind tests of the identification.
//!
//! A record is made from the clean model (the energy model for `axial` and `bending`, a random
//! affine map for `series`, the segment model for `pose`, see [`crate::pose_generator`]) driven by a rich identification protocol: ramps at rates spread
//! over a decade and more, reversals at random amplitudes, holds, and stepped pressures. The
//! true stiffness scales are drawn at random, then zero, one or two effects are added, each
//! scaled so that its *visible* part (what the baseline's free parameters cannot absorb) has
//! a chosen RMS relative to the white measurement noise. Everything follows from the seed.

use ocm_lutgen::hysteresis::{BoucWen, BoucWenShape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::cause::Cause;
use crate::data::{Channel, Kind, Record};
use crate::lsq;
use crate::physics::Physics;
use crate::signal;

/// What to generate.
#[derive(Debug, Clone)]
pub struct Spec {
    /// Record kind.
    pub kind: Kind,
    /// Hidden effects (empty for a clean control).
    pub effects: Vec<Cause>,
    /// Seed of every random choice.
    pub seed: u64,
    /// Number of rows.
    pub rows: usize,
    /// Range of the visible-effect to noise RMS ratio, drawn log-uniformly.
    pub ratio: (f64, f64),
}

/// A generated record and the truth behind it.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The record.
    pub record: Record,
    /// Hidden effects.
    pub effects: Vec<Cause>,
    /// Visible-effect RMS over noise RMS, per effect.
    pub ratios: Vec<f64>,
    /// Noise standard deviation.
    pub noise: f64,
    /// Short description of each effect's form and magnitude.
    pub details: Vec<String>,
    /// The visible part of all hidden effects per row (effect minus its least-squares
    /// projection on the baseline's free regressors); for `pose`, the RMS over `x, y, z`.
    pub visible: Vec<f64>,
}

pub(crate) const DT_S: f64 = 0.05;

struct Scenario {
    inputs: Vec<Vec<f64>>,
    names: Vec<(&'static str, &'static str)>,
    drive: usize,
    secondary: Option<usize>,
}

/// Ramp-hold-reverse protocol for one drive inside `[lo, hi]`.
pub(crate) fn drive_protocol(rng: &mut ChaCha8Rng, n: usize, lo: f64, hi: f64) -> Vec<f64> {
    let mut u = Vec::with_capacity(n);
    let mut x = 0.5 * (lo + hi);
    let mut up = true;
    while u.len() < n {
        let span = hi - lo;
        let target = if up {
            rng.random_range(x.max(lo + 0.3 * span)..=hi)
        } else {
            rng.random_range(lo..=x.min(hi - 0.3 * span))
        };
        // rates spread over a factor 30: a full span in 0.6 s .. 18 s
        let rate = span / (0.6 * 30f64.powf(rng.random::<f64>()));
        let steps = (((target - x).abs() / rate) / DT_S).ceil().max(1.0) as usize;
        for k in 1..=steps {
            u.push(x + (target - x) * k as f64 / steps as f64);
        }
        x = target;
        if rng.random::<f64>() < 0.5 {
            let hold = (rng.random_range(0.5..4.0) / DT_S) as usize;
            u.extend(std::iter::repeat_n(x, hold));
        }
        up = !up;
    }
    u.truncate(n);
    u
}

/// Stepped level sequence (pressures, initial strains): a new level every few seconds,
/// reached by a 1 s ramp.
pub(crate) fn stepped(
    rng: &mut ChaCha8Rng,
    n: usize,
    lo: f64,
    hi: f64,
    hold_s: (f64, f64),
) -> Vec<f64> {
    let mut u = Vec::with_capacity(n);
    let mut x = rng.random_range(lo..=hi);
    while u.len() < n {
        let target = rng.random_range(lo..=hi);
        let ramp = (1.0 / DT_S) as usize;
        for k in 1..=ramp {
            u.push(x + (target - x) * k as f64 / ramp as f64);
        }
        x = target;
        let hold = (rng.random_range(hold_s.0..hold_s.1) / DT_S) as usize;
        u.extend(std::iter::repeat_n(x, hold));
    }
    u.truncate(n);
    u
}

struct Clean {
    kind: Kind,
    physics: &'static Physics,
    scale: [f64; 2],
    affine: Vec<f64>,
}

impl Clean {
    /// (prediction, absorbable regressors, elastic part) at the given inputs.
    fn eval(&self, u: &[Vec<f64>]) -> (Vec<f64>, Vec<Vec<f64>>, Vec<f64>) {
        let n = u[0].len();
        match self.kind {
            Kind::Axial => {
                let mut y = vec![0.0; n];
                let mut r = vec![vec![0.0; n], vec![0.0; n]];
                let mut el = vec![0.0; n];
                for i in 0..n {
                    let t = self.physics.axial(u[0][i]);
                    r[0][i] = t[0];
                    r[1][i] = t[1];
                    el[i] = self.scale[0] * t[0] + self.scale[1] * t[1];
                    y[i] = el[i] + u[1][i] * t[2];
                }
                (y, r, el)
            }
            Kind::Bending => {
                let mut r = vec![vec![0.0; n], vec![0.0; n]];
                let mut el = vec![0.0; n];
                for i in 0..n {
                    let t = self.physics.free_bending_terms(u[1][i], u[0][i]);
                    r[0][i] = t[0];
                    r[1][i] = t[1];
                    el[i] = self.scale[0] * t[0] + self.scale[1] * t[1];
                }
                (el.clone(), r, el)
            }
            _ => {
                let k = u.len();
                let mut y = vec![self.affine[k]; n];
                let mut el = vec![0.0; n];
                for (j, uj) in u.iter().enumerate() {
                    for i in 0..n {
                        el[i] += self.affine[j] * uj[i];
                    }
                }
                for i in 0..n {
                    y[i] += el[i];
                }
                let mut r: Vec<Vec<f64>> = u.to_vec();
                r.push(vec![1.0; n]);
                (y, r, el)
            }
        }
    }
}

/// RMS of `e` after removing its least-squares projection on `regs`.
pub(crate) fn visible_rms(e: &[f64], regs: &[Vec<f64>]) -> f64 {
    let cols: Vec<&[f64]> = regs.iter().map(|r| r.as_slice()).collect();
    let mask = vec![true; e.len()];
    let f = lsq::fit(&cols, e, &mask, &[]);
    (f.rss / e.len() as f64).sqrt()
}

/// `e` minus its least-squares projection on `regs`.
pub(crate) fn visible_part(e: &[f64], regs: &[Vec<f64>]) -> Vec<f64> {
    let cols: Vec<&[f64]> = regs.iter().map(|r| r.as_slice()).collect();
    let mask = vec![true; e.len()];
    let f = lsq::fit(&cols, e, &mask, &[]);
    let p = lsq::predict(&cols, &f.coef, e.len());
    e.iter().zip(&p).map(|(a, b)| a - b).collect()
}

/// Bouc-Wen state driven by `x` (the classic symmetric loop), saturating at `+-z0`.
pub(crate) fn bouc_wen(x: &[f64], z0: f64) -> Vec<f64> {
    BoucWen::series(x, z0, BoucWenShape::SYMMETRIC)
}

/// The effects that can be hidden in a kind: a cause that the baseline's free parameters
/// absorb is no discrepancy (an output offset or an input gain under the affine `series` map;
/// a bend-angle gain or an initial-strain bias under the bending stiffness scales).
pub fn hideable(kind: Kind) -> &'static [Cause] {
    match kind {
        Kind::Axial | Kind::Pose => &Cause::CANDIDATES,
        Kind::Bending => &[
            Cause::Hysteresis,
            Cause::RateDependence,
            Cause::Softening,
            Cause::Latency,
            Cause::Offset,
            Cause::Nonlinearity,
        ],
        _ => &[
            Cause::Hysteresis,
            Cause::RateDependence,
            Cause::Softening,
            Cause::Latency,
            Cause::Nonlinearity,
        ],
    }
}

/// Generates a record of a scalar kind (`axial`, `bending`, `series`) for `spec`; `pose` has
/// its own generator and [`crate::synth::generate`] picks the right one. Effects not in
/// [`hideable`] for the kind are ignored.
pub fn generate_scalar(spec: &Spec) -> Generated {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let n = spec.rows.max(200);
    let physics = Physics::table_3_1();
    let time_s: Vec<f64> = (0..n).map(|i| i as f64 * DT_S).collect();
    let sc = match spec.kind {
        Kind::Axial => {
            let strain = drive_protocol(&mut rng, n, -0.5, 0.6);
            let p = stepped(&mut rng, n, 0.0, 25e3, (3.0, 8.0));
            Scenario {
                inputs: vec![strain, p],
                names: vec![("strain", "-"), ("pressure", "Pa")],
                drive: 0,
                secondary: Some(1),
            }
        }
        Kind::Bending => {
            let e0 = stepped(&mut rng, n, -0.3, 0.6, (10.0, 20.0));
            let unit = drive_protocol(&mut rng, n, -0.85, 0.85);
            let ang: Vec<f64> = (0..n)
                .map(|i| unit[i] * physics.bend_limit(e0[i]))
                .collect();
            Scenario {
                inputs: vec![e0, ang],
                names: vec![("strain0", "-"), ("bend_angle", "rad")],
                drive: 1,
                secondary: Some(0),
            }
        }
        _ => {
            let u1 = drive_protocol(&mut rng, n, -1.0, 1.0);
            let u2 = stepped(&mut rng, n, 0.0, 2.0, (2.0, 6.0));
            Scenario {
                inputs: vec![u1, u2],
                names: vec![("u1", "file"), ("u2", "file")],
                drive: 0,
                secondary: Some(1),
            }
        }
    };
    let clean = Clean {
        kind: spec.kind,
        physics,
        scale: [rng.random_range(0.7..1.4), rng.random_range(0.7..1.4)],
        affine: vec![
            rng.random_range(0.5..2.0),
            rng.random_range(-1.5..-0.3),
            rng.random_range(-1.0..1.0),
        ],
    };
    let (y0, regs, elastic) = clean.eval(&sc.inputs);
    let (_, sd) = signal::mean_std(&y0);
    let noise = sd * 10f64.powf(rng.random_range(-2.5..-1.5));
    let starts = vec![0usize];
    let drive = &sc.inputs[sc.drive];
    let range = |v: &[f64]| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (hi - lo).max(1e-12)
    };
    let r_drive = range(drive);
    // sign of the mean sensitivity to the drive, so that hysteresis and viscosity dissipate
    let mut shifted = sc.inputs.clone();
    shifted[sc.drive]
        .iter_mut()
        .for_each(|v| *v += 1e-4 * r_drive);
    let sens: f64 = clean
        .eval(&shifted)
        .0
        .iter()
        .zip(&y0)
        .map(|(a, b)| a - b)
        .sum();
    let sgn = if sens < 0.0 { -1.0 } else { 1.0 };

    let mut total = vec![0.0; n];
    let mut ratios = Vec::new();
    let mut details = Vec::new();
    let effects: Vec<Cause> = spec
        .effects
        .iter()
        .copied()
        .filter(|c| hideable(spec.kind).contains(c))
        .collect();
    for &cause in &effects {
        let ratio = spec.ratio.0 * (spec.ratio.1 / spec.ratio.0).powf(rng.random::<f64>());
        // effect shape with magnitude parameter m
        let shape: Box<dyn Fn(f64) -> Vec<f64>> = match cause {
            Cause::Hysteresis => {
                let z0 = r_drive * rng.random_range(0.03..0.15);
                let z = bouc_wen(drive, z0);
                details.push(format!(
                    "Bouc-Wen, saturation {:.3} of drive range",
                    z0 / r_drive
                ));
                Box::new(move |m| z.iter().map(|v| m * sd * sgn * v / z0).collect())
            }
            Cause::RateDependence => {
                let tau = 10f64.powf(rng.random_range(-0.5..0.7));
                let lp = signal::lowpass(drive, &time_s, &starts, tau);
                let q: Vec<f64> = drive
                    .iter()
                    .zip(&lp)
                    .map(|(a, b)| (a - b) / r_drive)
                    .collect();
                details.push(format!("standard linear solid, tau {tau:.2} s"));
                Box::new(move |m| q.iter().map(|v| m * sd * sgn * v).collect())
            }
            Cause::Softening => {
                let c0 = rng.random_range(0.2..0.8);
                let path = signal::path_length(drive);
                let last = path[n - 1].max(1e-12);
                let d: Vec<f64> = path
                    .iter()
                    .map(|p| 1.0 - (-(p / last) / c0).exp())
                    .collect();
                let el = elastic.clone();
                details.push(format!(
                    "stiffness loss 1-exp(-cycles/c0), c0 {c0:.2} of the record"
                ));
                Box::new(move |m| {
                    d.iter()
                        .zip(&el)
                        .map(|(a, e)| -m.min(0.9) * a * e)
                        .collect()
                })
            }
            Cause::Latency => {
                let d0 = rng.random_range(0.0..1.0);
                let t0 = rng.random_range(0.2..1.0);
                let y0c = y0.clone();
                let tm = time_s.clone();
                details.push(format!("dead time and lag in ratio {d0:.2}:{t0:.2}"));
                Box::new(move |m| {
                    // fractional dead time by linear interpolation, then a first-order lag
                    let d = m * d0 * 4.0;
                    let whole = d.floor() as usize;
                    let frac = d - d.floor();
                    let a = signal::delay_samples(&y0c, &[0], whole);
                    let b = signal::delay_samples(&y0c, &[0], whole + 1);
                    let delayed: Vec<f64> = a
                        .iter()
                        .zip(&b)
                        .map(|(x, y)| (1.0 - frac) * x + frac * y)
                        .collect();
                    let lagged = signal::lowpass(&delayed, &tm, &[0], m * t0 * DT_S * 4.0);
                    lagged.iter().zip(&y0c).map(|(a, b)| a - b).collect()
                })
            }
            Cause::Offset => {
                // output bias or a bias on an input; bending keeps to the output and the angle
                let channel = if spec.kind == Kind::Bending {
                    if rng.random::<bool>() {
                        sc.inputs.len()
                    } else {
                        sc.drive
                    }
                } else {
                    rng.random_range(0..=sc.inputs.len())
                };
                let inputs = sc.inputs.clone();
                let y0c = y0.clone();
                let ranges: Vec<f64> = inputs.iter().map(|v| range(v)).collect();
                if channel == sc.inputs.len() {
                    details.push("output bias".into());
                    Box::new(move |m| vec![m * sd; n])
                } else {
                    details.push(format!("bias on input {}", sc.names[channel].0));
                    let clean2 = Clean {
                        kind: clean.kind,
                        physics: clean.physics,
                        scale: clean.scale,
                        affine: clean.affine.clone(),
                    };
                    Box::new(move |m| {
                        let mut u = inputs.clone();
                        let b = m.min(0.5) * ranges[channel];
                        u[channel].iter_mut().for_each(|v| *v += b);
                        clean2
                            .eval(&u)
                            .0
                            .iter()
                            .zip(&y0c)
                            .map(|(a, c)| a - c)
                            .collect()
                    })
                }
            }
            Cause::Gain => {
                // a gain on the deformation drive is absorbed by the fitted stiffness scales, so the
                // hidden gain sits on the actuation channel (pressure, initial strain)
                let channel = sc.secondary.unwrap_or(sc.drive);
                let inputs = sc.inputs.clone();
                let y0c = y0.clone();
                let clean2 = Clean {
                    kind: clean.kind,
                    physics: clean.physics,
                    scale: clean.scale,
                    affine: clean.affine.clone(),
                };
                let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                details.push(format!("gain on input {}", sc.names[channel].0));
                Box::new(move |m| {
                    let mut u = inputs.clone();
                    let g = 1.0 + sign * m.min(0.3);
                    u[channel].iter_mut().for_each(|v| *v *= g);
                    clean2
                        .eval(&u)
                        .0
                        .iter()
                        .zip(&y0c)
                        .map(|(a, c)| a - c)
                        .collect()
                })
            }
            Cause::Nonlinearity => {
                let z = |k: usize| -> Vec<f64> {
                    let v = &sc.inputs[k];
                    let (m, _) = signal::mean_std(v);
                    let r = range(v);
                    v.iter().map(|x| (x - m) / r).collect()
                };
                let z0 = z(sc.drive);
                let z1 = sc.secondary.map(z).unwrap_or_else(|| z0.clone());
                // Pressure-dependent stiffening, the form the dissertation reports (errors that
                // grow above 20 kPa). A strain-only cubic is left out: under the energy model it
                // is nearly collinear with a strain offset times the local stiffness.
                let form = rng.random_range(0..2);
                let q: Vec<f64> = (0..n)
                    .map(|i| match form {
                        0 => z1[i] * z1[i] * z0[i],
                        _ => z1[i] * z0[i] * z0[i],
                    })
                    .collect();
                details.push(["secondary^2 * drive", "secondary * drive^2"][form].into());
                Box::new(move |m| q.iter().map(|v| m * sd * v).collect())
            }
            // friction needs a moving part these kinds lack; `unexplained` is a verdict
            Cause::None | Cause::Friction | Cause::Unexplained => Box::new(|_| vec![0.0; n]),
        };
        // bisection on log magnitude for the requested visible ratio
        let target = ratio * noise;
        let (mut lo, mut hi) = (-8.0f64, 3.0f64);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            let v = visible_rms(&shape(10f64.powf(mid)), &regs);
            if v < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        // the upper end of the bracket: at least the requested ratio
        let best = shape(10f64.powf(hi));
        let v = visible_rms(&best, &regs);
        ratios.push(v / noise);
        for i in 0..n {
            total[i] += best[i];
        }
    }
    let visible = visible_part(&total, &regs);
    let normal = Normal::new(0.0, noise).expect("positive noise");
    let y: Vec<f64> = (0..n)
        .map(|i| y0[i] + total[i] + normal.sample(&mut rng))
        .collect();
    let (out_name, out_unit) = match spec.kind {
        Kind::Axial => ("force", "N"),
        Kind::Bending => ("moment", "N m"),
        _ => ("y", "file"),
    };
    let drives = match spec.kind {
        Kind::Axial => vec![0],
        Kind::Bending => vec![1],
        _ => (0..sc.inputs.len()).collect(),
    };
    let inputs = sc
        .inputs
        .into_iter()
        .zip(&sc.names)
        .map(|(v, (name, unit))| Channel::new(name, unit, v))
        .collect();
    Generated {
        record: Record {
            kind: spec.kind,
            source: format!("generated:{}:{}", spec.kind.name(), spec.seed),
            time_s,
            segment_starts: vec![0],
            inputs,
            outputs: vec![Channel::new(out_name, out_unit, y)],
            drives,
            held_out: None,
            simulated: Vec::new(),
            states: Vec::new(),
            sensitivities: Vec::new(),
        },
        effects,
        ratios,
        noise,
        details,
        visible,
    }
}
