//! Residual diagnostics, one per cause, computed on the baseline's held-out residual. They are
//! the evidence printed beside each candidate; selection itself uses the fitted extensions.

use serde::Serialize;

use crate::cause::Cause;
use crate::extension::Prepared;
use crate::signal;

/// One diagnostic statistic.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnostic {
    /// The cause it probes.
    pub cause: Cause,
    /// What was computed.
    pub statistic: String,
    /// Its value.
    pub value: f64,
    /// Plain-language reading.
    pub reading: String,
}

/// Where the residual is largest: the input bin with the largest residual RMS.
#[derive(Debug, Clone, Serialize)]
pub struct Hotspot {
    /// Input channel.
    pub input: String,
    /// Bin lower edge (input units).
    pub from: f64,
    /// Bin upper edge.
    pub to: f64,
    /// Residual RMS in the bin.
    pub rmse: f64,
    /// Ratio to the overall residual RMS.
    pub ratio: f64,
}

/// Held-out residual of channel `c` under predictions `pred` (zero on training rows).
fn residual(prep: &Prepared, c: usize) -> Vec<f64> {
    let ch = &prep.channels[c];
    (0..ch.y.len()).map(|i| ch.y[i] - ch.yhat[i]).collect()
}

fn test_rows(prep: &Prepared) -> Vec<usize> {
    (0..prep.rec.len()).filter(|&i| prep.test[i]).collect()
}

fn pick(v: &[f64], rows: &[usize]) -> Vec<f64> {
    rows.iter().map(|&i| v[i]).collect()
}

/// The diagnostic variable plotted against the residual for a cause, with its label.
pub fn variable(prep: &Prepared, cause: Cause, c: usize) -> (Vec<f64>, String) {
    let rec = prep.rec;
    let k = rec.drives.first().copied().unwrap_or(0);
    let u = &rec.inputs[k].values;
    match cause {
        // pose: memory and viscosity act on the column strains
        Cause::Hysteresis if prep.pose.is_some() => (
            prep.pose
                .as_ref()
                .map(|p| p.strains[0].clone())
                .unwrap_or_default(),
            "model strain of column 1 [-]".into(),
        ),
        Cause::RateDependence if prep.pose.is_some() => (
            prep.pose
                .as_ref()
                .map(|p| signal::rate(&p.strains[0], &rec.time_s, &rec.segment_starts))
                .unwrap_or_default(),
            "model strain rate of column 1 [1/s]".into(),
        ),
        Cause::Hysteresis => (
            u.clone(),
            format!("{} [{}]", rec.inputs[k].name, rec.inputs[k].unit),
        ),
        Cause::RateDependence => (
            signal::rate(u, &rec.time_s, &rec.segment_starts),
            format!("d{}/dt [{}/s]", rec.inputs[k].name, rec.inputs[k].unit),
        ),
        Cause::Softening => (
            prep.damage_histories().0,
            "accumulated cycles (fraction)".into(),
        ),
        Cause::Latency => (
            signal::rate(&prep.channels[c].yhat, &rec.time_s, &rec.segment_starts),
            format!("model output rate [{}/s]", rec.outputs[c].unit),
        ),
        Cause::Friction if matches!(prep.baseline, crate::baseline::Baseline::StateSpace(_)) => (
            prep.model_velocity(c).0,
            format!(
                "model d{}/dt [{}/s]",
                rec.outputs[c].name, rec.outputs[c].unit
            ),
        ),
        Cause::Friction => match prep.velocities().into_iter().next() {
            Some((name, v, _)) => {
                let unit = rec
                    .states
                    .iter()
                    .find(|s| s.name == name)
                    .map(|s| s.unit.clone())
                    .unwrap_or_default();
                (v, format!("d{name}/dt [{unit}/s]"))
            }
            None => (rec.time_s.clone(), "time [s]".into()),
        },
        Cause::Offset | Cause::None | Cause::Unexplained => (rec.time_s.clone(), "time [s]".into()),
        Cause::Gain | Cause::Nonlinearity => (
            prep.channels[c].yhat.clone(),
            format!("model output [{}]", rec.outputs[c].unit),
        ),
    }
}

/// Computes every cause's diagnostic on output channel `c`.
pub fn diagnose(prep: &Prepared, c: usize) -> Vec<Diagnostic> {
    let rec = prep.rec;
    let rows = test_rows(prep);
    let r_all = residual(prep, c);
    let r = pick(&r_all, &rows);
    let (mean, sd) = signal::mean_std(&r);
    let rms = signal::rms(&r).max(1e-300);
    let k = rec.drives.first().copied().unwrap_or(0);
    let ch = &prep.channels[c];
    let u = &rec.inputs[k].values;
    // The signed drive rate: positive where the drive loads the structure. For pose the
    // drives are the three column strains, mapped to this channel by the tip sensitivity (a
    // lagging strain pulls the tip against `sens * de/dt`); otherwise the first drive, signed
    // by the mean sensitivity.
    let du: Vec<f64> = match &prep.pose {
        Some(ps) => {
            let mut v = vec![0.0; ch.y.len()];
            for (e, sens) in ps.strains.iter().zip(&ps.sens[c]) {
                let de = signal::rate(e, &rec.time_s, &rec.segment_starts);
                for i in 0..v.len() {
                    v[i] += sens[i] * de[i];
                }
            }
            v
        }
        None => signal::rate(u, &rec.time_s, &rec.segment_starts)
            .iter()
            .map(|v| v * ch.sign[k])
            .collect(),
    };
    // Loading direction and speed for the hysteresis split: for pose each moving column adds
    // its sensitivity times its direction of travel (a play operator's output sits its width
    // behind the strain, whatever the speed), and the speed is the summed relative strain rate.
    let (dir, speed): (Vec<f64>, Vec<f64>) = match &prep.pose {
        Some(ps) => {
            let n = ch.y.len();
            let mut dir = vec![0.0; n];
            let mut speed = vec![0.0; n];
            for (e, sens) in ps.strains.iter().zip(&ps.sens[c]) {
                let de = signal::rate(e, &rec.time_s, &rec.segment_starts);
                let lo = e.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = e.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let range = if hi > lo { hi - lo } else { 1.0 };
                for i in 0..n {
                    if de[i] != 0.0 {
                        dir[i] += sens[i] * de[i].signum() * range;
                        speed[i] += de[i].abs() / range;
                    }
                }
            }
            (dir, speed)
        }
        None => (du.clone(), du.iter().map(|v| v.abs()).collect()),
    };
    let drive_name = if prep.pose.is_some() {
        "column strains".to_string()
    } else {
        rec.inputs[k].name.clone()
    };
    let mut out = Vec::new();

    // Hysteresis: loading minus unloading residual at slow rates (rate-independent part).
    let rates: Vec<f64> = rows
        .iter()
        .map(|&i| speed[i])
        .filter(|v| *v > 0.0)
        .collect();
    let mut sorted = rates.clone();
    sorted.sort_by(f64::total_cmp);
    let slow = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let (mut up, mut nu, mut dn, mut nd) = (0.0, 0, 0.0, 0);
    for &i in &rows {
        let a = speed[i];
        if a > 0.0 && a <= slow {
            if dir[i] > 0.0 {
                up += r_all[i];
                nu += 1;
            } else {
                dn += r_all[i];
                nd += 1;
            }
        }
    }
    let split = if nu > 0 && nd > 0 {
        up / nu as f64 - dn / nd as f64
    } else {
        0.0
    };
    // With three columns moving at once the loading direction is graded, not binary: pose
    // reports the residual's correlation with it on the slow rows.
    let (statistic, value) = if prep.pose.is_some() {
        let slow_rows: Vec<usize> = rows
            .iter()
            .copied()
            .filter(|&i| speed[i] > 0.0 && speed[i] <= slow)
            .collect();
        (
            "corr(residual, loading direction of the column strains) at slow rates".to_string(),
            signal::correlation(&pick(&r_all, &slow_rows), &pick(&dir, &slow_rows)),
        )
    } else {
        (
            "slow loading minus unloading residual / residual RMS".to_string(),
            split / rms,
        )
    };
    out.push(Diagnostic {
        cause: Cause::Hysteresis,
        statistic,
        value,
        reading: format!(
            "loop width {split:.4e} {} at slow rates of the {drive_name}",
            rec.outputs[c].unit
        ),
    });

    // Rate dependence: residual correlation with the signed drive rate, and relaxation in holds.
    let sdu: Vec<f64> = rows.iter().map(|&i| du[i]).collect();
    let corr = signal::correlation(&r, &sdu);
    out.push(Diagnostic {
        cause: Cause::RateDependence,
        statistic: format!("corr(residual, signed rate of the {drive_name})"),
        value: corr,
        reading: if corr > 0.0 {
            "the model under-predicts while loading fast (stiffer when fast)".into()
        } else {
            "the residual falls with the drive rate".into()
        },
    });

    // Softening: slope of residual / elastic prediction against accumulated cycles.
    let (path, _) = prep.damage_histories();
    let rel: Vec<f64> = rows
        .iter()
        .map(|&i| -r_all[i] * ch.elastic[i].signum())
        .collect();
    let cyc = pick(&path, &rows);
    let ctrend = signal::correlation(&rel, &cyc);
    out.push(Diagnostic {
        cause: Cause::Softening,
        statistic: "corr(stiffness deficit, accumulated cycles)".into(),
        value: ctrend,
        reading: "positive when the structure gets softer as cycles accumulate".into(),
    });

    // Latency: lag (samples) maximising corr(y(t), yhat(t - lag)).
    let n = ch.y.len();
    let mut best = (0usize, f64::NEG_INFINITY);
    for lag in 0..=40.min(n / 10) {
        let a: Vec<f64> = rows
            .iter()
            .filter(|&&i| i >= lag)
            .map(|&i| ch.y[i])
            .collect();
        let b: Vec<f64> = rows
            .iter()
            .filter(|&&i| i >= lag)
            .map(|&i| ch.yhat[i - lag])
            .collect();
        let cc = signal::correlation(&a, &b);
        if cc > best.1 {
            best = (lag, cc);
        }
    }
    out.push(Diagnostic {
        cause: Cause::Latency,
        statistic: "cross-correlation peak lag [s]".into(),
        value: best.0 as f64 * prep.dt,
        reading: format!(
            "measurement best matches the model {} samples later",
            best.0
        ),
    });

    // Offset: mean residual in units of its standard error (rough, white assumption).
    let t = if sd > 0.0 {
        mean / (sd / (r.len() as f64).sqrt())
    } else {
        0.0
    };
    out.push(Diagnostic {
        cause: Cause::Offset,
        statistic: "mean residual / standard error".into(),
        value: t,
        reading: format!("mean residual {mean:.4e} {}", rec.outputs[c].unit),
    });

    // Gain: regression of the residual on each input's sensitivity-weighted value.
    let mut best_gain = (String::new(), 0.0f64);
    for (kk, inp) in rec.inputs.iter().enumerate() {
        let x: Vec<f64> = rows
            .iter()
            .map(|&i| inp.values[i] * ch.jac[kk][i])
            .collect();
        let cc = signal::correlation(&r, &x);
        if cc.abs() > best_gain.1.abs() {
            best_gain = (inp.name.clone(), cc);
        }
    }
    out.push(Diagnostic {
        cause: Cause::Gain,
        statistic: "largest corr(residual, u_k * dyhat/du_k)".into(),
        value: best_gain.1,
        reading: format!("strongest on input {}", best_gain.0),
    });

    // Nonlinearity: share of residual variance explained by quadratic/cubic input terms.
    let (cols, _, _) = prep.features(Cause::Nonlinearity, c);
    let refs: Vec<&[f64]> = cols.iter().map(|v| v.as_slice()).collect();
    let mut with_one: Vec<&[f64]> = refs.clone();
    let one = vec![1.0; n];
    with_one.push(&one);
    let f = crate::lsq::fit(&with_one, &r_all, &prep.test, &[]);
    let tss = r
        .iter()
        .map(|v| (v - mean) * (v - mean))
        .sum::<f64>()
        .max(1e-300);
    out.push(Diagnostic {
        cause: Cause::Nonlinearity,
        statistic: "R^2 of residual on quadratic and cubic input terms".into(),
        value: 1.0 - f.rss / tss,
        reading: "share of the residual that is a static polynomial of the inputs".into(),
    });
    out
}

/// Input bins (quintiles) where the held-out residual RMS is largest, one per input.
pub fn hotspots(prep: &Prepared, c: usize) -> Vec<Hotspot> {
    let rows = test_rows(prep);
    let r = residual(prep, c);
    let overall = signal::rms(&pick(&r, &rows)).max(1e-300);
    let mut out = Vec::new();
    for inp in &prep.rec.inputs {
        let mut v: Vec<f64> = rows.iter().map(|&i| inp.values[i]).collect();
        v.sort_by(f64::total_cmp);
        if v.is_empty() || v[0] == v[v.len() - 1] {
            continue;
        }
        let edges: Vec<f64> = (0..=5).map(|q| v[((v.len() - 1) * q) / 5]).collect();
        let mut best: Option<Hotspot> = None;
        for b in 0..5 {
            let (lo, hi) = (edges[b], edges[b + 1]);
            let sel: Vec<f64> = rows
                .iter()
                .filter(|&&i| {
                    inp.values[i] >= lo && (inp.values[i] < hi || (b == 4 && inp.values[i] <= hi))
                })
                .map(|&i| r[i])
                .collect();
            if sel.is_empty() {
                continue;
            }
            let e = signal::rms(&sel);
            if best.as_ref().is_none_or(|h| e > h.rmse) {
                best = Some(Hotspot {
                    input: format!("{} [{}]", inp.name, inp.unit),
                    from: lo,
                    to: hi,
                    rmse: e,
                    ratio: e / overall,
                });
            }
        }
        out.extend(best);
    }
    out
}
