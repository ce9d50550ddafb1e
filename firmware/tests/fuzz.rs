//! Fuzzing of frame decoding and command handling: one million inputs from a
//! seeded generator (random bytes, random but well-formed commands, and
//! corrupted valid frames) go through the decoder and the app. Nothing may
//! panic, every frame gets exactly one reply, and no commanded pressure may
//! ever leave the limits in force.

// Parallel arrays (fixed vs f64, per actuator) read clearest by index.
#![allow(clippy::needless_range_loop)]

use ocm_firmware::app::{App, AppConfig};
use ocm_firmware::fx::from_f64;
use ocm_firmware_support::physics;
use ocm_shared::lut::LUT_CAPACITY;
use ocm_shared::params::{ManipulatorParams, OcmParams};
use ocm_shared::protocol::*;

/// SplitMix64: tiny, seeded, good enough to drive a fuzzer.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
    fn f32_in(&mut self, lo: f32, hi: f32) -> f32 {
        // Mostly in range, sometimes wild (NaN, inf, huge, negative).
        match self.below(16) {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => -1e30,
            3 => f32::from_bits(self.next() as u32),
            _ => lo + (hi - lo) * (self.below(1 << 20) as f32 / (1 << 20) as f32),
        }
    }
    fn i32(&mut self) -> i32 {
        if self.below(4) == 0 {
            self.next() as i32
        } else {
            (self.below(4_000_000) as i32) - 1_000_000
        }
    }
}

fn random_command(rng: &mut Rng, lut: &[u8], actuators: usize) -> CommandBody {
    match rng.below(16) {
        0 => CommandBody::Ping {
            nonce: rng.next() as u32,
        },
        1 => CommandBody::GetInfo,
        2 => CommandBody::LutBegin {
            total_len: if rng.below(2) == 0 {
                lut.len() as u32
            } else {
                rng.below(70_000) as u32
            },
            crc32: rng.next() as u32,
        },
        3 => {
            let off = rng.below(lut.len() as u64) as usize;
            let len = rng.below(LUT_CHUNK as u64 + 1) as usize;
            let end = (off + len).min(lut.len());
            CommandBody::LutChunk {
                offset: if rng.below(2) == 0 {
                    off as u32
                } else {
                    rng.next() as u32
                },
                data: heapless::Vec::from_slice(&lut[off..end]).unwrap(),
            }
        }
        4 => CommandBody::LutCommit,
        5 => CommandBody::SetMode(match rng.below(4) {
            0 => Mode::Idle,
            1 => Mode::OpenLoop,
            2 => Mode::ClosedLoop,
            _ => Mode::Safe,
        }),
        6 => CommandBody::SetGains(Gains {
            kp_pa_per_m: rng.f32_in(0.0, 2e6),
            kd_pa_s_per_m: rng.f32_in(0.0, 1e5),
            ki_pa_per_m_s: rng.f32_in(0.0, 1e6),
            derivative_filter_s: rng.f32_in(0.0, 0.1),
        }),
        7 => CommandBody::SetLimits(Limits {
            min_pa: rng.f32_in(-50_000.0, 10_000.0),
            max_pa: rng.f32_in(0.0, 60_000.0),
            slew_pa_per_s: rng.f32_in(0.0, 1e6),
        }),
        8 => CommandBody::SetSafety(SafetyConfig {
            link_timeout_us: rng.below(300_000) as u32,
            action: if rng.below(2) == 0 {
                SafeAction::Hold
            } else {
                SafeAction::Vent
            },
            stuck_ticks: rng.below(300) as u16,
        }),
        9 => CommandBody::SetGeometry(Geometry {
            manipulator: ManipulatorParams {
                segments: rng.below(5) as u32,
                ocms_per_column: rng.below(5) as u32,
                column_radius_m: f64::from(rng.f32_in(0.0, 0.1)),
                ..ManipulatorParams::TABLE_3_1
            },
            ocm: if rng.below(4) == 0 {
                OcmParams {
                    layers: 11,
                    ..OcmParams::TABLE_3_1
                }
            } else {
                OcmParams::TABLE_3_1
            },
            mount: if rng.below(2) == 0 {
                Mount::Upright
            } else {
                Mount::Hanging
            },
        }),
        10 => {
            let kind = if rng.below(2) == 0 {
                let n = rng.below(4) as usize;
                TargetKind::Configuration(
                    (0..n)
                        .map(|_| SegmentConfig {
                            backbone_q24: if rng.below(3) == 0 {
                                rng.i32()
                            } else {
                                from_f64(0.08 + 0.1 * (rng.below(1000) as f64 / 1000.0), 24)
                            },
                            bend_q28: if rng.below(3) == 0 {
                                rng.i32()
                            } else {
                                (rng.below(1 << 28) as i32) - (1 << 27)
                            },
                            direction_q28: rng.next() as i32,
                        })
                        .collect(),
                )
            } else {
                TargetKind::TipPosition {
                    x_q24: rng.i32(),
                    y_q24: rng.i32(),
                    z_q24: rng.i32(),
                }
            };
            CommandBody::SetTarget(Target {
                kind,
                load: Load {
                    payload_kg: rng.f32_in(0.0, 0.5),
                    force_z_n: rng.f32_in(-5.0, 5.0),
                    moment_x_newton_m: rng.f32_in(-0.1, 0.1),
                    moment_y_newton_m: rng.f32_in(-0.1, 0.1),
                },
            })
        }
        11 => {
            let n = rng.below(MAX_CAL_POINTS as u64 + 1) as usize;
            let base = rng.below(20_000) as i32;
            CommandBody::Calibrate(Calibration {
                actuator: rng.below(12) as u8,
                points: (0..n)
                    .map(|k| CalPoint {
                        code: if rng.below(8) == 0 {
                            rng.next() as i16
                        } else {
                            (base + 500 * k as i32) as i16
                        },
                        length_q24: if rng.below(8) == 0 {
                            rng.i32()
                        } else {
                            from_f64(0.08 + 0.004 * k as f64, 24)
                        },
                    })
                    .collect(),
            })
        }
        12 => CommandBody::ClearFaults,
        _ => {
            let n = if rng.below(8) == 0 {
                rng.below(10) as usize
            } else {
                actuators
            };
            let m = if rng.below(8) == 0 {
                rng.below(10) as usize
            } else {
                n
            };
            CommandBody::SensorFrame(SensorFrame {
                hall_codes: (0..n)
                    .map(|_| {
                        if rng.below(32) == 0 {
                            rng.next() as i16
                        } else {
                            9_000 + rng.below(4_000) as i16
                        }
                    })
                    .collect(),
                imu_quat_q14: if rng.below(32) == 0 {
                    [rng.next() as i16, 0, 0, 0]
                } else {
                    [16_384, 0, 0, 0]
                },
                pressures_pa: (0..m)
                    .map(|_| {
                        if rng.below(32) == 0 {
                            rng.next() as i32
                        } else {
                            (rng.below(40_000) as i32) - 10_000
                        }
                    })
                    .collect(),
            })
        }
    }
}

/// Hall maps for closed loop: 4 um per code around code 11000.
fn calibrations() -> Vec<CommandBody> {
    (0..3u8)
        .map(|a| {
            let points = (0..8)
                .map(|k| CalPoint {
                    code: 9_000 + 500 * k,
                    length_q24: from_f64(0.12 + 4e-6 * (500.0 * f64::from(k) - 2_000.0), 24),
                })
                .collect();
            CommandBody::Calibrate(Calibration {
                actuator: a,
                points,
            })
        })
        .collect()
}

#[test]
fn one_million_inputs_never_panic_and_never_exceed_limits() {
    // The default physics image, as flashed.
    let lut = physics::default_image().to_vec();
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&lut);

    let mut rng = Rng(0x0c0f_fee5_eed5_2026);
    let mut inputs = 0u64;
    let mut frames_out = 0u64;
    let mut running_ticks = 0u64;
    let mut errors = 0u64;
    let mut now = 0u32;
    // Several app lifetimes, half of them starting with a loaded LUT and a
    // running controller so that the fuzzer also reaches the control path.
    for life in 0..20u64 {
        let mut buf = vec![0u8; LUT_CAPACITY];
        let mut app = App::new(&mut buf, AppConfig::default());
        if life.is_multiple_of(2) {
            let mut prelude = vec![CommandBody::LutBegin {
                total_len: lut.len() as u32,
                crc32: crc,
            }];
            for (k, c) in lut.chunks(LUT_CHUNK).enumerate() {
                prelude.push(CommandBody::LutChunk {
                    offset: (k * LUT_CHUNK) as u32,
                    data: heapless::Vec::from_slice(c).unwrap(),
                });
            }
            prelude.push(CommandBody::LutCommit);
            prelude.push(CommandBody::SetTarget(Target {
                kind: TargetKind::TipPosition {
                    x_q24: 300_000,
                    y_q24: 0,
                    z_q24: 2_000_000,
                },
                load: Load::default(),
            }));
            prelude.push(CommandBody::SetMode(Mode::OpenLoop));
            for body in prelude {
                let cmd = Command { seq: 1, body };
                let r = app.handle(&cmd, now);
                assert!(!matches!(r.body, ReplyBody::Error(_)), "{r:?}");
            }
            assert_eq!(app.mode(), Mode::OpenLoop);
        }
        let mut frame = [0u8; MAX_ENCODED_FRAME];
        let rearm = |app: &mut App, now: u32, closed: bool| {
            let mut bodies = vec![
                CommandBody::SetMode(Mode::Idle),
                CommandBody::SetGeometry(ocm_firmware::app::DEFAULT_GEOMETRY),
                CommandBody::SetLimits(Limits {
                    min_pa: -20_000.0,
                    max_pa: 35_000.0,
                    slew_pa_per_s: 200_000.0,
                }),
            ];
            bodies.extend(calibrations());
            bodies.extend([
                CommandBody::ClearFaults,
                CommandBody::SetTarget(Target {
                    kind: TargetKind::TipPosition {
                        x_q24: 200_000,
                        y_q24: 100_000,
                        z_q24: 2_100_000,
                    },
                    load: Load::default(),
                }),
                CommandBody::SetMode(if closed {
                    Mode::ClosedLoop
                } else {
                    Mode::OpenLoop
                }),
            ]);
            for body in bodies {
                let r = app.handle(&Command { seq: 0, body }, now);
                if std::env::var("FUZZ_DEBUG").is_ok() {
                    println!("rearm {r:?}");
                }
            }
        };
        if life.is_multiple_of(2) {
            app.handle(
                &Command {
                    seq: 0,
                    body: CommandBody::SetMode(Mode::Idle),
                },
                now,
            );
            for body in calibrations() {
                let r = app.handle(&Command { seq: 0, body }, now);
                assert!(matches!(r.body, ReplyBody::Calibrated(_)), "{r:?}");
            }
        }
        while inputs < (life + 1) * 50_000 {
            inputs += 1;
            if life.is_multiple_of(2) && inputs.is_multiple_of(100) {
                rearm(&mut app, now, inputs.is_multiple_of(200));
            }
            now = now.wrapping_add(rng.below(3_000) as u32);
            let bytes: Vec<u8> = match rng.below(10) {
                // Random bytes, random length, ending in a delimiter.
                0..=2 => {
                    let cap = if rng.below(10) == 0 { 600 } else { 40 };
                    let len = rng.below(cap);
                    let mut v: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
                    v.push(0);
                    v
                }
                // A well-formed random command.
                3..=7 => {
                    let cmd = Command {
                        seq: rng.next() as u16,
                        body: random_command(&mut rng, &lut, app.actuators()),
                    };
                    let n = encode_frame(&cmd, &mut frame).unwrap();
                    frame[..n].to_vec()
                }
                // A well-formed frame with a few bytes flipped.
                _ => {
                    let cmd = Command {
                        seq: rng.next() as u16,
                        body: random_command(&mut rng, &lut, app.actuators()),
                    };
                    let n = encode_frame(&cmd, &mut frame).unwrap();
                    let mut v = frame[..n].to_vec();
                    for _ in 0..=rng.below(3) {
                        let i = rng.below(n as u64 - 1) as usize;
                        v[i] ^= 1 << rng.below(8);
                    }
                    if *v.last().unwrap() != 0 {
                        v.push(0);
                    }
                    v
                }
            };
            let delimiters = bytes.iter().filter(|&&b| b == 0).count();
            let mut replies = 0usize;
            let mut empty_frames = 0usize;
            let mut prev_zero = true;
            for &b in &bytes {
                if b == 0 && prev_zero {
                    empty_frames += 1;
                }
                prev_zero = b == 0;
            }
            app.receive_bytes(&bytes, now, |r| {
                replies += 1;
                match &r.body {
                    ReplyBody::Telemetry(t)
                        if matches!(t.mode, Mode::OpenLoop | Mode::ClosedLoop) =>
                    {
                        running_ticks += 1
                    }
                    ReplyBody::Error(_) => errors += 1,
                    ReplyBody::Telemetry(t) if std::env::var("FUZZ_DEBUG").is_ok() => {
                        println!("tele {:?} {:#x}", t.mode, t.faults)
                    }
                    _ => {}
                }
            });
            frames_out += replies as u64;
            // One reply per non-empty frame (an oversize run may swallow
            // several delimiters' worth of bytes into one error at most).
            assert!(
                replies <= delimiters,
                "{replies} replies for {delimiters} delimiters"
            );
            assert!(replies + empty_frames + 1 >= delimiters || bytes.len() > MAX_ENCODED_FRAME);
            app.service(now);
            let lim = app.limits();
            for &p in &app.commanded()[..app.actuators()] {
                assert!(
                    p >= lim.min_q8 && p <= lim.max_q8,
                    "pressure {p} outside {lim:?}"
                );
            }
        }
    }
    assert_eq!(inputs, 1_000_000);
    println!("{frames_out} replies, {errors} errors, {running_ticks} ticks in open/closed loop");
    assert!(frames_out > 900_000, "only {frames_out} replies");
    // The fuzzer must reach the control path, not only the error paths.
    assert!(running_ticks > 5_000, "only {running_ticks} running ticks");
}
