//! `ocm track` end to end: the virtual lab's summary, determinism and logs.

mod common;

use std::process::Command;

fn track(args: &[&str]) -> serde_json::Value {
    common::json_summary(
        Command::new(env!("CARGO_BIN_EXE_ocm"))
            .arg("track")
            .args(args),
    )
}

/// Runs `ocm track ARGS`, which must fail, and returns its standard error.
fn track_fails(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .arg("track")
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("the ocm binary runs");
    assert!(!out.status.success(), "ocm track {args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The controllers of a scenario summary, in order.
fn controllers(r: &serde_json::Value) -> Vec<&str> {
    r["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["controller"].as_str().unwrap())
        .collect()
}

#[test]
fn circle_summary_orders_the_controllers_and_is_deterministic() {
    let a = track(&["--short", "--scenario", "circle", "--seed", "7", "--json"]);
    let (ol, cl, oracle) = (
        a["ol_rmse_mm"].as_f64().unwrap(),
        a["cl_rmse_mm"].as_f64().unwrap(),
        a["oracle_rmse_mm"].as_f64().unwrap(),
    );
    assert!(cl < 0.5 * ol, "closed loop {cl} mm vs open loop {ol} mm");
    // The lab's bound (hil-sim/tests/firmware.rs): the oracle reads the hysteresis state.
    assert!(
        cl <= 2.5 * oracle && cl <= 1.0,
        "closed loop {cl} mm vs oracle {oracle} mm"
    );
    assert!(a["realtime_factor"].as_f64().unwrap() > 0.0);
    let b = track(&["--short", "--scenario", "circle", "--seed", "7", "--json"]);
    for key in ["ol_rmse_mm", "cl_rmse_mm", "oracle_rmse_mm"] {
        assert_eq!(a[key], b[key], "{key} differs between runs with one seed");
    }
}

#[test]
fn logs_and_summary_are_written() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("track_logs");
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(["track", "--short", "--scenario", "triangle", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary[0]["name"], "triangle");
    let csvs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "csv"))
        .collect();
    assert_eq!(csvs.len(), 3, "one log per controller");
    let text = std::fs::read_to_string(csvs[0].path()).unwrap();
    assert!(
        text.lines().next().unwrap().contains("_mm"),
        "units in the header"
    );
    assert!(text.lines().count() > 10);
    // Trajectory against reference and error over time, PNG and SVG.
    for stem in ["triangle_trajectory", "triangle_error"] {
        for ext in ["png", "svg"] {
            let p = dir.join(format!("{stem}.{ext}"));
            let len = std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0);
            assert!(len > 1000, "{} missing or empty", p.display());
        }
    }
    let svg = std::fs::read_to_string(dir.join("triangle_trajectory.svg")).unwrap();
    assert!(svg.contains("firmware_cl") && svg.contains("reference"));
}

#[test]
fn host_controllers_run_on_request() {
    let r = track(&["--short", "--scenario", "circle", "--mcu", "host", "--json"]);
    let runs = controllers(&r);
    assert_eq!(runs, ["open_loop", "host_pid", "oracle"]);
}

#[test]
fn bad_mcu_and_missing_port_are_named() {
    let err = track_fails(&["--mcu", "serial", "--scenario", "circle"]);
    assert!(err.contains("port:PATH"), "{err}");
    let err = track_fails(&["--mcu", "port:/dev/ocm-absent", "--scenario", "circle"]);
    assert!(
        err.contains("/dev/ocm-absent") && err.contains("serial port"),
        "{err}"
    );
}

#[test]
fn unknown_scenario_is_named() {
    let err = track_fails(&["--scenario", "zigzag"]);
    assert!(err.contains("zigzag") && err.contains("circle"), "{err}");
}

#[test]
fn firmware_in_process_closes_the_loop() {
    let r = track(&[
        "--short",
        "--scenario",
        "circle",
        "--mcu",
        "inproc",
        "--json",
    ]);
    let (ol, cl) = (
        r["ol_rmse_mm"].as_f64().unwrap(),
        r["cl_rmse_mm"].as_f64().unwrap(),
    );
    assert!(
        cl < 0.5 * ol,
        "firmware closed loop {cl} mm vs open loop {ol} mm"
    );
    let runs = controllers(&r);
    assert!(
        runs.contains(&"firmware_ol") && runs.contains(&"firmware_cl") && runs.contains(&"oracle"),
        "{runs:?}"
    );
    for run in r["runs"].as_array().unwrap() {
        if let Some(v) = run["figures"].get("limit_violations") {
            assert_eq!(v.as_f64().unwrap(), 0.0, "pressure limits exceeded");
        }
    }
}

#[test]
fn the_example_config_is_the_default_lab_and_bad_keys_are_named() {
    let lab = concat!(env!("CARGO_MANIFEST_DIR"), "/../../hil-sim/lab.toml");
    let args = [
        "--short",
        "--scenario",
        "triangle",
        "--duration",
        "4",
        "--json",
    ];
    let a = track(&args);
    let mut with = args.to_vec();
    with.extend(["--config", lab]);
    let b = track(&with);
    for key in ["ol_rmse_mm", "cl_rmse_mm", "oracle_rmse_mm"] {
        assert_eq!(a[key], b[key], "{key}: lab.toml differs from the defaults");
    }
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    let bad = dir.join("bad_lab.toml");
    std::fs::write(&bad, "[plant.effects]\nstiffness_spred = 0.1\n").unwrap();
    let bad = bad.to_str().unwrap();
    let err = track_fails(&["--scenario", "circle", "--config", bad]);
    assert!(
        err.contains("stiffness_spred") && err.contains("line 2"),
        "{err}"
    );
}

#[test]
fn a_bad_or_foreign_lut_is_named_before_the_run() {
    let dir = std::env::temp_dir().join(format!("ocm-track-lut-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // not an image: the firmware's refusal named neither the file nor the reason
    let junk = dir.join("junk.lut");
    std::fs::write(&junk, vec![7u8; 1000]).unwrap();
    let err = track_fails(&[
        "--short",
        "--scenario",
        "circle",
        "--lut",
        junk.to_str().unwrap(),
    ]);
    assert!(
        err.contains("junk.lut") && err.contains("invalid LUT image"),
        "{err}"
    );
    // an image of the Table 3.1 parameters for the lab's calibrated plant
    let foreign = dir.join("table31.lut");
    let built = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(["lut", "build", "--params", "table-3.1", "--out"])
        .arg(&foreign)
        .output()
        .expect("the ocm binary runs");
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stderr)
    );
    let err = track_fails(&[
        "--short",
        "--scenario",
        "circle",
        "--lut",
        foreign.to_str().unwrap(),
    ]);
    assert!(
        err.contains("table31.lut") && err.contains("built for other OCM parameters"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
