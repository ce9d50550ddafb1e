//! Causal signal operators used by diagnostics and model extensions. Every operator restarts
//! at each segment start (a new trial), because memory does not carry across trials.

/// Contiguous row ranges `[start, end)` of the segments given by their start rows.
pub fn segments(starts: &[usize], n: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(starts.len());
    for (i, &s) in starts.iter().enumerate() {
        let e = starts.get(i + 1).copied().unwrap_or(n);
        if e > s {
            out.push((s, e));
        }
    }
    out
}

/// First-order low-pass with time constant `tau_s` (exact discretisation for held input).
pub fn lowpass(x: &[f64], time_s: &[f64], starts: &[usize], tau_s: f64) -> Vec<f64> {
    lowpass_with(x, starts, &lowpass_factors(time_s, tau_s))
}

/// The per-row factors `exp(-dt_i / tau_s)` of [`lowpass`] (0 for `tau_s <= 0`; the first
/// row's is unused), for filtering many signals of one record at one time constant.
pub fn lowpass_factors(time_s: &[f64], tau_s: f64) -> Vec<f64> {
    let mut a = vec![0.0; time_s.len()];
    if tau_s > 0.0 {
        // Records are sampled evenly: the exponential of a repeated step is reused (the same
        // value it would give again; it dominated the identification's time).
        let (mut last_dt, mut last_a) = (f64::NAN, 0.0);
        for i in 1..time_s.len() {
            let dt = (time_s[i] - time_s[i - 1]).max(0.0);
            if dt != last_dt {
                last_a = (-dt / tau_s).exp();
                last_dt = dt;
            }
            a[i] = last_a;
        }
    }
    a
}

/// [`lowpass`] with its factors computed by [`lowpass_factors`].
pub fn lowpass_with(x: &[f64], starts: &[usize], factors: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for (s, e) in segments(starts, x.len()) {
        let mut state = x[s];
        y[s] = state;
        for i in s + 1..e {
            let a = factors[i];
            state = a * state + (1.0 - a) * x[i];
            y[i] = state;
        }
    }
    y
}

/// Discrete Laguerre filters of `x` with pole `pole` in (0, 1): the first is the lag
/// `sqrt(1 - a^2) / (1 - a q^-1)`, each next one the previous passed through the all-pass
/// `(q^-1 - a) / (1 - a q^-1)`. The functions are orthonormal (for white input), so a
/// combination of `count` of them is a finite memory of about `count (1 + a) / (1 - a)`
/// samples whose coefficients stay well conditioned, unlike a bank of neighbouring lags. Each
/// segment starts in the steady state of its first value (every all-pass has unit DC gain).
pub fn laguerre(x: &[f64], starts: &[usize], pole: f64, count: usize) -> Vec<Vec<f64>> {
    let a = pole;
    let g = (1.0 - a * a).sqrt();
    let mut out = vec![vec![0.0; x.len()]; count];
    for (s, e) in segments(starts, x.len()) {
        let steady = g * x[s] / (1.0 - a);
        // previous input and output of each stage (stage 0 is the lag)
        let mut prev_in = vec![x[s]; count];
        let mut prev_out = vec![steady; count];
        for k in 1..count {
            prev_in[k] = steady;
        }
        for i in s..e {
            let mut v = x[i];
            for k in 0..count {
                let y = if k == 0 {
                    a * prev_out[0] + g * v
                } else {
                    a * prev_out[k] + prev_in[k] - a * v
                };
                prev_in[k] = v;
                prev_out[k] = y;
                out[k][i] = y;
                v = y;
            }
        }
    }
    out
}

/// Dead time of `delay` samples: each row takes the value `delay` rows earlier in its segment
/// (the first value is held at the segment start).
pub fn delay_samples(x: &[f64], starts: &[usize], delay: usize) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for (s, e) in segments(starts, x.len()) {
        let held = s.saturating_add(delay).min(e);
        y[s..held].fill(x[s]);
        y[held..e].copy_from_slice(&x[s..e - (held - s)]);
    }
    y
}

/// Play (backlash) operator of half-width `r`, the building block of the Prandtl-Ishlinskii
/// model; starts centred on the first input of each segment.
pub fn play(x: &[f64], starts: &[usize], r: f64) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for (s, e) in segments(starts, x.len()) {
        let mut state = x[s];
        for i in s..e {
            state = state.clamp(x[i] - r, x[i] + r);
            y[i] = state;
        }
    }
    y
}

/// Accumulated path length `sum |dx|`, not reset between segments (damage persists).
pub fn path_length(x: &[f64]) -> Vec<f64> {
    let mut acc = 0.0;
    let mut out = Vec::with_capacity(x.len());
    for i in 0..x.len() {
        if i > 0 {
            acc += (x[i] - x[i - 1]).abs();
        }
        out.push(acc);
    }
    out
}

/// Running maximum of `|x - reference|`, not reset between segments.
pub fn running_peak(x: &[f64], reference: f64) -> Vec<f64> {
    let mut m: f64 = 0.0;
    x.iter()
        .map(|v| {
            m = m.max((v - reference).abs());
            m
        })
        .collect()
}

/// Backward-difference rate `dx/dt` (zero at segment starts).
pub fn rate(x: &[f64], time_s: &[f64], starts: &[usize]) -> Vec<f64> {
    let mut r = vec![0.0; x.len()];
    for (s, e) in segments(starts, x.len()) {
        for i in s + 1..e {
            let dt = time_s[i] - time_s[i - 1];
            r[i] = if dt > 0.0 {
                (x[i] - x[i - 1]) / dt
            } else {
                0.0
            };
        }
        if e > s + 1 {
            r[s] = r[s + 1];
        }
    }
    r
}

/// Central-difference rate `dx/dt` over `half` samples each side, within each segment (one-sided
/// at its ends): a velocity that lets measurement quantisation average out.
pub fn central_rate(x: &[f64], time_s: &[f64], starts: &[usize], half: usize) -> Vec<f64> {
    let mut r = vec![0.0; x.len()];
    for (s, e) in segments(starts, x.len()) {
        for i in s..e {
            let a = i.saturating_sub(half).max(s);
            let b = (i + half).min(e - 1);
            let dt = time_s[b] - time_s[a];
            r[i] = if dt > 0.0 { (x[b] - x[a]) / dt } else { 0.0 };
        }
    }
    r
}

/// Standard deviation of white noise in `x`, estimated from second differences within segments
/// on the rows where `mask` holds: for white noise `var(x[i+1] - 2 x[i] + x[i-1]) = 6 sigma^2`,
/// while a signal that is smooth at the sampling rate contributes little. The median absolute
/// deviation (times 1.4826) keeps steps and outliers from inflating it.
pub fn noise_sd(x: &[f64], starts: &[usize], mask: &[bool]) -> f64 {
    let mut d = Vec::with_capacity(x.len());
    for (s, e) in segments(starts, x.len()) {
        for i in s + 1..e.saturating_sub(1) {
            if mask[i - 1] && mask[i] && mask[i + 1] {
                d.push(x[i + 1] - 2.0 * x[i] + x[i - 1]);
            }
        }
    }
    if d.is_empty() {
        return 0.0;
    }
    let med = median(&mut d.clone());
    let mut dev: Vec<f64> = d.iter().map(|v| (v - med).abs()).collect();
    1.4826 * median(&mut dev) / 6f64.sqrt()
}

/// Median of a slice (reorders it); 0 when empty.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    let (_, x, _) = v.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    *x
}

/// Median sampling interval, seconds (robust to gaps between trials).
pub fn median_dt(time_s: &[f64]) -> f64 {
    let mut d: Vec<f64> = time_s
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    if d.is_empty() {
        return 1.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// Mean and population standard deviation.
pub fn mean_std(x: &[f64]) -> (f64, f64) {
    if x.is_empty() {
        return (0.0, 0.0);
    }
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / n;
    (m, v.sqrt())
}

/// Root mean square.
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Pearson correlation (0 when either side is constant).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let (ma, sa) = mean_std(a);
    let (mb, sb) = mean_std(b);
    if sa == 0.0 || sb == 0.0 {
        return 0.0;
    }
    let n = a.len().min(b.len()) as f64;
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - ma) * (y - mb))
        .sum::<f64>()
        / (n * sa * sb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laguerre_impulse_responses_are_orthonormal_and_hold_a_constant() {
        // The discrete Laguerre functions are orthonormal in l2: the Gram matrix of the
        // impulse responses is the identity.
        let (pole, count) = (0.8, 6);
        let mut x = vec![0.0; 400];
        x[1] = 1.0;
        let l = laguerre(&x, &[0], pole, count);
        for j in 0..count {
            for k in 0..count {
                let g: f64 = l[j].iter().zip(&l[k]).map(|(a, b)| a * b).sum();
                let want = if j == k { 1.0 } else { 0.0 };
                assert!((g - want).abs() < 1e-9, "<l{j}, l{k}> = {g}");
            }
        }
        // a constant input starts (and stays) in the steady state, per segment
        let c = [2.0, 2.0, 2.0, -1.0, -1.0];
        let l = laguerre(&c, &[0, 3], pole, count);
        let dc = (1.0 - pole * pole).sqrt() / (1.0 - pole);
        for f in &l {
            for (v, x) in f.iter().zip(&c) {
                assert!((v - dc * x).abs() < 1e-12, "{v} vs {}", dc * x);
            }
        }
    }

    #[test]
    fn lowpass_step_response_matches_exponential() {
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 0.01).collect();
        let mut x = vec![1.0; 200];
        x[0] = 0.0;
        let y = lowpass(&x, &t, &[0], 0.3);
        for i in 1..200 {
            let exact = 1.0 - (-(t[i]) / 0.3).exp();
            assert!((y[i] - exact).abs() < 1e-12, "{i}");
        }
    }

    #[test]
    fn play_operator_lags_by_its_width_and_holds_at_reversal() {
        let x: Vec<f64> = (0..=20).chain((0..20).rev()).map(|i| i as f64).collect();
        let y = play(&x, &[0], 2.0);
        assert_eq!(y[10], 8.0);
        assert_eq!(y[20], 18.0);
        // after the reversal the output stays until the input has moved back 2r
        assert_eq!(y[22], 18.0);
        assert_eq!(y[24], 18.0);
        assert_eq!(y[25], 17.0);
    }

    #[test]
    fn operators_restart_at_segment_starts() {
        let x = [0.0, 5.0, 5.0, 10.0, 10.0];
        let d = delay_samples(&x, &[0, 3], 1);
        assert_eq!(d, vec![0.0, 0.0, 5.0, 10.0, 10.0]);
        let p = play(&x, &[0, 3], 1.0);
        assert_eq!(p[3], 10.0);
    }

    /// The fast paths (a reused step factor, block copies) against the definitions, on
    /// uneven steps, repeated steps, short segments and delays longer than a segment.
    #[test]
    fn fast_operators_equal_their_definitions() {
        let t: Vec<f64> = (0..60)
            .map(|i| i as f64 * 0.01 + if i % 7 == 0 { 0.003 } else { 0.0 })
            .collect();
        let x: Vec<f64> = (0..60).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
        let starts = [0, 1, 9, 10, 31];
        for tau in [0.0, 0.02, 0.5] {
            let y = lowpass(&x, &t, &starts, tau);
            for (s, e) in segments(&starts, x.len()) {
                let mut state = x[s];
                assert_eq!(y[s], state);
                for i in s + 1..e {
                    let dt = (t[i] - t[i - 1]).max(0.0);
                    let a = if tau > 0.0 { (-dt / tau).exp() } else { 0.0 };
                    state = a * state + (1.0 - a) * x[i];
                    assert_eq!(y[i].to_bits(), state.to_bits(), "tau {tau}, row {i}");
                }
            }
        }
        for delay in [0, 1, 3, 25, usize::MAX] {
            let y = delay_samples(&x, &starts, delay);
            for (s, e) in segments(&starts, x.len()) {
                for i in s..e {
                    assert_eq!(
                        y[i],
                        x[i.saturating_sub(delay).max(s)],
                        "delay {delay}, row {i}"
                    );
                }
            }
        }
    }

    #[test]
    fn path_and_peak_accumulate() {
        let x = [0.0, 1.0, -1.0, 0.5];
        assert_eq!(path_length(&x), vec![0.0, 1.0, 3.0, 4.5]);
        assert_eq!(running_peak(&x, 0.0), vec![0.0, 1.0, 1.0, 1.0]);
    }

    #[test]
    fn noise_estimate_recovers_white_noise_under_a_slow_signal() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let nd = Normal::new(0.0, 0.05).unwrap();
        let n = 20_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let x: Vec<f64> = t
            .iter()
            .map(|t| 3.0 * (0.5 * t).sin() + nd.sample(&mut rng))
            .collect();
        let sd = noise_sd(&x, &[0], &vec![true; n]);
        assert!((sd / 0.05 - 1.0).abs() < 0.05, "{sd}");
        let clean: Vec<f64> = t.iter().map(|t| 3.0 * (0.5 * t).sin()).collect();
        // the smooth signal alone reads as less than 0.2 % of that noise
        assert!(noise_sd(&clean, &[0], &vec![true; n]) < 1e-4);
    }

    #[test]
    fn central_rate_is_exact_on_a_ramp() {
        let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let x: Vec<f64> = t.iter().map(|t| 2.0 * t - 1.0).collect();
        let r = central_rate(&x, &t, &[0, 25], 3);
        assert!(r.iter().all(|v| (v - 2.0).abs() < 1e-9));
    }
}
