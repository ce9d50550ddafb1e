//! The firmware in-process against the plant (needs `--features firmware`).
#![cfg(feature = "firmware")]

use ocm_hilsim::firmware::{FirmwareMcu, LUT_CAPACITY, lut_image};
use ocm_hilsim::{ControllerKind, SimConfig, run_scenario, run_with_mcu};

#[test]
fn firmware_tracks_the_circle_in_process() {
    let cfg = SimConfig {
        short: true,
        controllers: vec![ControllerKind::OpenLoop, ControllerKind::Oracle],
        ..SimConfig::default()
    };
    let image = lut_image(&cfg.plant, &cfg.limits).expect("lut");
    let mut results = Vec::new();
    for closed in [false, true] {
        let mut buf = vec![0u8; LUT_CAPACITY];
        let mut fw = FirmwareMcu::new(
            &mut buf,
            &image,
            &cfg.plant,
            &cfg.hall,
            &cfg.gains,
            &cfg.limits,
            closed,
        )
        .expect("firmware boots");
        let run = run_with_mcu("circle", &cfg, &mut fw).expect("run");
        assert_eq!(run.figures["limit_violations"], 0.0);
        results.push(run.rmse_mm);
    }
    let host = run_scenario("circle", &cfg).expect("host");
    println!(
        "firmware OL {:.2} mm, CL {:.2} mm; host OL {:?}, oracle {:?}",
        results[0], results[1], host.ol_rmse_mm, host.oracle_rmse_mm
    );
    let host_ol = host.ol_rmse_mm.expect("host open loop ran");
    // The firmware's open loop is the same model through its LUT.
    assert!(
        (results[0] - host_ol).abs() < 0.05 * host_ol,
        "firmware OL {} vs host OL {host_ol}",
        results[0]
    );
    // Closed loop at least halves the open-loop error (issue 4, tests).
    assert!(
        results[1] < 0.5 * results[0],
        "CL {} vs OL {}",
        results[1],
        results[0]
    );
}
