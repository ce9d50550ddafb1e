//! Renderer throughput from FEM displacement fields: `cargo run --release -p ocm-tactile
//! --example render_bench -- FIELDS_DIR [fine|coarse] [frames] [threads]` (the same measurement
//! as `ocm tactile render FIELDS_DIR --bench N`).

use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::mask::Grid;
use ocm_tactile::optics::bench::bench_render;
use ocm_tactile::optics::{CameraMap, PolyCalib, Renderer, RgbImage, SurfaceSampler};
use ocm_tactile::real::{COLS, DEFAULT_BACKGROUND, DEFAULT_CALIB, ROWS, read_cached_steps};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let fields_dir = std::path::PathBuf::from(
        args.get(1)
            .ok_or("usage: FIELDS_DIR [fine|coarse] [frames] [threads]")?,
    );
    let mesh = match args.get(2).map(String::as_str) {
        Some("coarse") => "DIGIT_remesh2.vtk",
        _ => "DIGIT_v8.vtk",
    };
    let frames: usize = args.get(3).map_or(Ok(300), |s| s.parse())?;
    let threads: usize = args.get(4).map_or(Ok(2), |s| s.parse())?;
    let digit = ocm_datadir::data_file(None, "digit")?;
    let gel = Gel::digit(digit.join(mesh), GelMaterial::default())?;
    let calib = PolyCalib::from_npz(digit.join(DEFAULT_CALIB))?;
    let bg = RgbImage::read_sized(digit.join(DEFAULT_BACKGROUND), ROWS, COLS)?;
    let sampler = SurfaceSampler::new(&gel, ROWS, COLS, &CameraMap::for_grid(&Grid::for_gel(&gel)));
    let mut steps = 0;
    while fields_dir.join(format!("u_{:03}.npy", steps + 1)).exists() {
        steps += 1;
    }
    let fields = read_cached_steps(&fields_dir, steps, gel.num_nodes())
        .ok_or("no u_NNN.npy fields of this mesh in FIELDS_DIR")?;
    // Where a frame's time goes: the resampling onto the image alone, then the whole frame.
    let pool = ocm_tactile::optics::bench::pool(threads)?;
    let mut h = vec![0.0f32; ROWS * COLS];
    let mut per_frame = Vec::new();
    pool.install(|| -> ocm_tactile::Result<()> {
        for _ in 0..5 {
            let t0 = std::time::Instant::now();
            for i in 0..frames {
                sampler.heights(&fields[i % fields.len()], &mut h)?;
            }
            per_frame.push(t0.elapsed().as_secs_f64() / frames as f64 * 1e6);
        }
        Ok(())
    })?;
    per_frame.sort_by(f64::total_cmp);
    println!("resampling alone: median {:.0} us per frame", per_frame[2]);
    let (mut sloped, mut total) = (0usize, 0usize);
    for u in &fields {
        sampler.heights(u, &mut h)?;
        let s = ocm_tactile::optics::render::slopes(&h, ROWS, COLS, sampler.m_per_px as f32)?;
        sloped += s
            .iter()
            .filter(|(a, b)| calib.bin(*a, *b) != calib.flat_bin())
            .count();
        total += s.len();
    }
    println!(
        "pixels outside the flat bin: {:.1} % (over the {} fields)",
        100.0 * sloped as f64 / total as f64,
        fields.len()
    );
    for smooth in [0.0, 5.0] {
        let mut r = Renderer::new(calib.clone(), &bg)?;
        r.smooth_px = smooth;
        let b = bench_render(&r, &sampler, &fields, frames, 5, threads)?;
        println!(
            "smoothing {smooth} px: median {:.0} frames/s on {threads} threads ({:?})",
            b.median_fps, b.fps
        );
    }
    Ok(())
}
