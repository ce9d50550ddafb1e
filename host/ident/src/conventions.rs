//! A record against its kind's conventions: the conventions' text (printed in reports and in
//! the CLI help) and the warnings of a record that contradicts them.

use crate::baseline::Baseline;
use crate::data::{Kind, Record};
use crate::extension::Prepared;
use crate::signal;

/// The schema's conventions for a kind, printed in reports and in the CLI help.
pub fn conventions(kind: Kind) -> &'static str {
    match kind {
        Kind::Axial => {
            "axial: force_n is the axial force on the OCM, tension positive; strain is elongation over rest length (extension positive); pressure_kpa is gauge pressure (inflation positive)"
        }
        Kind::Bending => {
            "bending: strain0 is the initial axial strain set by pressure; bend_angle_rad and moment_nm share their sign (the moment that bends the OCM by a positive angle is positive)"
        }
        Kind::Pose => {
            "pose: tip x_mm, y_mm, z_mm in the base frame of a standing segment, z along the unbent backbone pointing from base to tip (z > 0); load_n is axial tension on the segment; p1..p3_kpa gauge pressures of chambers at 90, 210 and 330 degrees from x (inflation positive). A hanging mount must be rotated into this frame first"
        }
        Kind::Series => {
            "series: u_<name> inputs, y_<name> measured outputs, optional sim_<name> (a simulator's prediction of y_<name>) and x_<name> (its states; where they determine the simulated output, memory, offsets and gains also act on them, a gain about the state's zero, so log states whose zero is the unloaded configuration, e.g. an elongation rather than a length) and dsim_<output>__<state> (its own sensitivity d sim_<output> / d x_<state>, one per state or none for an output: taken as exact, and then an input's or a state's offset or gain is one parameter for every output); values in the file's units, named by the suffix (_n, _m, _mm, _kpa, _pa, _rad, _s); a time that goes backwards starts a new trial"
        }
    }
}

/// Relative departure of a time step from the record's median step above which the sampling
/// counts as irregular.
const SAMPLING_TOLERANCE: f64 = 0.01;

/// A warning when the time step varies inside trials: the state-space model is a discrete-time
/// model of one step, and the lag, latency and rate terms count samples, so an irregular
/// record is fitted as if it were regular (the conventions ask for a constant step).
fn sampling_warning(rec: &Record) -> Option<String> {
    let t = &rec.time_s;
    let first: std::collections::HashSet<usize> = rec.segment_starts.iter().copied().collect();
    let steps: Vec<f64> = (1..t.len())
        .filter(|i| !first.contains(i))
        .map(|i| t[i] - t[i - 1])
        .collect();
    if steps.is_empty() {
        return None;
    }
    if steps.iter().all(|d| *d <= 0.0) {
        return Some("every time stamp inside a trial repeats the one before: the record has no time step; the state-space model, the lag, latency and rate terms need one".to_string());
    }
    // the median of the positive steps (a trial's reset goes backwards and is not one): repeated
    // stamps are counted apart
    let median = signal::median_dt(t);
    let off = steps
        .iter()
        .filter(|d| (**d - median).abs() > SAMPLING_TOLERANCE * median || **d <= 0.0)
        .count();
    if off == 0 {
        return None;
    }
    let repeated = steps.iter().filter(|d| **d == 0.0).count();
    let (lo, hi) = steps
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            (a.min(*d), b.max(*d))
        });
    Some(format!(
        "the time step varies: {off} of {} steps inside trials differ from the median step {median:.4e} s by more than {:.0} % (from {:.4e} to {:.4e} s{}); the state-space model, the lag, latency and rate terms assume a constant step, so resample the record to one step first",
        steps.len(),
        100.0 * SAMPLING_TOLERANCE,
        lo,
        hi,
        if repeated > 0 {
            format!(", {repeated} repeated time stamps")
        } else {
            String::new()
        }
    ))
}

/// Checks a record against its kind's conventions; each finding is a warning.
pub(crate) fn schema_warnings(rec: &Record, prep: &Prepared) -> Vec<String> {
    let mut w = Vec::new();
    // A fitted model that anti-correlates with the measurement in a channel says the record's
    // frame or sign differs from the schema's (a hanging mount, a flipped axis).
    for (c, ch) in prep.channels.iter().enumerate() {
        let r = signal::correlation(&ch.y, &ch.yhat);
        if r < -0.2 {
            w.push(format!(
                "{}: the model's prediction anti-correlates with the measurement (r = {r:.2}): the record's sign or frame contradicts the schema ({})",
                rec.outputs[c].name,
                conventions(rec.kind)
            ));
        }
    }
    if rec.kind == Kind::Pose {
        let z = &rec.outputs[2].values;
        let neg = z.iter().filter(|v| **v < 0.0).count();
        if neg * 2 > z.len() {
            w.push(format!(
                "z is negative on {neg} of {} rows: the schema's z points from base to tip of a standing segment (a hanging mount's log must be rotated first)",
                z.len()
            ));
        }
    }
    // Pressures far outside the parameter set's range: the record is from another design (the
    // lab's calibrated plant read with Table 3.1, say); the fit would be a stretched reading.
    if let Baseline::Pose {
        physics,
        stiffness_scale,
    } = &prep.baseline
    {
        let (lo, hi) = physics.pressure_range_pa();
        let (lo, hi) = (lo * stiffness_scale, hi * stiffness_scale);
        let total = 3 * rec.len();
        let out = rec.inputs[..3]
            .iter()
            .flat_map(|ch| &ch.values)
            .filter(|p| **p < lo || **p > hi)
            .count();
        if out * 2 > total {
            w.push(format!(
                "{out} of {total} chamber pressures lie outside {:.1}..{:.1} kPa, the working range of the {} parameter set at the fitted stiffness scale {stiffness_scale:.3}: the record may come from another design (the virtual lab's plant is `--params calibrated`)",
                lo / 1e3,
                hi / 1e3,
                physics.params_label()
            ));
        }
    }
    if let Some(msg) = sampling_warning(rec) {
        w.push(msg);
    }
    for (o, s) in rec.outputs.iter().zip(&rec.simulated) {
        if o.values == s.values {
            w.push(format!(
                "y_{0} equals sim_{0} on every row: the measured column may be a copy of the simulated one",
                o.name
            ));
        }
    }
    w
}
