//! Counts out of range on the command line get an error naming the flag, before any file is
//! read or any work is done (each used to crash, exhaust the memory or hang).

use std::process::Command;

/// Runs `ocm ARGS`, which must fail cleanly (an error, not a crash), and returns its stderr.
/// `RUST_BACKTRACE` is set, as on many developers' machines: a refused input still prints
/// its message alone, without a backtrace.
fn fails(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .env_remove("OCM_ERROR_BACKTRACE")
        .output()
        .expect("the ocm binary runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "ocm {args:?}: {err}");
    assert!(!err.contains("panicked"), "ocm {args:?}: {err}");
    assert!(
        !err.to_lowercase().contains("backtrace"),
        "ocm {args:?}: {err}"
    );
    assert!(err.starts_with("Error: "), "ocm {args:?}: {err}");
    err
}

#[test]
fn learn_bench_refuses_an_empty_or_huge_batch() {
    // --batch 0 reached the matrix kernels with zero-sized operands and crashed (SIGSEGV)
    for batch in ["0", "1000000000000"] {
        let e = fails(&[
            "learn",
            "bench",
            "--forward",
            "no-such.ckpt",
            "--batch",
            batch,
        ]);
        assert!(
            e.contains(&format!(
                "--batch must be between 1 and 1048576, got {batch}"
            )),
            "{e}"
        );
    }
}

#[test]
fn rl_refuses_zero_evaluation_episodes_before_training() {
    // zero episodes left the plots an empty range, on which the axis search never ended
    let e = fails(&[
        "rl",
        "eval",
        "--model",
        "no-such.json",
        "--task",
        "circle",
        "--episodes",
        "0",
    ]);
    assert!(e.contains("--episodes must be at least 1"), "{e}");
    let e = fails(&[
        "rl",
        "train",
        "--model",
        "no-such.json",
        "--task",
        "circle",
        "--eval-episodes",
        "0",
        "--out",
        "no-such-dir",
    ]);
    assert!(e.contains("--eval-episodes must be at least 1"), "{e}");
}

#[test]
fn ident_synth_refuses_a_row_count_beyond_its_cap() {
    let out = std::env::temp_dir().join(format!("ocm-synth-{}.csv", std::process::id()));
    let e = fails(&[
        "ident",
        "synth",
        out.to_str().unwrap(),
        "--rows",
        "18446744073709551615",
    ]);
    assert!(e.contains("--rows must be between 100 and 1000000"), "{e}");
    assert!(!out.exists());
}

/// Runs `ocm ARGS`, which clap must refuse as a usage error (exit code 2) naming `flag`.
fn refused_flag(args: &[&str], flag: &str, why: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("the ocm binary runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "ocm {args:?}: {err}");
    assert!(
        err.contains("invalid value") && err.contains(flag) && err.contains(why),
        "ocm {args:?}: {err}"
    );
}

#[test]
fn zero_counts_and_non_finite_numbers_are_refused_naming_the_flag() {
    // each of these ran to an empty "successful" result, or was clamped silently
    for (args, flag) in [
        (&["mor", "snapshots", "--steps", "0"][..], "--steps"),
        (&["mor", "reduce", "--every", "0"], "--every"),
        (&["rl", "bench", "--repeats", "0"], "--repeats"),
        (&["rl", "bench", "--envs", "0"], "--envs"),
        (&["tactile", "dataset", "--threads", "0"], "--threads"),
        (&["peg", "replay", "--every", "0"], "--every"),
        (&["npe", "bench", "--calls", "0"], "--calls"),
        (
            &["peg", "train", "x", "--out", "y", "--dagger-trials", "0"],
            "--dagger-trials",
        ),
    ] {
        refused_flag(args, flag, "must be at least 1");
    }
    refused_flag(
        &["learn", "eval", "--horizon-s", "nan"],
        "--horizon-s",
        "finite",
    );
    refused_flag(
        &["npe", "train", "--lambda-total=-1"],
        "--lambda-total",
        "must be 0 or more",
    );
    refused_flag(
        &["peg", "demos", "--out", "x", "--pad-friction", "nan"],
        "--pad-friction",
        "finite",
    );
    refused_flag(
        &["peg", "eval", "x", "--pad-friction=-1"],
        "--pad-friction",
        "greater than 0",
    );
    refused_flag(
        &["peg", "demos", "--out", "x", "--noise-correlation-s=-0.5"],
        "--noise-correlation-s",
        "must be 0 or more",
    );
    refused_flag(
        &["peg", "eval", "x", "--noise-correlation-s", "nan"],
        "--noise-correlation-s",
        "finite",
    );
    refused_flag(
        &["peg", "demos", "--out", "x", "--hole-error-mm=-1"],
        "--hole-error-mm",
        "must be 0 or more",
    );
    refused_flag(
        &["peg", "eval", "x", "--hole-error-mm", "inf"],
        "--hole-error-mm",
        "finite",
    );
    refused_flag(
        &["peg", "demos", "--out", "x", "--time-limit-s", "0"],
        "--time-limit-s",
        "greater than 0",
    );
    for args in [
        &["npe", "train", "--lr-final", "1.5"][..],
        &["learn", "train", "--lr-final=-0.1"],
    ] {
        refused_flag(args, "--lr-final", "must lie between 0 and 1");
    }
}

#[test]
fn dagger_rounds_beyond_the_cap_are_refused_before_anything_is_read() {
    let e = fails(&[
        "peg",
        "train",
        "no-such-dir",
        "--out",
        "no-such-out",
        "--dagger-rounds",
        "21",
    ]);
    assert!(e.contains("dagger rounds = 21: need 1 to 20"), "{e}");
    assert!(!std::path::Path::new("no-such-out").exists());
}

#[test]
fn a_dataset_of_only_random_placements_needs_some() {
    let e = fails(&[
        "tactile",
        "dataset",
        "--random-only",
        "--out",
        "no-such-dir",
    ]);
    assert!(e.contains("--random is 0"), "{e}");
}

#[test]
fn malformed_shards_and_states_name_their_flag() {
    for shard in ["x/4", "1/y", "3"] {
        let e = fails(&[
            "mor",
            "dataset",
            "--model",
            "full",
            "--samples",
            "10",
            "--shard",
            shard,
            "--out",
            "no-such-dir",
        ]);
        assert!(e.contains(&format!("--shard '{shard}' must be I/N")), "{e}");
    }
    for state in ["1:2", "1:x:3", "1:nan:3"] {
        let e = fails(&["fem", "calibrate", "grid", "--states", state]);
        assert!(
            e.contains(&format!("--states: '{state}' must be three")),
            "{e}"
        );
    }
}

#[test]
fn compare_real_candidates_are_checked_before_any_work() {
    refused_flag(
        &["tactile", "compare-real", "--threshold", "10,0"],
        "--threshold",
        "must be greater than 0",
    );
    refused_flag(
        &["tactile", "compare-real", "--pitch-deg=0,nan"],
        "--pitch-deg",
        "finite",
    );
    refused_flag(
        &["tactile", "compare-real", "--crown-radius-mm=20,-5"],
        "--crown-radius-mm",
        "must be 0 or more",
    );
    refused_flag(
        &["tactile", "compare-real", "--mm-per-px", "0"],
        "--mm-per-px",
        "must be greater than 0",
    );
    refused_flag(
        &["tactile", "compare-real", "--steps-per-frame=1,-1.2"],
        "--steps-per-frame",
        "must be greater than 0",
    );
    refused_flag(
        &["tactile", "compare-real", "--skin-um=100,-5"],
        "--skin-um",
        "must be 0 or more",
    );
    refused_flag(
        &["tactile", "compare-real", "--fem-slope=0.06,-0.1"],
        "--fem-slope",
        "must be 0 or more",
    );
    refused_flag(
        &["tactile", "compare-real", "--skin-stiffness=3,0"],
        "--skin-stiffness",
        "must be greater than 0",
    );
    refused_flag(
        &[
            "tactile",
            "indent",
            "--setup",
            "edge6",
            "--skin-stiffness=nan",
        ],
        "--skin-stiffness",
        "finite",
    );
    // a fitted map belongs to one tilt, crown and threshold; several candidates with it are
    // refused before the frames, the mesh or the FEM are touched
    for (candidates, n) in [
        ("--roll-deg=-2,0,2", 3),
        ("--crown-radius-mm=0,20", 2),
        ("--steps-per-frame=1,1.2", 2),
        ("--skin-stiffness=3,10", 2),
        ("--fem-slope=0,0.06,0.1", 3),
    ] {
        let e = fails(&[
            "tactile",
            "compare-real",
            "--fit",
            "no-such-map.json",
            candidates,
            "--data",
            "no-such-dir",
        ]);
        assert!(
            e.contains("--fit reuses a fitted map") && e.contains(&format!("{n} candidates")),
            "{e}"
        );
    }
    // a map fitted on a crown of another cap (one without the key predates the cap's change
    // from 0.5) belongs to another gel shape: refused before the data are read; a flat map
    // has no cap and passes this check (then fails on the missing data directory)
    let map = std::env::temp_dir().join(format!("ocm-old-map-{}.json", std::process::id()));
    for (json, refused) in [
        (r#"{"crown_radius_mm": 20, "offset_steps": 11}"#, true),
        (
            r#"{"crown_radius_mm": 20, "crown_cap_share": 0.5, "offset_steps": 11}"#,
            true,
        ),
        (r#"{"crown_radius_mm": 0, "offset_steps": 11}"#, false),
    ] {
        std::fs::write(&map, json).unwrap();
        let e = fails(&[
            "tactile",
            "compare-real",
            "--fit",
            map.to_str().unwrap(),
            "--data",
            "no-such-dir",
        ]);
        assert_eq!(
            e.contains("capped at 0.5") && e.contains("rerun compare-real without --fit"),
            refused,
            "{json}: {e}"
        );
        assert_eq!(e.contains("no-such-dir"), !refused, "{json}: {e}");
    }
    let _ = std::fs::remove_file(&map);
}

#[test]
fn an_error_prints_its_causes_and_a_backtrace_only_when_asked() {
    let missing = "no-such-dir/no-such.lut";
    let e = fails(&["lut", "check", missing]);
    assert!(e.contains(&format!("reading LUT image {missing}")), "{e}");
    assert!(e.contains("Caused by:"), "{e}");
    let out = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(["lut", "check", missing])
        .env("RUST_BACKTRACE", "1")
        .env("OCM_ERROR_BACKTRACE", "1")
        .output()
        .expect("the ocm binary runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("Stack backtrace"), "{err}");
}
