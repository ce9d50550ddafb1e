//! Throughput of the renderer from FEM nodal displacements to RGB frames.

use super::camera::SurfaceSampler;
use super::render::{RenderScratch, Renderer};
use crate::{Result, TactileError};
use serde::{Deserialize, Serialize};

/// Renderer throughput on a fixed number of threads.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RenderBench {
    /// Worker threads.
    pub threads: usize,
    /// Frames per repeat.
    pub frames: usize,
    /// Frames per second of each repeat.
    pub fps: Vec<f64>,
    /// Median of `fps`.
    pub median_fps: f64,
    /// Image size (rows, cols).
    pub size: [usize; 2],
}

/// Renders the displacement fields `fields` round-robin (resampling onto the image, slopes,
/// calibration lookup, background) `frames` times per repeat on a pool of `threads` threads,
/// `repeats` times.
pub fn bench_render(
    renderer: &Renderer,
    sampler: &SurfaceSampler,
    fields: &[Vec<[f64; 3]>],
    frames: usize,
    repeats: usize,
    threads: usize,
) -> Result<RenderBench> {
    if fields.is_empty() || frames == 0 || repeats == 0 || threads == 0 {
        return Err(TactileError::Input(
            "render benchmark needs fields, frames, repeats and threads".into(),
        ));
    }
    let pool = pool(threads)?;
    let n = sampler.rows * sampler.cols;
    let mut h = vec![0.0f32; n];
    let mut out = vec![0u8; n * 3];
    let mut scratch = RenderScratch::default();
    let mut fps = Vec::with_capacity(repeats);
    pool.install(|| -> Result<()> {
        for _ in 0..repeats {
            let t0 = std::time::Instant::now();
            for i in 0..frames {
                sampler.heights(&fields[i % fields.len()], &mut h)?;
                renderer.render_with(&h, sampler.m_per_px as f32, &mut scratch, &mut out)?;
            }
            fps.push(frames as f64 / t0.elapsed().as_secs_f64());
        }
        Ok(())
    })?;
    let mut sorted = fps.clone();
    sorted.sort_by(f64::total_cmp);
    Ok(RenderBench {
        threads,
        frames,
        median_fps: sorted[sorted.len() / 2],
        fps,
        size: [sampler.rows, sampler.cols],
    })
}

/// A rayon thread pool (rendering on a fixed number of cores).
pub type Pool = rayon::ThreadPool;

/// A pool of `threads` worker threads.
pub fn pool(threads: usize) -> Result<Pool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| TactileError::Input(format!("thread pool: {e}")))
}
