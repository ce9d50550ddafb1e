//! The firmware under QEMU commands the very same pressures, bit for bit, as
//! the same firmware code run in-process.
//!
//! The test builds the `mps2-an386` board binary (firmware/boards/qemu) for
//! `thumbv7em-none-eabihf`, boots it in `qemu-system-arm` with its UART on a
//! pty, handshakes, uploads a LUT, configures calibration, target and
//! closed-loop mode, then streams sensor frames and compares every telemetry
//! reply with an in-process `App` fed the same commands. The LUT is the
//! closed-form bring-up image (`ocm_firmware::bringup`), built here because
//! the physics generator's default image is produced elsewhere.
//!
//! Skips (passing, with a message) when qemu-system-arm or the Cortex-M
//! target is not installed.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Proc, Stdio};
use std::time::{Duration, Instant};

use ocm_firmware::app::{App, AppConfig};
use ocm_firmware::bringup;
use ocm_shared::params::OcmParams;
use ocm_shared::protocol::*;

const TARGET: &str = "thumbv7em-none-eabihf";

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn have(cmd: &str, arg: &str) -> bool {
    Proc::new(cmd)
        .arg(arg)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn target_installed() -> bool {
    // Without rustup, assume the target may exist and let the build decide.
    match Proc::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
    {
        Ok(o) => String::from_utf8_lossy(&o.stdout)
            .lines()
            .any(|l| l.trim() == TARGET),
        Err(_) => true,
    }
}

/// Builds the board binary; `None` (with a message) when that is impossible.
fn build_board() -> Option<PathBuf> {
    let board = repo_root().join("firmware/boards/qemu");
    let target_dir = repo_root().join("target-boards");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Proc::new(cargo)
        .current_dir(&board)
        .env("CARGO_TARGET_DIR", &target_dir)
        .args(["build", "--release", "--bin", "ocm-qemu"])
        .output()
        .expect("cargo runs");
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        if err.contains("may not be installed") || err.contains("can't find crate for `core`") {
            eprintln!("SKIP qemu test: target {TARGET} is not installed");
            return None;
        }
        panic!("building the QEMU board failed:\n{err}");
    }
    Some(target_dir.join(TARGET).join("release/ocm-qemu"))
}

struct Qemu {
    child: Child,
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Boots the ELF and returns the process and its UART pty path.
fn boot(elf: &Path) -> (Qemu, String) {
    let mut child = Proc::new("qemu-system-arm")
        .args([
            "-cpu",
            "cortex-m4",
            "-machine",
            "mps2-an386",
            "-display",
            "none",
            "-monitor",
            "none",
        ])
        .args([
            "-semihosting-config",
            "enable=on,target=native",
            "-serial",
            "pty",
            "-kernel",
        ])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("qemu-system-arm starts");
    // QEMU announces the pty on stderr (older versions: stdout).
    let (tx, rx) = std::sync::mpsc::channel();
    for stream in [
        Box::new(child.stderr.take().expect("piped")) as Box<dyn Read + Send>,
        Box::new(child.stdout.take().expect("piped")),
    ] {
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stream).lines().map_while(Result::ok) {
                if let Some(i) = line.find("/dev/pts/") {
                    let path: String = line[i..]
                        .chars()
                        .take_while(|c| !c.is_whitespace() && *c != ')')
                        .collect();
                    let _ = tx.send(path);
                }
            }
        });
    }
    let path = rx
        .recv_timeout(Duration::from_secs(20))
        .expect("QEMU printed its pty");
    (Qemu { child }, path)
}

struct Link {
    port: Box<dyn serialport::SerialPort>,
    decoder: FrameDecoder,
}

impl Link {
    fn send(&mut self, cmd: &Command) {
        let mut buf = [0u8; MAX_ENCODED_FRAME];
        let n = encode_frame(cmd, &mut buf).expect("command encodes");
        self.port.write_all(&buf[..n]).expect("pty write");
        self.port.flush().expect("pty flush");
    }

    fn recv(&mut self, timeout: Duration) -> Option<Reply> {
        let end = Instant::now() + timeout;
        let mut b = [0u8; 1];
        while Instant::now() < end {
            match self.port.read(&mut b) {
                Ok(1) => {
                    if let Some(r) = self.decoder.push::<Reply>(b[0]) {
                        return Some(r.expect("firmware frames decode"));
                    }
                }
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => panic!("pty read: {e}"),
            }
        }
        None
    }

    fn call(&mut self, cmd: &Command) -> Reply {
        self.send(cmd);
        let r = self
            .recv(Duration::from_secs(10))
            .expect("firmware replies");
        assert_eq!(r.seq, cmd.seq, "reply to the wrong command: {r:?}");
        r
    }
}

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
    if !have("qemu-system-arm", "--version") {
        eprintln!("SKIP qemu test: qemu-system-arm not found (apt-get install qemu-system-arm)");
        return;
    }
    if !target_installed() {
        eprintln!(
            "SKIP qemu test: rustup target {TARGET} not installed (rustup target add {TARGET})"
        );
        return;
    }
    let Some(elf) = build_board() else { return };
    let (_qemu, pty) = boot(&elf);
    let port = serialport::new(&pty, 115_200)
        .timeout(Duration::from_millis(50))
        .open()
        .expect("pty opens");
    let mut link = Link {
        port,
        decoder: FrameDecoder::new(),
    };

    // Handshake: bytes sent before the pty was opened are lost, so ping
    // until the firmware answers.
    let mut seq = 0u16;
    let mut alive = false;
    for _ in 0..100 {
        seq += 1;
        link.send(&Command {
            seq,
            body: CommandBody::Ping { nonce: 0xfeed },
        });
        if let Some(r) = link.recv(Duration::from_millis(200))
            && r.body == (ReplyBody::Pong { nonce: 0xfeed })
        {
            alive = true;
            break;
        }
    }
    assert!(alive, "firmware never answered a ping");
    // Drain late pongs of earlier pings.
    while link.recv(Duration::from_millis(300)).is_some() {}

    let mut img = vec![0u8; 32 * 1024];
    let n = bringup::write_image(&OcmParams::TABLE_3_1, &mut img).unwrap();
    let img = &img[..n];
    let mut lut_buf = vec![0u8; 26 * 1024];
    let mut local = App::new(&mut lut_buf, AppConfig::default());
    let mut now = 0u32;
    for body in setup_commands(img) {
        seq += 1;
        let cmd = Command { seq, body };
        let remote = link.call(&cmd);
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
        let remote = link.call(&cmd);
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
