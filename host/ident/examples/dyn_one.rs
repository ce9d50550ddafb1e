//! One record of the dynamic battery, identified on the state-space baseline, with every
//! candidate's evidence: `cargo run -p ocm-ident --example dyn_one -- oscillator1 friction 1000`
//! (system `oscillator1|oscillator2|chamber`, effects joined by `+`, seed).

use ocm_ident::baseline::SeriesModel;
use ocm_ident::dynamic_generator::{DynSpec, System, generate};
use ocm_ident::{Cause, Config, identify};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let system = match args.first().map(String::as_str) {
        Some("oscillator2") => System::Oscillator2,
        Some("chamber") => System::Chamber,
        _ => System::Oscillator1,
    };
    let effects: Vec<Cause> = args
        .get(1)
        .map(String::as_str)
        .unwrap_or("none")
        .split('+')
        .map(|e| match e {
            "hysteresis" => Cause::Hysteresis,
            "friction" => Cause::Friction,
            "nonlinearity" => Cause::Nonlinearity,
            _ => Cause::None,
        })
        .collect();
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let g = generate(&DynSpec {
        system,
        effects,
        seed,
        rows: 2000,
    });
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        ..Config::default()
    };
    let id = identify(&g.record, &cfg).expect("identification");
    let r = &id.report;
    println!("baseline: {}", r.baseline);
    println!("verdict: {}", r.verdict);
    println!(
        "named {:?}, ratios {:.1?}, gain {:.1} %, {}",
        r.causes, g.ratios, r.gain_pct, g.details
    );
    for (label, cs) in [("single", &r.candidates), ("addition", &r.additions)] {
        for c in cs.iter() {
            println!(
                "  {label} {}: gain {:.1} %, score {:.0}, p {:.1e}, rmse {:.3e}{}{}",
                c.cause,
                c.gain_pct,
                c.score,
                c.p_value,
                c.rmse,
                if c.accepted { " accepted" } else { "" },
                if c.ill_conditioned { " ILL" } else { "" }
            );
        }
    }
}
