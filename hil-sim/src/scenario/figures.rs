//! Scenario-specific scores of a time-domain run.

use std::collections::BTreeMap;

use crate::metrics::{mean, step_times};
use crate::reference::Path;

use super::setup::Setup;

pub(super) fn points_figures(su: &Setup, t: &[f64], e: &[f64], out: &mut BTreeMap<String, f64>) {
    let Path::Points { targets_m, dwell_s } = &su.path else {
        return;
    };
    let (mut finals, mut rises, mut settles) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..targets_m.len() {
        let (a, b) = (k as f64 * dwell_s, (k + 1) as f64 * dwell_s);
        let window: Vec<(f64, f64)> = t
            .iter()
            .zip(e)
            .filter(|(ti, _)| **ti > a && **ti <= b)
            .map(|(ti, ei)| (*ti, *ei))
            .collect();
        let last: Vec<f64> = window
            .iter()
            .filter(|(ti, _)| *ti > b - 1.0)
            .map(|w| w.1)
            .collect();
        finals.push(mean(&last));
        if k > 0 {
            let (r, s) = step_times(&window, 0.05, 1e-3);
            rises.push(r.unwrap_or(*dwell_s));
            settles.push(s.unwrap_or(*dwell_s));
        }
    }
    out.insert("mean_final_error_mm".into(), mean(&finals) * 1e3);
    out.insert("rise_s".into(), mean(&rises));
    out.insert("settling_s".into(), mean(&settles));
}

pub(super) fn disconnect_figures(
    a: f64,
    b: f64,
    t: &[f64],
    e: &[f64],
    out: &mut BTreeMap<String, f64>,
) {
    let before: Vec<f64> = t
        .iter()
        .zip(e)
        .filter(|(ti, _)| **ti < a)
        .map(|x| *x.1)
        .collect();
    let base = before.iter().cloned().fold(0.0, f64::max);
    let max_dev = t
        .iter()
        .zip(e)
        .filter(|(ti, _)| **ti >= a)
        .map(|x| *x.1)
        .fold(0.0, f64::max);
    let band = base + 2e-3;
    // Recovered when the error last leaves the band after the reconnect.
    let last_out = t
        .iter()
        .zip(e)
        .filter(|(ti, ei)| **ti >= b && **ei > band)
        .map(|x| *x.0)
        .fold(b, f64::max);
    out.insert("baseline_max_err_mm".into(), base * 1e3);
    out.insert("max_deviation_mm".into(), max_dev * 1e3);
    out.insert("recovery_s".into(), last_out - b);
    out.insert(
        "recovered".into(),
        if t.last().is_some_and(|&tl| last_out < tl - 1e-9) {
            1.0
        } else {
            0.0
        },
    );
}
