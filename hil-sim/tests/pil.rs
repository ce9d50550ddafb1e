//! PIL: the firmware binary under qemu-system-arm, driven over its UART pty
//! with the wire protocol, commands the very same pressures as the firmware
//! linked in-process, tick for tick, on the same scenario.
//!
//! Skips (passing, with a message) when qemu-system-arm or the Cortex-M
//! target is not installed.
#![cfg(feature = "serial")]

use ocm_hilsim::SimConfig;
use ocm_hilsim::firmware::{lut_image, run_scenario_over, run_scenario_with_firmware};
use ocm_hilsim::qemu::{QemuLink, board_for_pil};

#[test]
fn qemu_and_in_process_firmware_command_identical_pressures() {
    let elf = match board_for_pil().expect("the board builds") {
        Ok(elf) => elf,
        Err(why) => {
            eprintln!("SKIP PIL test: {why}");
            return;
        }
    };
    // 4 s of the circle: the 3 s settle and the first second of the lap,
    // with the target moving at every update.
    let cfg = SimConfig {
        short: true,
        duration_cap_s: Some(4.0),
        log_every: 1,
        ..SimConfig::default()
    };
    let image = lut_image(&cfg.plant, &cfg.limits).expect("LUT");
    let pil =
        run_scenario_over("circle", &cfg, &image, false, || QemuLink::boot(&elf)).expect("PIL run");
    let sil = run_scenario_with_firmware("circle", &cfg).expect("SIL run");
    assert_eq!(pil.runs.len(), sil.runs.len());
    for (a, b) in pil.runs.iter().zip(&sil.runs) {
        assert_eq!(a.controller, b.controller);
        assert_eq!(a.log.len(), 4000, "{}", a.controller);
        for (k, (x, y)) in a.log.iter().zip(&b.log).enumerate() {
            assert_eq!(
                [x.cmd1_pa, x.cmd2_pa, x.cmd3_pa],
                [y.cmd1_pa, y.cmd2_pa, y.cmd3_pa],
                "{}: tick {k}: commanded pressures differ",
                a.controller
            );
            assert_eq!(x, y, "{}: tick {k}", a.controller);
        }
        // The pressures moved: the comparison covers a working loop.
        let first = a.log[0].cmd1_pa;
        assert!(
            a.log.iter().any(|r| (r.cmd1_pa - first).abs() > 10.0),
            "{}: commands never moved",
            a.controller
        );
    }
    println!(
        "PIL and SIL identical over {} ticks per run; PIL ran at {:.2}x real time",
        pil.runs[0].log.len(),
        pil.realtime_factor
    );
}

#[test]
fn a_missing_port_is_a_clear_error() {
    let e = ocm_hilsim::serial::SerialLink::open(
        "/dev/ocm-no-such-port",
        115_200,
        std::time::Duration::from_millis(100),
    )
    .err()
    .expect("no such port");
    let text = e.to_string();
    assert!(text.contains("/dev/ocm-no-such-port"), "{text}");
}
