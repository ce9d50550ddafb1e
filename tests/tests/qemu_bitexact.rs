//! The firmware under QEMU commands the very same pressures, bit for bit, as
//! the same firmware code run in-process.
//!
//! The test builds the `mps2-an386` board binary (firmware/boards/qemu) for
//! `thumbv7em-none-eabihf`, boots it in `qemu-system-arm` with its UART on a
//! pty, handshakes, uploads a LUT, configures calibration, target and
//! closed-loop mode, then streams sensor frames and compares every telemetry
//! reply with an in-process `App` fed the same commands. The LUT is the
//! default physics image from `ocm-lutgen`, the one users flash.
//!
//! Skips (passing, with a message) when qemu-system-arm or the Cortex-M
//! target is not installed.

use ocm_firmware::app::{App, AppConfig};
use ocm_firmware_support::physics;
use ocm_hilsim::firmware::Link;
use ocm_hilsim::qemu::{QemuLink, board_for_pil};
use ocm_shared::lut::LUT_CAPACITY;
use ocm_shared::protocol::*;

fn setup_commands(img: &[u8]) -> Vec<CommandBody> {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(img);
    let mut v = vec![
        CommandBody::GetInfo,
        CommandBody::LutBegin {
            total_len: img.len() as u32,
            crc32: crc,
        },
    ];
    for (k, c) in img.chunks(LUT_CHUNK).enumerate() {
        v.push(CommandBody::LutChunk {
            offset: (k * LUT_CHUNK) as u32,
            data: heapless::Vec::from_slice(c).unwrap(),
        });
    }
    v.push(CommandBody::LutCommit);
    for a in 0..3u8 {
        let points = (0..8)
            .map(|k| CalPoint {
                code: 8_000 + 1_000 * k,
                length_q24: 1_600_000 + 52_000 * i32::from(k) + 7 * i32::from(a),
            })
            .collect();
        v.push(CommandBody::Calibrate(Calibration {
            actuator: a,
            points,
        }));
    }
    v.push(CommandBody::SetGains(Gains {
        kp_pa_per_m: 4e5,
        kd_pa_s_per_m: 2e3,
        ki_pa_per_m_s: 1e6,
        derivative_filter_s: 0.004,
    }));
    v.push(CommandBody::SetSafety(SafetyConfig {
        link_timeout_us: 5_000_000,
        action: SafeAction::Hold,
        stuck_ticks: 0,
    }));
    v.push(CommandBody::SetTarget(Target {
        kind: TargetKind::TipPosition {
            x_q24: 250_000,
            y_q24: -120_000,
            z_q24: 2_050_000,
        },
        load: Load {
            payload_kg: 0.15,
            force_z_n: 0.0,
            moment_x_newton_m: 0.01,
            moment_y_newton_m: -0.005,
        },
    }));
    v.push(CommandBody::SetMode(Mode::ClosedLoop));
    v
}

/// A deterministic, plant-like sensor stream.
fn sensor_frame(k: u32) -> SensorFrame {
    let t = f64::from(k) * 0.01;
    let code = |phase: f64| (10_500.0 + 900.0 * (t + phase).sin()) as i16;
    let (th, ph) = (0.12 + 0.05 * (0.7 * t).sin(), 0.4 * t);
    let (s, c) = ((th / 2.0).sin(), (th / 2.0).cos());
    let q = [c, -s * ph.sin(), s * ph.cos(), 0.0].map(|x| (x * 16_384.0).round() as i16);
    SensorFrame {
        hall_codes: heapless::Vec::from_slice(&[code(0.0), code(2.0), code(4.0)]).unwrap(),
        imu_quat_q14: q,
        pressures_pa: heapless::Vec::from_slice(&[4_000, 5_000, 6_000]).unwrap(),
    }
}

#[test]
fn qemu_firmware_matches_in_process_firmware_bit_for_bit() {
    let elf = match board_for_pil().expect("the board builds") {
        Ok(elf) => elf,
        Err(why) => {
            eprintln!("SKIP qemu test: {why}");
            return;
        }
    };
    // Boots, then pings until the firmware answers.
    let mut link = QemuLink::boot(&elf).expect("QEMU boots and answers");
    let mut seq = 0u16;
    let mut call = |cmd: &Command| link.exchange(cmd, 0).expect("firmware replies");

    let img = physics::default_image();
    let mut lut_buf = vec![0u8; LUT_CAPACITY];
    let mut local = App::new(&mut lut_buf, AppConfig::default());
    let mut now = 0u32;
    for body in setup_commands(img) {
        seq += 1;
        let cmd = Command { seq, body };
        let remote = call(&cmd);
        now += 1_000;
        let mine = local.handle(&cmd, now);
        match (&remote.body, &mine.body) {
            (ReplyBody::Info(a), ReplyBody::Info(b)) => assert_eq!(a.lut_capacity, b.lut_capacity),
            (a, b) => assert_eq!(a, b, "setup reply differs for {:?}", cmd.body),
        }
        assert!(!matches!(remote.body, ReplyBody::Error(_)), "{remote:?}");
    }
    let mut compared = 0;
    for k in 0..300u32 {
        seq += 1;
        let cmd = Command {
            seq,
            body: CommandBody::SensorFrame(sensor_frame(k)),
        };
        let remote = call(&cmd);
        now += 1_000;
        let mine = local.handle(&cmd, now);
        let (ReplyBody::Telemetry(a), ReplyBody::Telemetry(b)) = (&remote.body, &mine.body) else {
            panic!("tick {k}: {remote:?} / {mine:?}");
        };
        assert_eq!(
            a.commanded_pa_q8, b.commanded_pa_q8,
            "tick {k}: commanded pressures differ"
        );
        assert_eq!(a.estimate, b.estimate, "tick {k}: estimates differ");
        assert_eq!(
            (a.tick, a.mode, a.faults, a.tip_q24),
            (b.tick, b.mode, b.faults, b.tip_q24)
        );
        assert_eq!(a.mode, Mode::ClosedLoop, "tick {k}: {a:?}");
        compared += 1;
    }
    // The stream must have moved the outputs, or the comparison proves little.
    let ReplyBody::Telemetry(last) = local
        .handle(
            &Command {
                seq: 0,
                body: CommandBody::SensorFrame(sensor_frame(300)),
            },
            now,
        )
        .body
    else {
        panic!()
    };
    assert!(last.commanded_pa_q8.iter().any(|&p| p != 0));
    println!("{compared} ticks bit-identical between QEMU and in-process");
}
