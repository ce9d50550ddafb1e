//! The firmware in-process against the plant (needs `--features firmware`).
#![cfg(feature = "firmware")]

use ocm_hilsim::firmware::{FirmwareMcu, InProcess, LUT_CAPACITY, Link, check_info, lut_image};
use ocm_hilsim::{ControllerKind, SimConfig, SimError, run_scenario, run_with_mcu};
use ocm_shared::protocol::{Command, CommandBody, PROTOCOL_VERSION, Reply, ReplyBody};

/// The real firmware, except that it claims another protocol revision.
struct OtherProtocol<'a>(InProcess<'a>);

impl Link for OtherProtocol<'_> {
    fn exchange(&mut self, cmd: &Command, now_us: u32) -> Result<Reply, SimError> {
        let mut reply = self.0.exchange(cmd, now_us)?;
        if let ReplyBody::Info(info) = &mut reply.body {
            info.protocol_version = PROTOCOL_VERSION + 1;
        }
        Ok(reply)
    }
}

/// The host asks for the firmware's protocol revision when it connects and
/// refuses another one, before it uploads or commands anything; the same
/// firmware telling the truth passes the check.
#[test]
fn host_refuses_a_firmware_of_another_protocol_version() {
    let cfg = SimConfig {
        short: true,
        ..SimConfig::default()
    };
    let period_us = (cfg.plant.dt_s * 1e6).round() as u32;
    let mut buf = vec![0u8; LUT_CAPACITY];
    let link = OtherProtocol(InProcess::new(&mut buf, period_us));
    let err = match FirmwareMcu::new(link, &[], &cfg, true) {
        Ok(_) => panic!(
            "a firmware of protocol {} was accepted",
            PROTOCOL_VERSION + 1
        ),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains(&format!("protocol version {}", PROTOCOL_VERSION + 1))
            && err.contains(&format!("this host speaks version {PROTOCOL_VERSION}")),
        "{err}"
    );

    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut honest = InProcess::new(&mut buf, period_us);
    let get_info = Command {
        seq: 1,
        body: CommandBody::GetInfo,
    };
    let ReplyBody::Info(info) = honest.exchange(&get_info, 0).expect("reply").body else {
        panic!("no Info in reply to GetInfo");
    };
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.lut_capacity as usize, LUT_CAPACITY);
    check_info(&info, period_us).expect("the matching firmware is accepted");
    let slower = check_info(&info, 2 * period_us).expect_err("another rate is refused");
    assert!(slower.to_string().contains("ticks every"), "{slower}");
}

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
        let mut fw =
            FirmwareMcu::in_process(&mut buf, &image, &cfg, closed).expect("firmware boots");
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

/// The firmware's closed loop stays within 2.5x of the oracle, the plant's exact inverse, and
/// under 1 mm on every tracking task. The oracle knows the columns' hysteresis state, which no
/// controller can read; on the calibrated plant the hysteresis loop (0.48 N) is a larger share
/// of a much smaller total error than on the Table 3.1 plant, so the ratio measured is about
/// 2.2 (triangle 0.47 mm against 0.21 mm), where it was 1.4. The dissertation's closed loop
/// reached 7.22 mm (triangle) and 5.54 mm (circle).
#[test]
fn firmware_closed_loop_is_within_two_and_a_half_oracles_and_a_millimetre() {
    let cfg = SimConfig {
        short: true,
        ..SimConfig::default()
    };
    for name in ["triangle", "circle", "points", "step_load"] {
        let r = ocm_hilsim::firmware::run_scenario_with_firmware(name, &cfg).expect("run");
        let (cl, oracle) = (r.cl_rmse_mm.unwrap(), r.oracle_rmse_mm.unwrap());
        println!("{name}: CL {cl:.3} mm, oracle {oracle:.3} mm");
        assert!(
            cl <= 2.5 * oracle,
            "{name}: CL {cl} mm vs oracle {oracle} mm"
        );
        if name != "points" {
            // points is judged by its settling figures; its RMSE includes the jumps between points
            assert!(cl <= 1.0, "{name}: CL {cl} mm");
        }
        let ol = r.ol_rmse_mm.unwrap();
        // points' RMSE counts the jumps between targets, which open and closed loop share
        // (measured 2.0 against 3.5 mm): there the loop must still cut the error by 30 %.
        let ratio = if name == "points" { 0.7 } else { 0.5 };
        assert!(cl <= ratio * ol, "{name}: CL {cl} mm vs OL {ol} mm");
    }
}

/// Holding a pose under a ramping load, the loop is as good as the oracle
/// once the sensors are exact; with the rig's sensors the excess stays
/// within what their bias explains (the oracle reads no sensor).
#[test]
fn firmware_holds_the_orientation_down_to_its_sensors() {
    let rig = SimConfig::default();
    let mut exact = rig.clone();
    exact.imu.bias_rad = 0.0;
    exact.hall.tilt_error_gain = 0.0;
    let run = |cfg: &SimConfig| {
        let r = ocm_hilsim::firmware::run_scenario_with_firmware("orientation", cfg).expect("run");
        (r.cl_rmse_mm.unwrap(), r.oracle_rmse_mm.unwrap())
    };
    let (cl, oracle) = run(&exact);
    println!("exact sensors: CL {cl:.3} mm, oracle {oracle:.3} mm");
    // Both are micrometres on the calibrated plant (measured 11 um against 3 um): the bound
    // allows 1.5x the oracle plus 25 um, far below what the rig's motion capture resolves.
    assert!(
        cl <= 1.5 * oracle + 0.025,
        "CL {cl} mm vs oracle {oracle} mm"
    );
    let (cl, oracle) = run(&rig);
    // An IMU tilt bias b moves the estimated tip by about b S (S = 155 mm on the calibrated
    // plant's working backbone).
    let floor_mm = rig.imu.bias_rad * 155.0;
    println!("rig sensors: CL {cl:.3} mm, oracle {oracle:.3} mm, sensor floor {floor_mm:.3} mm");
    assert!(
        cl <= 1.5 * oracle + floor_mm,
        "CL {cl} mm vs oracle {oracle} mm"
    );
}

/// A chamber cut for 5 s: the firmware keeps every command inside its
/// limits, raises no fault and is back on the circle within 5 s.
#[test]
fn firmware_recovers_from_a_chamber_disconnect() {
    let cfg = SimConfig::default();
    let r = ocm_hilsim::firmware::run_scenario_with_firmware("disconnect", &cfg).expect("run");
    let cl = r
        .runs
        .iter()
        .find(|x| x.controller == "firmware_cl")
        .unwrap();
    let f = &cl.figures;
    println!("{f:?}");
    assert_eq!(f["limit_violations"], 0.0);
    assert!(f["min_command_pa"] >= cfg.limits.min_pa - 0.01);
    assert!(f["max_command_pa"] <= cfg.limits.max_pa + 0.01);
    // The cut is felt: the loss of a chamber moves the tip by centimetres.
    assert!(
        f["max_deviation_mm"] > 10.0 * f["baseline_max_err_mm"],
        "{f:?}"
    );
    assert_eq!(f["recovered"], 1.0, "{f:?}");
    assert!(f["recovery_s"] < 5.0, "{f:?}");
}

/// One seed, one log: the firmware runs (on their own threads) and the
/// oracle reproduce bit for bit; another seed changes them.
#[test]
fn firmware_runs_are_deterministic() {
    let cfg = SimConfig {
        short: true,
        duration_cap_s: Some(5.0),
        log_every: 1,
        ..SimConfig::default()
    };
    let logs = |cfg: &SimConfig| -> Vec<Vec<u8>> {
        let r = ocm_hilsim::firmware::run_scenario_with_firmware("triangle", cfg).expect("run");
        r.runs.iter().map(|x| x.csv_bytes().expect("csv")).collect()
    };
    let a = logs(&cfg);
    assert_eq!(a.len(), 3);
    assert!(a.iter().all(|l| l.len() > 100_000));
    assert_eq!(a, logs(&cfg));
    let other = SimConfig { seed: 2, ..cfg };
    let b = logs(&other);
    assert!(a.iter().zip(&b).all(|(x, y)| x != y));
}

/// The firmware's PD (with its integral) rejects an unannounced 250 g step
/// load: back within 1 mm in a few seconds; the open loop stays off.
#[test]
fn firmware_rejects_a_step_load() {
    let cfg = SimConfig::default();
    let r = ocm_hilsim::firmware::run_scenario_with_firmware("step_load", &cfg).expect("run");
    let fig = |name: &str| {
        &r.runs
            .iter()
            .find(|x| x.controller == name)
            .unwrap()
            .figures
    };
    let (cl, ol) = (fig("firmware_cl"), fig("firmware_ol"));
    println!("CL {cl:?}\nOL {ol:?}");
    // On the calibrated plant the 250 g step moves the tip by about 2.3 mm at its peak and
    // leaves the open loop about 4 mm off: the step is felt at several times the loop's final
    // error, the closed loop removes it, the open loop keeps it.
    assert!(cl["max_deviation_mm"] > 1.5, "the step is felt: {cl:?}");
    assert_eq!(cl["recovered"], 1.0, "{cl:?}");
    assert!(cl["recovery_s"] < 5.0, "{cl:?}");
    assert!(cl["final_error_mm"] < 0.5, "{cl:?}");
    assert!(
        cl["max_deviation_mm"] > 4.0 * cl["final_error_mm"],
        "{cl:?}"
    );
    assert!(ol["final_error_mm"] > 2.0, "{ol:?}");
    assert!(
        ol["final_error_mm"] > 4.0 * cl["final_error_mm"],
        "{ol:?} {cl:?}"
    );
    assert_eq!(cl["limit_violations"], 0.0);
}
