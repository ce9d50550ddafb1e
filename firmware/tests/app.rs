//! Command handling end to end through the frame codec, on the host.

// Parallel arrays (fixed vs f64, per actuator) read clearest by index.
#![allow(clippy::needless_range_loop)]

use ocm_firmware::app::{App, AppConfig};
use ocm_firmware::fx::{angle_q28_from_rad, from_f64, to_f64};
use ocm_firmware_support::{bringup, physics};
use ocm_shared::lut::LUT_CAPACITY;
use ocm_shared::params::OcmParams;
use ocm_shared::protocol::*;

/// The default physics image, the one users flash.
fn lut_image() -> Vec<u8> {
    physics::default_image().to_vec()
}

fn crc32(b: &[u8]) -> u32 {
    crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(b)
}

struct Host<'a> {
    app: App<'a>,
    seq: u16,
    now: u32,
}

impl<'a> Host<'a> {
    fn new(buf: &'a mut [u8]) -> Self {
        Self {
            app: App::new(buf, AppConfig::default()),
            seq: 0,
            now: 0,
        }
    }

    /// Sends a command through encode -> bytes -> decoder -> handler.
    fn send(&mut self, body: CommandBody) -> ReplyBody {
        self.seq = self.seq.wrapping_add(1);
        self.now = self.now.wrapping_add(1_000);
        let mut frame = [0u8; MAX_ENCODED_FRAME];
        let n = encode_frame(
            &Command {
                seq: self.seq,
                body,
            },
            &mut frame,
        )
        .unwrap();
        let mut replies = Vec::new();
        self.app
            .receive_bytes(&frame[..n], self.now, |r| replies.push(r.clone()));
        assert_eq!(replies.len(), 1);
        assert_eq!(replies[0].seq, self.seq);
        replies.pop().unwrap().body
    }

    fn upload(&mut self, img: &[u8]) -> ReplyBody {
        let r = self.send(CommandBody::LutBegin {
            total_len: img.len() as u32,
            crc32: crc32(img),
        });
        assert_eq!(r, ReplyBody::LutProgress { received: 0 });
        for (k, chunk) in img.chunks(LUT_CHUNK).enumerate() {
            let r = self.send(CommandBody::LutChunk {
                offset: (k * LUT_CHUNK) as u32,
                data: heapless::Vec::from_slice(chunk).unwrap(),
            });
            assert!(matches!(r, ReplyBody::LutProgress { .. }), "{r:?}");
        }
        self.send(CommandBody::LutCommit)
    }

    fn sensors(&mut self, codes: [i16; 3], p: [i32; 3]) -> ReplyBody {
        self.sensors_imu(codes, [16_384, 0, 0, 0], p)
    }

    fn sensors_imu(&mut self, codes: [i16; 3], quat: [i16; 4], p: [i32; 3]) -> ReplyBody {
        self.send(CommandBody::SensorFrame(SensorFrame {
            hall_codes: heapless::Vec::from_slice(&codes).unwrap(),
            imu_quat_q14: quat,
            pressures_pa: heapless::Vec::from_slice(&p).unwrap(),
        }))
    }
}

fn straight_target(len_m: f64) -> Target {
    let mut v = heapless::Vec::new();
    v.push(SegmentConfig {
        backbone_q24: from_f64(len_m, 24),
        bend_q28: 0,
        direction_q28: 0,
    })
    .unwrap();
    Target {
        kind: TargetKind::Configuration(v),
        load: Load::default(),
    }
}

fn telemetry(r: ReplyBody) -> Telemetry {
    match r {
        ReplyBody::Telemetry(t) => t,
        other => panic!("expected telemetry, got {other:?}"),
    }
}

#[test]
fn modes_are_refused_without_lut_target_or_calibration() {
    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut h = Host::new(&mut buf);
    assert_eq!(
        h.send(CommandBody::SetMode(Mode::OpenLoop)),
        ReplyBody::Error(ProtocolError::NoLut)
    );
    assert_eq!(
        h.send(CommandBody::SetMode(Mode::ClosedLoop)),
        ReplyBody::Error(ProtocolError::NoLut)
    );
    let img = lut_image();
    assert!(matches!(h.upload(&img), ReplyBody::LutLoaded { .. }));
    assert_eq!(
        h.send(CommandBody::SetMode(Mode::OpenLoop)),
        ReplyBody::Error(ProtocolError::NoTarget)
    );
    assert_eq!(
        h.send(CommandBody::SetTarget(straight_target(0.13))),
        ReplyBody::Ack
    );
    assert_eq!(
        h.send(CommandBody::SetMode(Mode::ClosedLoop)),
        ReplyBody::Error(ProtocolError::NotCalibrated)
    );
    assert_eq!(h.send(CommandBody::SetMode(Mode::OpenLoop)), ReplyBody::Ack);
    assert_eq!(h.app.mode(), Mode::OpenLoop);
    // A second upload is refused while the first image is in use.
    assert_eq!(
        h.send(CommandBody::LutBegin {
            total_len: 10,
            crc32: 0
        }),
        ReplyBody::Error(ProtocolError::LutLocked)
    );
}

#[test]
fn lut_upload_rejects_bad_sequences_and_keeps_state() {
    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut h = Host::new(&mut buf);
    let img = lut_image();
    let chunk = |o: usize| CommandBody::LutChunk {
        offset: o as u32,
        data: heapless::Vec::from_slice(&img[o..o + LUT_CHUNK]).unwrap(),
    };
    assert_eq!(
        h.send(chunk(0)),
        ReplyBody::Error(ProtocolError::LutNotStarted)
    );
    assert_eq!(
        h.send(CommandBody::LutCommit),
        ReplyBody::Error(ProtocolError::LutNotStarted)
    );
    assert_eq!(
        h.send(CommandBody::LutBegin {
            total_len: 1 << 20,
            crc32: 0
        }),
        ReplyBody::Error(ProtocolError::LutTooLarge {
            capacity: LUT_CAPACITY as u32
        })
    );
    h.send(CommandBody::LutBegin {
        total_len: img.len() as u32,
        crc32: crc32(&img),
    });
    assert_eq!(
        h.send(chunk(0)),
        ReplyBody::LutProgress {
            received: LUT_CHUNK as u32
        }
    );
    assert_eq!(
        h.send(chunk(3 * LUT_CHUNK)),
        ReplyBody::Error(ProtocolError::LutOutOfOrder {
            expected: LUT_CHUNK as u32,
            got: 3 * LUT_CHUNK as u32
        })
    );
    assert_eq!(
        h.send(CommandBody::LutCommit),
        ReplyBody::Error(ProtocolError::LutIncomplete {
            received: LUT_CHUNK as u32,
            total: img.len() as u32
        })
    );
    // The rejected chunk changed nothing: the upload continues where it was.
    assert_eq!(
        h.send(chunk(LUT_CHUNK)),
        ReplyBody::LutProgress {
            received: 2 * LUT_CHUNK as u32
        }
    );
    // Wrong announced CRC: the commit is refused, no LUT.
    let mut bad = img.clone();
    bad[200] ^= 1;
    let r = h.send(CommandBody::LutBegin {
        total_len: bad.len() as u32,
        crc32: crc32(&img),
    });
    assert_eq!(r, ReplyBody::LutProgress { received: 0 });
    for (k, c) in bad.chunks(LUT_CHUNK).enumerate() {
        h.send(CommandBody::LutChunk {
            offset: (k * LUT_CHUNK) as u32,
            data: heapless::Vec::from_slice(c).unwrap(),
        });
    }
    assert_eq!(
        h.send(CommandBody::LutCommit),
        ReplyBody::Error(ProtocolError::LutCrc)
    );
    // Consistent CRC over a corrupted image: the image's own CRC catches it.
    assert!(matches!(
        h.upload(&bad),
        ReplyBody::Error(ProtocolError::LutInvalid)
    ));
    // An image for other OCM parameters is refused.
    // (The closed-form bring-up image: any valid image for other parameters.)
    let mut other = vec![0u8; LUT_CAPACITY];
    let mut p = OcmParams::TABLE_3_1;
    p.layers = 12;
    let n = bringup::write_image(&p, &mut other).unwrap();
    assert_eq!(
        h.upload(&other[..n]),
        ReplyBody::Error(ProtocolError::LutParamMismatch)
    );
    assert!(
        matches!(h.upload(&img), ReplyBody::LutLoaded { len, .. } if len as usize == img.len())
    );
    let ReplyBody::Info(info) = h.send(CommandBody::GetInfo) else {
        panic!()
    };
    assert!(info.lut_loaded);
}

#[test]
fn open_loop_converges_to_the_inverse_model_and_respects_limits() {
    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut h = Host::new(&mut buf);
    h.upload(&lut_image());
    // Bend 0.3 rad towards column 1 under a 100 g payload.
    let mut v = heapless::Vec::new();
    v.push(SegmentConfig {
        backbone_q24: from_f64(0.13, 24),
        bend_q28: angle_q28_from_rad(0.3),
        direction_q28: 0,
    })
    .unwrap();
    let target = Target {
        kind: TargetKind::Configuration(v.clone()),
        load: Load {
            payload_kg: 0.1,
            ..Load::default()
        },
    };
    assert_eq!(
        h.send(CommandBody::SetTarget(target.clone())),
        ReplyBody::Ack
    );
    assert_eq!(h.send(CommandBody::SetMode(Mode::OpenLoop)), ReplyBody::Ack);
    let mut last = Telemetry {
        tick: 0,
        mode: Mode::Idle,
        faults: 0,
        estimate: Default::default(),
        tip_q24: [0; 3],
        commanded_pa_q8: Default::default(),
        loop_time_us: 0,
    };
    for k in 0..400i16 {
        // Uncalibrated Hall codes that move (a frozen code under a moving
        // command would be flagged as stuck).
        last = telemetry(h.sensors([100 + k, 200 + k, 300 + k], [0, 0, 0]));
        for &p in &last.commanded_pa_q8 {
            assert!((-20_000 * 256..=35_000 * 256).contains(&p));
        }
    }
    assert_eq!(last.faults, 0, "faults {:#x}", last.faults);
    assert_eq!(last.mode, Mode::OpenLoop);
    // Reference: the f64 inverse on the same image.
    let img = lut_image();
    let lut = ocm_shared::lut::LutImage::parse(&img).unwrap();
    let g = ocm_firmware::app::DEFAULT_GEOMETRY;
    let mf = ocm_firmware_support::reference::ModelF64::new(&g);
    let lf = ocm_firmware_support::reference::LoadF64::new(&target.load, &mf);
    let tc = ocm_firmware_support::reference::ConfigF64 {
        backbone_m: 0.13,
        bend_rad: 0.3,
        direction_rad: 0.0,
    };
    let mut want = [0.0; 9];
    ocm_firmware_support::reference::inverse(&lut, &mf, &lf, &[tc], -20_000.0, 35_000.0, &mut want)
        .unwrap();
    for i in 0..3 {
        let got = to_f64(last.commanded_pa_q8[i].into(), 8);
        assert!(
            (got - want[i]).abs() < 30.0,
            "actuator {i}: {got} vs {}",
            want[i]
        );
    }
    // Column 1 is on the concave side: lowest pressure.
    assert!(want[0] < want[1] && (want[1] - want[2]).abs() < 30.0);
    // Uncalibrated: the estimate is the model's forward map, so it shows the target.
    let bend = ocm_firmware::fx::angle_q28_to_rad(last.estimate[0].bend_q28);
    assert!((bend - 0.3).abs() < 5e-3, "{bend}");
    // Tighter limits clamp the outputs at once and forever after.
    let r = h.send(CommandBody::SetLimits(Limits {
        min_pa: 0.0,
        max_pa: 5_000.0,
        slew_pa_per_s: 1e5,
    }));
    assert_eq!(r, ReplyBody::Ack);
    for k in 0..50i16 {
        let t = telemetry(h.sensors([500 + k, 600 + k, 700 + k], [0, 0, 0]));
        for &p in &t.commanded_pa_q8 {
            assert!((0..=5_000 * 256).contains(&p));
        }
    }
}

#[test]
fn watchdog_and_sensor_faults_enter_the_configured_safe_state() {
    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut h = Host::new(&mut buf);
    h.upload(&lut_image());
    h.send(CommandBody::SetTarget(straight_target(0.14)));
    h.send(CommandBody::SetMode(Mode::OpenLoop));
    for k in 0..100 {
        h.sensors([100 + k, 200 + k, 300 + k], [0, 0, 0]);
    }
    let held = h.app.commanded();
    // 150 ms of silence: link loss, hold.
    h.app.service(h.now + 150_000);
    assert_eq!(h.app.mode(), Mode::Safe);
    assert_eq!(h.app.faults() & fault::LINK_LOSS, fault::LINK_LOSS);
    assert_eq!(h.app.commanded(), held);
    assert_eq!(
        h.send(CommandBody::SetMode(Mode::OpenLoop)),
        ReplyBody::Error(ProtocolError::FaultsActive {
            faults: fault::LINK_LOSS
        })
    );
    assert_eq!(h.send(CommandBody::ClearFaults), ReplyBody::Ack);
    // Vent on the next fault: a saturated Hall code.
    h.send(CommandBody::SetSafety(SafetyConfig {
        link_timeout_us: 100_000,
        action: SafeAction::Vent,
        stuck_ticks: 200,
    }));
    assert_eq!(h.send(CommandBody::SetMode(Mode::OpenLoop)), ReplyBody::Ack);
    let t = telemetry(h.sensors([i16::MAX, 200, 300], [0, 0, 0]));
    assert_eq!(t.mode, Mode::Safe);
    assert_eq!(t.faults, fault::HALL_RANGE);
    assert!(t.commanded_pa_q8.iter().all(|&p| p == 0));
    // A malformed sensor frame is an error and changes nothing.
    let before = h.app.commanded();
    let r = h.send(CommandBody::SensorFrame(SensorFrame {
        hall_codes: heapless::Vec::from_slice(&[1, 2]).unwrap(),
        imu_quat_q14: [16_384, 0, 0, 0],
        pressures_pa: heapless::Vec::from_slice(&[0, 0, 0]).unwrap(),
    }));
    assert_eq!(
        r,
        ReplyBody::Error(ProtocolError::InvalidArgument {
            field: Field::SensorChannels
        })
    );
    assert_eq!(h.app.commanded(), before);
}

#[test]
fn closed_loop_tracks_a_target_on_a_simulated_plant() {
    use ocm_firmware_support::reference as r;
    let img = lut_image();
    let lut = ocm_shared::lut::LutImage::parse(&img).unwrap();
    let g = ocm_firmware::app::DEFAULT_GEOMETRY;
    let mf = r::ModelF64::new(&g);
    let mut buf = vec![0u8; LUT_CAPACITY];
    let mut h = Host::new(&mut buf);
    h.upload(&img);
    // Hall sensors: 5 um per code around 0.12 m at code 10000.
    let code_of = |l: f64| (10_000.0 + (l - 0.12) / 5e-6).round() as i16;
    for a in 0..3u8 {
        let pts: heapless::Vec<CalPoint, MAX_CAL_POINTS> = (0..8)
            .map(|k| {
                let l = 0.09 + 0.01 * f64::from(k);
                CalPoint {
                    code: code_of(l),
                    length_q24: from_f64(l, 24),
                }
            })
            .collect();
        let rep = h.send(CommandBody::Calibrate(Calibration {
            actuator: a,
            points: pts,
        }));
        let ReplyBody::Calibrated(rep) = rep else {
            panic!("{rep:?}")
        };
        assert_eq!(rep.r2_q15, 32_768);
    }
    let target_cfg = r::ConfigF64 {
        backbone_m: 0.135,
        bend_rad: 0.25,
        direction_rad: 1.0,
    };
    let mut v = heapless::Vec::new();
    v.push(SegmentConfig {
        backbone_q24: from_f64(target_cfg.backbone_m, 24),
        bend_q28: angle_q28_from_rad(target_cfg.bend_rad),
        direction_q28: angle_q28_from_rad(target_cfg.direction_rad),
    })
    .unwrap();
    // The plant carries 250 g more than the model is told: open loop misses,
    // closed loop must correct.
    h.send(CommandBody::SetTarget(Target {
        kind: TargetKind::Configuration(v),
        load: Load::default(),
    }));
    h.send(CommandBody::SetGains(Gains {
        kp_pa_per_m: 3e5,
        kd_pa_s_per_m: 0.0,
        ki_pa_per_m_s: 3e6,
        derivative_filter_s: 0.005,
    }));
    h.send(CommandBody::SetMode(Mode::ClosedLoop));
    let plant_load = r::LoadF64::new(
        &Load {
            payload_kg: 0.25,
            ..Load::default()
        },
        &mf,
    );
    let mut p = [0.0f64; 3];
    let mut err_mm = f64::MAX;
    for _ in 0..3_000 {
        let mut cfg = [r::ConfigF64::default(); MAX_SEGMENTS];
        r::forward(&lut, &mf, &plant_load, &p, &mut cfg).unwrap();
        let l = r::lengths_from_pcc(&mf, &cfg[0]);
        let (th, ph) = (cfg[0].bend_rad, cfg[0].direction_rad);
        let (hs, hc) = ((th / 2.0).sin(), (th / 2.0).cos());
        let quat = [hc, -hs * ph.sin(), hs * ph.cos(), 0.0].map(|q| (q * 16_384.0).round() as i16);
        let t = telemetry(h.sensors_imu(l.map(code_of), quat, [0, 0, 0]));
        assert_eq!(t.faults, 0);
        // First-order regulators, 20 ms time constant.
        for i in 0..3 {
            p[i] += (to_f64(t.commanded_pa_q8[i].into(), 8) - p[i]) * 0.05;
        }
        let tip = r::tip_pose(&cfg[..1]).p;
        let want = r::tip_pose(&[target_cfg]).p;
        err_mm = (0..3)
            .map(|i| (tip[i] - want[i]).powi(2))
            .sum::<f64>()
            .sqrt()
            * 1e3;
    }
    assert!(err_mm < 0.5, "closed-loop tip error {err_mm} mm");
    // Open loop on the same plant misses by the unmodelled payload.
    let mut p_ol = [0.0; 9];
    let model_load = r::LoadF64::new(&Load::default(), &mf);
    r::inverse(
        &lut,
        &mf,
        &model_load,
        &[target_cfg],
        -20_000.0,
        35_000.0,
        &mut p_ol,
    )
    .unwrap();
    let mut cfg = [r::ConfigF64::default(); MAX_SEGMENTS];
    r::forward(&lut, &mf, &plant_load, &p_ol[..3], &mut cfg).unwrap();
    let tip = r::tip_pose(&cfg[..1]).p;
    let want = r::tip_pose(&[target_cfg]).p;
    let ol_mm = (0..3)
        .map(|i| (tip[i] - want[i]).powi(2))
        .sum::<f64>()
        .sqrt()
        * 1e3;
    assert!(
        ol_mm > 1.0 && ol_mm > 20.0 * err_mm,
        "open loop {ol_mm} mm, closed {err_mm} mm"
    );
}
