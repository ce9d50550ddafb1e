//! Hidden effects inside the dynamics of oscillators, identified as `ocm ident` does by default
//! (`SeriesModel::Auto`: the linear state-space baseline with free-run predictions, or the
//! static map where that fits better, which no record of these dynamic systems may choose). `OCM_DYN_SEEDS` sets the seeds per case (default 3),
//! `OCM_DYN_SEED0` the first seed (default 1000), `OCM_DYN_SYSTEMS` the systems (a
//! comma-separated subset of `oscillator1,oscillator2,chamber`, default all three).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use ocm_ident::baseline::SeriesModel;
use ocm_ident::dynamic_generator::{DynGenerated, DynSpec, EFFECTS, System, generate};
use ocm_ident::{Cause, Config, Report, identify};

/// A record of `effects` on `system` (2000 rows), generated and identified with the CLI's
/// default baseline once per test binary: the battery, the pairs and the focused tests below share
/// records (the chamber cubic of seed 1001, the one-mass hysteresis+friction of seed 5000),
/// and each costs seconds. A test that asks for a record another is identifying waits for it.
fn identified(system: System, effects: &[Cause], seed: u64) -> Arc<(DynGenerated, Report)> {
    type Cell = Arc<OnceLock<Arc<(DynGenerated, Report)>>>;
    static MEMO: OnceLock<Mutex<HashMap<(String, u64), Cell>>> = OnceLock::new();
    let cell = MEMO
        .get_or_init(Default::default)
        .lock()
        .expect("the memo's lock")
        .entry((format!("{system:?} {effects:?}"), seed))
        .or_default()
        .clone();
    cell.get_or_init(|| {
        let g = generate(&DynSpec {
            system,
            effects: effects.to_vec(),
            seed,
            rows: 2000,
        });
        let cfg = Config {
            series_model: SeriesModel::Auto,
            ..Config::default()
        };
        let r = identify(&g.record, &cfg).unwrap().report;
        Arc::new((g, r))
    })
    .clone()
}

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
    let cases: Vec<(System, Cause, u64)> = systems()
        .into_iter()
        .flat_map(|system| {
            std::iter::once(Cause::None)
                .chain(EFFECTS)
                .flat_map(move |effect| (0..seeds).map(move |seed| (system, effect, seed)))
        })
        .collect();
    // two workers (the records are independent): half the wall-clock time on two cores
    let outcomes: Vec<(Cause, bool, bool)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|w| {
                let cases = &cases;
                scope.spawn(move || {
                    cases
                        .iter()
                        .skip(w)
                        .step_by(2)
                        .map(|&(system, effect, seed)| {
                            let memo = identified(system, &[effect], seed0 + seed);
                            let (g, r) = &*memo;
                            let ok = r.causes == [effect];
                            let stat = is_static(r);
                            eprintln!(
                                "{system:?} {effect} seed {seed}: named {:?} ({}{}), ratio {:.1}, gain {:.1} %, {}",
                                r.causes,
                                if ok { "ok" } else { "MISS" },
                                if stat { ", STATIC MAP" } else { "" },
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
                            (effect, ok, stat)
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
    let statics = outcomes.iter().filter(|o| o.2).count();
    for (effect, ok, _) in outcomes {
        if effect == Cause::None {
            false_alarms += usize::from(!ok);
        } else {
            total += 1;
            correct += usize::from(ok);
        }
    }
    eprintln!("dynamic battery: {correct} / {total} correct, {false_alarms} false alarms");
    // the 95 %: measured 26, 24, 26 and 27 of 27 from seeds 1000, 1003, 1006 and 1009
    // (103 of 108), no false alarm on 9 clean records each (README, "Test time and the
    // structure searches' cost")
    assert!(total > 0);
    assert_eq!(
        statics, 0,
        "{statics} records of dynamic systems took the static map"
    );
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
    let cases: Vec<(System, [Cause; 2], u64)> = systems()
        .into_iter()
        .flat_map(|system| {
            PAIRS
                .into_iter()
                .flat_map(move |pair| (0..seeds).map(move |s| (system, pair, seed0 + s)))
        })
        .collect();
    let outcomes: Vec<(bool, bool, bool, bool)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|w| {
                let cases = &cases;
                scope.spawn(move || {
                    cases
                        .iter()
                        .skip(w)
                        .step_by(2)
                        .map(|(system, pair, seed)| {
                            let memo = identified(*system, pair, *seed);
                            let (g, r) = &*memo;
                            let named = &r.causes;
                            let counts = g.ratios.iter().all(|r| *r >= 3.0);
                            let exact = named.len() == 2 && pair.iter().all(|c| named.contains(c));
                            let one = pair.iter().any(|c| named.contains(c));
                            let stat = is_static(r);
                            eprintln!(
                                "{system:?} {}+{} seed {seed}: named {named:?} ({}{}), ratios {:.1?}, gain {:.1} %, {}",
                                pair[0],
                                pair[1],
                                if !counts {
                                    "not counted"
                                } else if exact {
                                    "exact"
                                } else {
                                    "MISS"
                                },
                                if stat { ", STATIC MAP" } else { "" },
                                g.ratios,
                                r.gain_pct,
                                g.details
                            );
                            // the evidence per candidate, to see why a pair is missed:
                            // cause gain/score/accepted, singles then additions
                            eprintln!(
                                "  singles: {}\n  additions: {}",
                                ocm_ident::select::evidence(&r.candidates),
                                ocm_ident::select::evidence(&r.additions)
                            );
                            (counts, exact, one, stat)
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
    let statics = outcomes.iter().filter(|o| o.3).count();
    assert_eq!(
        statics, 0,
        "{statics} records of dynamic systems took the static map"
    );
    // every counted record names at least one of its two effects
    assert_eq!(neither, 0, "{neither} records name neither effect");
    assert!(
        exact * 100 >= PAIR_FLOOR_PCT * counted,
        "{exact} / {counted}"
    );
}

/// Whether the report's baseline is the static map ([`SeriesModel::Auto`] chose it).
fn is_static(r: &Report) -> bool {
    r.baseline.starts_with("static affine map")
}

/// The pairs of the dynamic battery.
const PAIRS: [[Cause; 2]; 3] = [
    [Cause::Hysteresis, Cause::Nonlinearity],
    [Cause::Friction, Cause::Nonlinearity],
    [Cause::Hysteresis, Cause::Friction],
];

/// Regression floor of the exact-pair share, percent: measured 7 of 9 on this seed (5000) and
/// 57 of 68 (83.8 %, the 80 %) over seeds 5000-5007 since the force may enter after an
/// actuator's lag; 6 of 9 here with the lower orders alone, 2 of 9 before the flexible starts.
const PAIR_FLOOR_PCT: usize = 66;

/// Friction and hysteresis are classes of widths (the README's "Friction and hysteresis as
/// classes of widths"): on one mass, a LuGre friction alone is named `friction`, and a
/// Bouc-Wen loop beside a LuGre friction is named as both. While the hysteresis extension held
/// friction's pre-sliding stop and its flexible variant narrower ones, the first record was
/// named `hysteresis` and the second `hysteresis` alone.
#[test]
fn friction_and_hysteresis_are_told_apart_by_the_width_of_their_loops() {
    for (effects, expected) in [
        (vec![Cause::Friction], vec![Cause::Friction]),
        (
            vec![Cause::Hysteresis, Cause::Friction],
            vec![Cause::Friction, Cause::Hysteresis],
        ),
    ] {
        // the second record is one of the pairs' (seed 5000): identified once
        let memo = identified(System::Oscillator1, &effects, 5000);
        let r = &memo.1;
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
    // one of the battery's records (its default seeds): identified once
    let memo = identified(System::Chamber, &[Cause::Nonlinearity], 1001);
    let r = &memo.1;
    assert_eq!(r.causes, [Cause::Nonlinearity], "{}", r.verdict);
    assert!(r.gain_pct > 95.0, "{}", r.verdict);
    assert!(
        r.baseline.contains("after a lag of"),
        "the force should enter after the filling's lag: {}",
        r.baseline
    );
}

/// The structure searches wait for a residual above the noise (`structure_search_ratio`): the
/// chamber cubic of seed 1001 leaves some 13 times the noise after the first selection, so by
/// default its lower orders and lags are searched (the test above); with the ratio set beyond
/// that, the baseline keeps its order and the input's entry, and the cubic explains less.
#[test]
fn the_structure_searches_wait_for_a_residual_above_the_noise() {
    let searched = identified(System::Chamber, &[Cause::Nonlinearity], 1001);
    let cfg = Config {
        series_model: SeriesModel::StateSpace,
        structure_search_ratio: 1e6,
        ..Config::default()
    };
    let r = identify(&searched.0.record, &cfg).unwrap().report;
    assert!(
        !r.baseline.contains("lower order") && !r.baseline.contains("after a lag of"),
        "nothing should have been searched: {}",
        r.baseline
    );
    assert!(
        r.baseline.contains("structure searches were skipped"),
        "the report should say so: {}",
        r.baseline
    );
    assert!(
        !searched.1.baseline.contains("skipped"),
        "{}",
        searched.1.baseline
    );
    assert!(
        r.gain_pct < searched.1.gain_pct - 10.0,
        "unsearched {:.1} % against searched {:.1} %",
        r.gain_pct,
        searched.1.gain_pct
    );
}
