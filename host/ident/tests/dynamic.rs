//! Hidden effects inside the dynamics of oscillators, identified on the linear state-space
//! baseline (free-run predictions). `OCM_DYN_SEEDS` sets the seeds per case (default 3),
//! `OCM_DYN_SEED0` the first seed (default 1000), `OCM_DYN_SYSTEMS` the systems (a
//! comma-separated subset of `oscillator1,oscillator2,chamber`, default all three).

use ocm_ident::baseline::SeriesModel;
use ocm_ident::dynamic_generator::{DynSpec, EFFECTS, System, generate};
use ocm_ident::{Cause, Config, identify};

/// The systems of the battery: `OCM_DYN_SYSTEMS` or all.
fn systems() -> Vec<System> {
    let all = [
        ("oscillator1", System::Oscillator1),
        ("oscillator2", System::Oscillator2),
        ("chamber", System::Chamber),
    ];
    match std::env::var("OCM_DYN_SYSTEMS") {
        Ok(list) => list
            .split(',')
            .map(|name| {
                all.iter()
                    .find(|(n, _)| *n == name.trim())
                    .unwrap_or_else(|| panic!("OCM_DYN_SYSTEMS: unknown system {name:?}"))
                    .1
            })
            .collect(),
        Err(_) => all.iter().map(|(_, s)| *s).collect(),
    }
}

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
    let cases: Vec<(System, Cause, u64)> = systems()
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
                                effects: vec![effect],
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
                            if !ok {
                                // why: every candidate's held-out gain / score / acceptance,
                                // alone and as additions to the named set
                                eprintln!(
                                    "  singles: {}\n  additions: {}",
                                    ocm_ident::select::evidence(&r.candidates),
                                    ocm_ident::select::evidence(&r.additions)
                                );
                            }
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
    // the 95 %: measured 27 of 27 on seeds 1000-1002 and on 1003-1005, 25 of 27 on the
    // never-used 1006-1008 (the internal coordinate's scale fixed, friction's pre-sliding stop
    // shared with hysteresis, the dissipative sign from the step response; see the README);
    // no false alarm on 9 clean records each
    assert!(total > 0);
    assert_eq!(false_alarms, 0, "{false_alarms} false alarms");
    assert!(correct * 100 >= 95 * total, "{correct} / {total}");
}

/// Two effects inside the dynamics at once. `OCM_DYN_PAIR_SEEDS` sets the seeds per pair and
/// system (default 1, to keep CI short), `OCM_DYN_PAIR_SEED0` the first seed (default 5000). A record counts
/// when each effect alone reaches 3x the noise; it is exact when the named causes are the two.
#[test]
fn dynamic_pairs_name_both_effects() {
    let env = |k: &str, d: u64| -> u64 {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let seeds = env("OCM_DYN_PAIR_SEEDS", 1);
    let seed0 = env("OCM_DYN_PAIR_SEED0", 5000);
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        ..Config::default()
    };
    let cases: Vec<(System, [Cause; 2], u64)> = systems()
        .into_iter()
        .flat_map(|system| {
            PAIRS
                .into_iter()
                .flat_map(move |pair| (0..seeds).map(move |s| (system, pair, seed0 + s)))
        })
        .collect();
    let outcomes: Vec<(bool, bool, bool)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|w| {
                let (cases, cfg) = (&cases, &cfg);
                scope.spawn(move || {
                    cases
                        .iter()
                        .skip(w)
                        .step_by(2)
                        .map(|(system, pair, seed)| {
                            let g = generate(&DynSpec {
                                system: *system,
                                effects: pair.to_vec(),
                                seed: *seed,
                                rows: 2000,
                            });
                            let id = identify(&g.record, cfg).unwrap();
                            let named = &id.report.causes;
                            let counts = g.ratios.iter().all(|r| *r >= 3.0);
                            let exact = named.len() == 2 && pair.iter().all(|c| named.contains(c));
                            let one = pair.iter().any(|c| named.contains(c));
                            eprintln!(
                                "{system:?} {}+{} seed {seed}: named {named:?} ({}), ratios {:.1?}, gain {:.1} %, {}",
                                pair[0],
                                pair[1],
                                if !counts {
                                    "not counted"
                                } else if exact {
                                    "exact"
                                } else {
                                    "MISS"
                                },
                                g.ratios,
                                id.report.gain_pct,
                                g.details
                            );
                            // the evidence per candidate, to see why a pair is missed:
                            // cause gain/score/accepted, singles then additions
                            eprintln!(
                                "  singles: {}\n  additions: {}",
                                ocm_ident::select::evidence(&id.report.candidates),
                                ocm_ident::select::evidence(&id.report.additions)
                            );
                            (counts, exact, one)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|h| h.join().expect("a pair worker panicked"))
            .collect()
    });
    let counted = outcomes.iter().filter(|o| o.0).count();
    let exact = outcomes.iter().filter(|o| o.0 && o.1).count();
    let neither = outcomes.iter().filter(|o| o.0 && !o.2).count();
    eprintln!("dynamic pairs: {exact} / {counted} exact, {neither} with neither effect named");
    assert!(counted > 0);
    // every counted record names at least one of its two effects
    assert_eq!(neither, 0, "{neither} records name neither effect");
    assert!(
        exact * 100 >= PAIR_FLOOR_PCT * counted,
        "{exact} / {counted}"
    );
}

/// The pairs of the dynamic battery.
const PAIRS: [[Cause; 2]; 3] = [
    [Cause::Hysteresis, Cause::Nonlinearity],
    [Cause::Friction, Cause::Nonlinearity],
    [Cause::Hysteresis, Cause::Friction],
];

/// Regression floor of the exact-pair share, percent: measured 6 of 9 with one seed (seed
/// 5000) since a named cause sends the selection to the baseline's lower orders too (4 of 9
/// before, 2 of 9 before ordinary sets started from the flexible variants). The 80 %
/// is not reached, see the README.
const PAIR_FLOOR_PCT: usize = 66;

/// Friction and hysteresis are classes of widths (the README's "Friction and hysteresis as
/// classes of widths"): on one mass, a LuGre friction alone is named `friction`, and a
/// Bouc-Wen loop beside a LuGre friction is named as both. While the hysteresis extension held
/// friction's pre-sliding stop and its flexible variant narrower ones, the first record was
/// named `hysteresis` and the second `hysteresis` alone.
#[test]
fn friction_and_hysteresis_are_told_apart_by_the_width_of_their_loops() {
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        ..Config::default()
    };
    for (effects, expected) in [
        (vec![Cause::Friction], vec![Cause::Friction]),
        (
            vec![Cause::Hysteresis, Cause::Friction],
            vec![Cause::Friction, Cause::Hysteresis],
        ),
    ] {
        let g = generate(&DynSpec {
            system: System::Oscillator1,
            effects: effects.clone(),
            seed: 5000,
            rows: 2000,
        });
        let r = identify(&g.record, &cfg).unwrap().report;
        let mut named = r.causes.clone();
        named.sort_by_key(|c| c.name());
        let mut want = expected.clone();
        want.sort_by_key(|c| c.name());
        assert_eq!(named, want, "{effects:?}: {}", r.verdict);
        assert!(r.gain_pct > 75.0, "{effects:?}: {}", r.verdict);
    }
}

/// Where the force enters (README, "Where the force enters: a property of the baseline"): on
/// a pneumatic chamber the supply reaches the piston through the filling's lag, while a
/// stiffening spring acts on the piston itself. Entering where the input does, the cubic of
/// seed 1001 explained 68 % of the held-out error and left 13x the noise; entering after the
/// lag read off a lower order's real pole, it explains more than 95 % and is named alone.
#[test]
fn a_chamber_stiffening_acts_after_the_filling_lag() {
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        ..Config::default()
    };
    let g = generate(&DynSpec {
        system: System::Chamber,
        effects: vec![Cause::Nonlinearity],
        seed: 1001,
        rows: 2000,
    });
    let id = identify(&g.record, &cfg).unwrap();
    let r = &id.report;
    assert_eq!(r.causes, [Cause::Nonlinearity], "{}", r.verdict);
    assert!(r.gain_pct > 95.0, "{}", r.verdict);
    assert!(
        r.baseline.contains("after a lag of"),
        "the force should enter after the filling's lag: {}",
        r.baseline
    );
}
