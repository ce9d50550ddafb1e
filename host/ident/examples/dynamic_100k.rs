//! Speed benchmark of a 100,000-row dynamic record (one-mass oscillator with LuGre friction,
//! the CLI's default baseline `auto`, which keeps the state-space model here; goal: within 30 s
//! on 2 cores); prints each run and the median:
//! `cargo run -p ocm-ident --example dynamic_100k -- [RUNS]` (default 3).

use ocm_ident::baseline::SeriesModel;
use ocm_ident::dynamic_generator::{DynSpec, System, generate};
use ocm_ident::{Cause, Config, identify};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let runs: usize = match std::env::args().nth(1) {
        Some(s) => s
            .parse()
            .map_err(|e| format!("RUNS must be a positive integer, got {s:?}: {e}"))?,
        None => 3,
    };
    if runs == 0 {
        return Err("RUNS must be at least 1".into());
    }
    let g = generate(&DynSpec {
        system: System::Oscillator1,
        effects: vec![Cause::Friction],
        seed: 7,
        rows: 100_000,
    });
    let cfg = Config {
        series_model: SeriesModel::Auto,
        ..Config::default()
    };
    let mut secs = Vec::new();
    for run in 0..runs {
        let t0 = std::time::Instant::now();
        let id = identify(&g.record, &cfg)?;
        let s = t0.elapsed().as_secs_f64();
        println!(
            "run {}: {s:.1} s, named {:?}, held-out gain {:.1} %",
            run + 1,
            id.report.causes,
            id.report.gain_pct
        );
        secs.push(s);
    }
    secs.sort_by(f64::total_cmp);
    println!(
        "100k-row dynamic record: median {:.1} s of {runs} runs (min {:.1}, max {:.1})",
        secs[runs / 2],
        secs[0],
        secs[runs - 1]
    );
    Ok(())
}
