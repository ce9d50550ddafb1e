//! The SIL loop of the bench (`cargo bench -p ocm-hilsim --bench plant --
//! sil`) as a plain program, a target for instruction-count profilers: the
//! in-process firmware in closed loop on the short circle, `--runs N` times
//! (default 1), with the LUT built once. Prints each run's RMSE and
//! realtime factor and the median factor.
//!
//! `valgrind --tool=callgrind --toggle-collect='*scenario*simulate*simulate'
//! target/release/examples/sil` counts the closed-loop ticks alone; divide
//! by 13,000 for instructions per tick.

use ocm_hilsim::firmware::{FirmwareMcu, LUT_CAPACITY, lut_image};
use ocm_hilsim::{SimConfig, run_with_mcu};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut runs = 1usize;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--runs" => runs = args.next().ok_or("--runs needs a value")?.parse()?,
            other => return Err(format!("unknown argument {other:?}").into()),
        }
    }
    // The bench's configuration: short circle, logging off.
    let cfg = SimConfig {
        short: true,
        log_every: 1_000_000,
        ..SimConfig::default()
    };
    let image = lut_image(&cfg.plant, &cfg.limits)?;
    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut factors = Vec::with_capacity(runs);
    for _ in 0..runs {
        let mut fw = FirmwareMcu::in_process(&mut buf, &image, &cfg, true)?;
        let r = run_with_mcu("circle", &cfg, &mut fw)?;
        println!(
            "rmse {:.6} mm, {} s simulated, {:.0}x real time",
            r.rmse_mm, r.sim_s, r.realtime_factor
        );
        factors.push(r.realtime_factor);
    }
    factors.sort_by(f64::total_cmp);
    println!("median {:.0}x real time", factors[factors.len() / 2]);
    Ok(())
}
