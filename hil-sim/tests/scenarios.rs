//! Scenarios: determinism, the oracle floor, disconnect safety.

use ocm_hilsim::{ControllerKind, SCENARIOS, SimConfig, SimError, run_scenario};

fn short(controllers: Vec<ControllerKind>) -> SimConfig {
    SimConfig {
        short: true,
        controllers,
        ..SimConfig::default()
    }
}

#[test]
fn same_seed_gives_identical_logs() {
    let cfg = short(vec![ControllerKind::HostPid]);
    let a = run_scenario("points", &cfg).expect("run");
    let b = run_scenario("points", &cfg).expect("run");
    let (la, lb) = (
        a.runs[0].csv_bytes().expect("csv"),
        b.runs[0].csv_bytes().expect("csv"),
    );
    assert!(la.len() > 1000);
    assert_eq!(la, lb);
    let other = SimConfig { seed: 2, ..cfg };
    let c = run_scenario("points", &other).expect("run");
    assert_ne!(la, c.runs[0].csv_bytes().expect("csv"));
}

#[test]
fn oracle_tracks_the_circle_closely_and_beats_the_others() {
    let cfg = short(vec![
        ControllerKind::Oracle,
        ControllerKind::OpenLoop,
        ControllerKind::HostPid,
    ]);
    let r = run_scenario("circle", &cfg).expect("run");
    let oracle = r.oracle_rmse_mm.expect("oracle ran");
    let ol = r.ol_rmse_mm.expect("ol ran");
    let cl = r.cl_rmse_mm.expect("cl ran");
    assert!(oracle < 1.5, "oracle RMSE {oracle} mm");
    assert!(oracle < cl && cl < ol, "oracle {oracle}, cl {cl}, ol {ol}");
    let json = serde_json::to_string(&r).expect("serializes");
    assert!(json.contains("oracle_rmse_mm"));
}

#[test]
fn disconnect_stays_within_limits_and_recovers() {
    let cfg = short(vec![ControllerKind::HostPid, ControllerKind::Oracle]);
    let r = run_scenario("disconnect", &cfg).expect("run");
    for run in &r.runs {
        let f = &run.figures;
        assert_eq!(f["limit_violations"], 0.0, "{}", run.controller);
        assert!(f["max_chamber_pa"] <= cfg.plant.regulator.max_pa);
        assert!(f["min_chamber_pa"] >= cfg.plant.regulator.min_pa);
        // The cut visibly disturbs the arm, and it comes back within 5 s.
        assert!(
            f["max_deviation_mm"] > 2.0 * f["baseline_max_err_mm"],
            "{}: {f:?}",
            run.controller
        );
        assert_eq!(f["recovered"], 1.0, "{}", run.controller);
        assert!(f["recovery_s"] < 5.0, "{}: {f:?}", run.controller);
    }
}

#[test]
fn rom_compares_model_and_plant() {
    let cfg = SimConfig {
        rom_levels: 4,
        ..SimConfig::default()
    };
    let r = run_scenario("rom", &cfg).expect("rom");
    let f = &r.figures;
    assert_eq!(f["points"], 64.0);
    assert_eq!(f["failed"], 0.0);
    assert!(f["l_max_mm"] > 50.0);
    assert!(f["rmse_mm"] > 0.0 && f["rmse_mm"].is_finite());
    let pct = 100.0 * f["rmse_mm"] / f["l_max_mm"];
    assert!((pct - f["rmse_pct_of_l_max"]).abs() < 1e-9);
}

#[test]
fn unknown_scenario_is_an_error() {
    assert_eq!(SCENARIOS.len(), 7);
    let e = run_scenario("square", &SimConfig::default()).unwrap_err();
    assert!(matches!(e, SimError::UnknownScenario(ref n) if n == "square"));
}

#[test]
fn bad_settings_are_errors_not_panics() {
    let mut cfg = SimConfig::default();
    cfg.limits.min_pa = 1.0;
    cfg.limits.max_pa = 0.0;
    assert!(
        matches!(run_scenario("circle", &cfg), Err(SimError::Config(m)) if m.contains("limits"))
    );
    let mut cfg = SimConfig::default();
    cfg.plant.dt_s = f64::NAN;
    assert!(matches!(
        run_scenario("circle", &cfg),
        Err(SimError::Config(_))
    ));
    let mut cfg = SimConfig::default();
    cfg.plant.effects.hysteresis_fraction = -1.0;
    assert!(matches!(
        run_scenario("rom", &cfg),
        Err(SimError::Config(_))
    ));
    let mut cfg = SimConfig::default();
    cfg.hall.sensitivity_v_per_m = 0.0;
    assert!(
        matches!(run_scenario("points", &cfg), Err(SimError::Config(m)) if m.contains("sensitivity"))
    );
    let cfg = SimConfig {
        rom_pressure_pa: Some((0.0, f64::INFINITY)),
        ..SimConfig::default()
    };
    assert!(run_scenario("rom", &cfg).is_err());
}

#[test]
fn closed_loop_rejects_a_step_load_and_open_loop_does_not() {
    let cfg = short(vec![ControllerKind::HostPid, ControllerKind::OpenLoop]);
    let r = run_scenario("step_load", &cfg).expect("run");
    let cl = &r.runs[0].figures;
    let ol = &r.runs[1].figures;
    // 250 g (2.45 N over three columns of about 450 N/m) moves the
    // calibrated arm by millimetres and leaves the open loop there.
    assert!(ol["final_error_mm"] > 2.0, "{ol:?}");
    assert!(cl["max_deviation_mm"] > 1.0, "{cl:?}");
    assert!(cl["recovery_s"] < 5.0, "{cl:?}");
    assert!(
        cl["final_error_mm"] < 0.1 * ol["final_error_mm"],
        "{cl:?} vs {ol:?}"
    );
    assert_eq!(ol["recovered"], 0.0);
    assert_eq!(cl["recovered"], 1.0);
}
