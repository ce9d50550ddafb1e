//! Train / held-out splits by time blocks.
//!
//! The record's elapsed time (summed over segments, so gaps between trials do not count) is cut
//! into [`BLOCKS`] equal blocks; blocks [`HELD_OUT_BLOCKS`] (the 3rd, 6th and 9th, 30 % of the
//! time) are held out and the rest train. Interleaved blocks make both sides see the whole
//! range of the protocol while every held-out row is at least a block away from most training
//! rows. A record that brings its own split (the soft-arm `val` trials) keeps it.

use crate::data::Record;
use crate::signal;

/// Number of equal time blocks.
pub const BLOCKS: usize = 10;
/// Zero-based indices of the held-out blocks.
pub const HELD_OUT_BLOCKS: [usize; 3] = [2, 5, 8];

/// Held-out flags per row.
pub fn held_out(rec: &Record) -> Vec<bool> {
    if let Some(h) = &rec.held_out {
        return h.clone();
    }
    let n = rec.len();
    let mut elapsed = vec![0.0; n];
    let mut acc = 0.0;
    for (s, e) in signal::segments(&rec.segment_starts, n) {
        elapsed[s] = acc;
        for i in s + 1..e {
            acc += (rec.time_s[i] - rec.time_s[i - 1]).max(0.0);
            elapsed[i] = acc;
        }
    }
    let total = acc.max(f64::MIN_POSITIVE);
    elapsed
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            // Rows with no elapsed time (all-equal stamps) fall back to row order.
            let frac = if acc > 0.0 {
                t / total
            } else {
                i as f64 / n as f64
            };
            let b = ((frac * BLOCKS as f64) as usize).min(BLOCKS - 1);
            HELD_OUT_BLOCKS.contains(&b)
        })
        .collect()
}

/// One-line description of the split used.
pub fn describe(rec: &Record) -> String {
    if rec.held_out.is_some() {
        "the record's own split (held-out trials)".into()
    } else {
        format!(
            "{BLOCKS} equal time blocks, blocks {:?} (1-based) held out",
            HELD_OUT_BLOCKS.map(|b| b + 1)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Channel, Kind};

    #[test]
    fn holds_out_thirty_percent_in_three_blocks() {
        let n = 1000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let rec = Record {
            kind: Kind::Series,
            source: "t".into(),
            time_s: t,
            segment_starts: vec![0],
            inputs: vec![Channel::new("u", "-", vec![0.0; n])],
            outputs: vec![Channel::new("y", "-", vec![0.0; n])],
            drives: vec![0],
            held_out: None,
            simulated: Vec::new(),
            states: Vec::new(),
            sensitivities: Vec::new(),
        };
        let h = held_out(&rec);
        let count = h.iter().filter(|v| **v).count();
        assert!((count as i64 - 300).abs() <= 3, "{count}");
        let runs = h.windows(2).filter(|w| w[0] != w[1]).count();
        assert_eq!(runs, 6);
        assert!(!h[0] && h[250] && h[550] && h[850] && !h[999]);
    }
}
