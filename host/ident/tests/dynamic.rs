//! Hidden effects inside the dynamics of oscillators, identified on the linear state-space
//! baseline (free-run predictions). `OCM_DYN_SEEDS` sets the seeds per case (default 3),
//! `OCM_DYN_SEED0` the first seed (default 1000).

use ocm_ident::baseline::SeriesModel;
use ocm_ident::dynamic_generator::{DynSpec, EFFECTS, System, generate};
use ocm_ident::{Cause, Config, identify};

#[test]
fn dynamic_battery_names_the_hidden_effect_and_nothing_on_clean_records() {
    let seeds: u64 = std::env::var("OCM_DYN_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    // the first seed (`OCM_DYN_SEED0`, default 1000): other values check fresh records
    let seed0: u64 = std::env::var("OCM_DYN_SEED0")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        ..Config::default()
    };
    let cases: Vec<(System, Cause, u64)> = [System::Oscillator1, System::Oscillator2]
        .into_iter()
        .flat_map(|system| {
            std::iter::once(Cause::None)
                .chain(EFFECTS)
                .flat_map(move |effect| (0..seeds).map(move |seed| (system, effect, seed)))
        })
        .collect();
    // two workers (the records are independent): half the wall-clock time on two cores
    let outcomes: Vec<(Cause, bool)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|w| {
                let cases = &cases;
                let cfg = &cfg;
                scope.spawn(move || {
                    cases
                        .iter()
                        .skip(w)
                        .step_by(2)
                        .map(|&(system, effect, seed)| {
                            let g = generate(&DynSpec {
                                system,
                                effect,
                                seed: seed0 + seed,
                                rows: 2000,
                            });
                            let id = identify(&g.record, cfg).unwrap();
                            let r = &id.report;
                            let ok = r.causes == [effect];
                            eprintln!(
                                "{system:?} {effect} seed {seed}: named {:?} ({}), ratio {:.1}, gain {:.1} %, {}",
                                r.causes,
                                if ok { "ok" } else { "MISS" },
                                g.ratio,
                                r.gain_pct,
                                g.details
                            );
                            (effect, ok)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|h| h.join().expect("a battery worker panicked"))
            .collect()
    });
    let mut correct = 0;
    let mut total = 0;
    let mut false_alarms = 0;
    for (effect, ok) in outcomes {
        if effect == Cause::None {
            false_alarms += usize::from(!ok);
        } else {
            total += 1;
            correct += usize::from(ok);
        }
    }
    eprintln!("dynamic battery: {correct} / {total} correct, {false_alarms} false alarms");
    // regression bounds of the measured figures (3 seeds: 16 of 18 correct, no false alarm on
    // 6 clean records; 10 seeds: 55 of 60, none on 20; fresh seeds 2000-2009: 50 of 60, none
    // on 20); the 95 % is not reached, see the README
    assert!(total > 0);
    assert_eq!(false_alarms, 0, "{false_alarms} false alarms");
    assert!(correct * 100 >= 80 * total, "{correct} / {total}");
}

/// The speed figure of a 100k-row dynamic record (no assertion on time: run it with
/// `--ignored --nocapture` and read the figure; the identification itself must still work).
#[test]
#[ignore]
fn dynamic_100k_record_figure() {
    let g = generate(&DynSpec {
        system: System::Oscillator1,
        effect: Cause::Friction,
        seed: 7,
        rows: 100_000,
    });
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        ..Config::default()
    };
    let t0 = std::time::Instant::now();
    let id = identify(&g.record, &cfg).unwrap();
    eprintln!(
        "100k-row dynamic record: {:.1} s, named {:?}, gain {:.1} %",
        t0.elapsed().as_secs_f64(),
        id.report.causes,
        id.report.gain_pct
    );
    assert!(id.report.causes.contains(&Cause::Friction));
}
