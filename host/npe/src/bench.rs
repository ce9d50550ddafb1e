//! Latency of one engine call.

use serde::{Deserialize, Serialize};

use crate::Result;
use crate::engine::Npe;

/// Latency figures, milliseconds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Latency {
    /// Calls timed.
    pub calls: usize,
    /// Contact points per call.
    pub points: usize,
    /// Median of the calls, ms.
    pub median_ms: f64,
    /// 10th and 90th percentiles, ms.
    pub p10_p90_ms: [f64; 2],
}

/// Times `calls` calls of [`Npe::predict`] (of [`Npe::predict_contact`] for an engine with a
/// contact head, which then belongs to the call) on the same input after `warmup` untimed
/// ones, with the CPU backend limited to `threads` worker threads.
pub fn latency(
    npe: &Npe,
    points_m: &[[f64; 3]],
    force_n: f64,
    depth_m: f64,
    warmup: usize,
    calls: usize,
    threads: usize,
) -> Result<Latency> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| crate::NpeError::Data(format!("thread pool: {e}")))?;
    pool.install(|| timed(npe, points_m, force_n, depth_m, warmup, calls))
}

fn timed(
    npe: &Npe,
    points_m: &[[f64; 3]],
    force_n: f64,
    depth_m: f64,
    warmup: usize,
    calls: usize,
) -> Result<Latency> {
    let call = || -> Result<_> {
        if npe.has_contact_head() {
            Ok(std::hint::black_box(npe.predict_contact(points_m, force_n, depth_m)?).0)
        } else {
            npe.predict(points_m, force_n, depth_m)
        }
    };
    for _ in 0..warmup {
        call()?;
    }
    let mut t = Vec::with_capacity(calls);
    for _ in 0..calls.max(1) {
        let t0 = std::time::Instant::now();
        let f = call()?;
        t.push(t0.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(f);
    }
    t.sort_by(f64::total_cmp);
    let q = |f: f64| t[((t.len() - 1) as f64 * f).round() as usize];
    Ok(Latency {
        calls: t.len(),
        points: points_m.len(),
        median_ms: q(0.5),
        p10_p90_ms: [q(0.1), q(0.9)],
    })
}
