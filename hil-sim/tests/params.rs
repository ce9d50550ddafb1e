//! The calibrated parameter set against what it was fitted to and checked
//! against (docs/model.md, "Calibrated parameters"), and the lab's command
//! range on it.

use ocm_hilsim::plant::PlateLoad;
use ocm_hilsim::{ControllerKind, SimConfig, run_scenario, working_limits};
use ocm_lutgen::{OcmModel, OcmParams};
use ocm_shared::params::ParamPreset;

/// Strain of the unloaded module at `pa` (the tensile tester's F = 0).
fn free_strain(model: &OcmModel, pa: f64) -> f64 {
    let (_, hi) = model.strain_limits();
    model
        .strain_for_force(0.0, pa, (-0.95, 0.98 * hi))
        .expect("free strain")
}

/// Mean |M| over the bending grid of Fig 3.10-D: 16 initial strains set
/// by 0..30 kPa in 2 kPa steps, each bent up to its feasible angle (at
/// most the 1.5 rad of Fig 3.10-B).
fn mean_moment_nm(model: &OcmModel) -> f64 {
    let mut sum = 0.0;
    let mut n = 0;
    for k in 0..16 {
        let pa = 2_000.0 * k as f64;
        let eps0 = free_strain(model, pa);
        let top = model.max_bend_angle_rad(eps0).min(1.5);
        for j in 1..=20 {
            let phi = top * j as f64 / 20.0;
            sum += model.bending_moment_nm(phi, eps0, pa).abs();
            n += 1;
        }
    }
    sum / n as f64
}

#[test]
fn calibrated_module_spans_strain_0_to_0_6_over_0_to_30_kpa() {
    let cal = OcmModel::new(OcmParams::CALIBRATED).unwrap();
    assert!(free_strain(&cal, 0.0).abs() < 1e-9);
    let top = free_strain(&cal, 30_000.0);
    assert!((top - 0.6).abs() < 0.002, "free strain at 30 kPa {top}");
    // The 16 levels of Fig 3.10-C/D give 16 distinct, rising strains.
    let levels: Vec<f64> = (0..16)
        .map(|k| free_strain(&cal, 2_000.0 * k as f64))
        .collect();
    assert!(levels.windows(2).all(|w| w[1] - w[0] > 0.02), "{levels:?}");
    // Table 3.1 as printed gets there at about 1.5 kPa.
    let t31 = OcmModel::new(OcmParams::TABLE_3_1).unwrap();
    let at_1500 = free_strain(&t31, 1_500.0);
    assert!(
        (at_1500 - 0.6).abs() < 0.05,
        "Table 3.1 at 1.5 kPa: {at_1500}"
    );
}

#[test]
fn calibrated_moments_are_near_the_dissertations_magnitude() {
    // Ch. 3.4.1: a mean moment error of 0.014 N m is 18 %, so the measured
    // moments average about 0.078 N m.
    let target = 0.014 / 0.18;
    let cal = mean_moment_nm(&OcmModel::new(OcmParams::CALIBRATED).unwrap());
    let t31 = mean_moment_nm(&OcmModel::new(OcmParams::TABLE_3_1).unwrap());
    println!("mean |M|: calibrated {cal:.4} N m, Table 3.1 {t31:.4} N m, target {target:.4}");
    assert!(
        (0.5 * target..2.5 * target).contains(&cal),
        "calibrated {cal}"
    );
    assert!(t31 < 0.1 * target, "Table 3.1 {t31}");
}

#[test]
fn the_lab_commands_most_of_the_regulators_0_to_30_kpa() {
    let cfg = SimConfig::default();
    assert_eq!(cfg.plant.ocm, OcmParams::CALIBRATED);
    let reg = cfg.plant.regulator;
    assert_eq!((reg.min_pa, reg.max_pa), (0.0, 30_000.0));
    let lim = cfg.limits;
    assert_eq!(lim, working_limits(&cfg.plant));
    assert_eq!(lim.min_pa, 0.0);
    // The top is where the heaviest load stretches a column to strain 0.6.
    assert!((25_000.0..30_000.0).contains(&lim.max_pa), "{lim:?}");
    // Hanging, the plate's weight pulls the columns a little longer than
    // the free module at every command.
    let model = OcmModel::new(cfg.plant.ocm).unwrap();
    let tension = cfg.plant.external_force_n(&PlateLoad::default())[2] / 3.0;
    assert!(tension > 0.0);
    for pa in [lim.min_pa, lim.max_pa] {
        let loaded = model.strain_for_force(tension, pa, (-0.95, 1.5)).unwrap();
        let free = free_strain(&model, pa);
        assert!(
            loaded > free && loaded - free < 0.05,
            "{pa}: {loaded} vs {free}"
        );
        assert!((0.0..=0.6).contains(&loaded), "{pa}: {loaded}");
    }
}

#[test]
fn table_3_1_stays_selectable_in_the_lab() {
    let cfg = SimConfig {
        short: true,
        controllers: vec![ControllerKind::Oracle, ControllerKind::HostPid],
        ..SimConfig::with_preset(ParamPreset::Table31)
    };
    assert_eq!(cfg.plant.ocm, OcmParams::TABLE_3_1);
    // Its working range is the one the lab ran at before: a few kPa of vacuum.
    assert!(
        (cfg.limits.min_pa + 4_457.0).abs() < 5.0,
        "{:?}",
        cfg.limits
    );
    assert!((cfg.limits.max_pa - 240.0).abs() < 5.0, "{:?}", cfg.limits);
    let r = run_scenario("circle", &cfg).expect("circle on Table 3.1");
    let (cl, oracle) = (r.cl_rmse_mm.unwrap(), r.oracle_rmse_mm.unwrap());
    println!("Table 3.1 circle: CL {cl:.2} mm, oracle {oracle:.2} mm");
    assert!(
        oracle < 3.0 && cl < 1.5 * oracle,
        "CL {cl} mm, oracle {oracle} mm"
    );
}

#[test]
fn a_plant_ocm_table_starts_from_its_preset() {
    let parse = |text: &str| serde_json::from_str::<SimConfig>(text).expect("config");
    assert_eq!(parse(r#"{"plant": {}}"#).plant.ocm, OcmParams::CALIBRATED);
    assert_eq!(
        parse(r#"{"plant": {"ocm": {}}}"#).plant.ocm,
        OcmParams::CALIBRATED
    );
    let t = parse(r#"{"plant": {"ocm": {"preset": "table-3.1", "mass_kg": 0.02}}}"#);
    assert_eq!(
        t.plant.ocm,
        OcmParams {
            mass_kg: 0.02,
            ..OcmParams::TABLE_3_1
        }
    );
    let e = serde_json::from_str::<SimConfig>(r#"{"plant": {"ocm": {"preset": "table3"}}}"#)
        .unwrap_err();
    assert!(e.to_string().contains("table3"), "{e}");
}
