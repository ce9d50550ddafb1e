//! Inference throughput of the perception and rendering networks: `cargo run -p ocm-tactile
//! --example nets_bench -- [scale] [threads] [batch] [repeats] [burn] [train]` (defaults 1 =
//! 240 x 320, 2 threads, batches of 8, 5 repeats; `burn` also times burn's graph, `train` a
//! forward and backward pass on burn's autodiff device).
//! Freshly initialised networks of the exact architecture (the time does not depend on the
//! weights); one JSON line per network and engine: the plain engine in f32 ("plain"), in
//! bfloat16 ("plain-bf16") and in f32 by Winograd's F(4 x 4, 3 x 3) ("plain-winograd"), the
//! last two with their outputs' RMS difference from f32's.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, d: usize| args.get(i).map_or(Ok(d), |s| s.parse::<usize>());
    let scale = arg(1, 1)?;
    let threads = arg(2, 2)?;
    let batch = arg(3, 8)?;
    let repeats = arg(4, 5)?;
    let extra = |w: &str| args.iter().skip(5).any(|s| s == w);
    let (with_burn, with_train) = (extra("burn"), extra("train"));
    let (rows, cols) = (
        ocm_tactile::real::ROWS / scale,
        ocm_tactile::real::COLS / scale,
    );
    let pool = ocm_tactile::optics::bench::pool(threads)?;
    for kind in [
        ocm_tactile::nets::NetKind::Perception,
        ocm_tactile::nets::NetKind::Rendering,
    ] {
        let b = pool.install(|| {
            ocm_tactile::nets::bench::bench_inference(
                kind, rows, cols, batch, repeats, with_burn, with_train,
            )
        })?;
        for r in b {
            println!("{}", serde_json::to_string(&r)?);
        }
    }
    Ok(())
}
