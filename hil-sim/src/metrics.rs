//! Metrics of Ch. 3.4: RMSE, workspace-normalized errors (eq 3.40-3.43),
//! rise and settling times.

/// Root mean square of `v` (0 for an empty slice).
pub fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Mean of `v` (0 for an empty slice).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.iter().sum::<f64>() / v.len() as f64
}

/// Workspace diagonal `l_max` of a point cloud (eq 3.40).
pub fn workspace_diagonal(points: &[[f64; 3]]) -> f64 {
    let mut d2 = 0.0;
    for k in 0..3 {
        let lo = points.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
        let hi = points
            .iter()
            .map(|p| p[k])
            .fold(f64::NEG_INFINITY, f64::max);
        if hi >= lo {
            d2 += (hi - lo).powi(2);
        }
    }
    d2.sqrt()
}

/// Euclidean distance.
pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Rise and settling time of a step from samples `(t, distance to
/// target)` starting at the step: rise when the distance first falls to
/// 10 % of its initial value, settling when it last leaves the band
/// `max(band_fraction d0, band_floor)`. `None` when never reached.
pub fn step_times(
    samples: &[(f64, f64)],
    band_fraction: f64,
    band_floor: f64,
) -> (Option<f64>, Option<f64>) {
    let Some(&(t0, d0)) = samples.first() else {
        return (None, None);
    };
    let rise = samples
        .iter()
        .find(|(_, d)| *d <= 0.1 * d0)
        .map(|(t, _)| t - t0);
    let band = (band_fraction * d0).max(band_floor);
    let settle = match samples.iter().rposition(|(_, d)| *d > band) {
        None => Some(0.0),
        Some(k) if k + 1 < samples.len() => Some(samples[k + 1].0 - t0),
        Some(_) => None,
    };
    (rise, settle)
}
