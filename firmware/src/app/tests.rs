//! The app's memo of bending lookups, seen from inside.

extern crate std;
use super::*;
use crate::kinematics::{LoadFx, inverse};
use ocm_shared::protocol::{LUT_CHUNK, Load, SensorFrame, Target, TargetKind};
use std::vec;
use upload::LUT_CRC;

fn send(app: &mut App<'_>, body: CommandBody) -> ReplyBody {
    app.handle(&Command { seq: 1, body }, 0).body
}

/// A new moment target is looked up in the bending map by `handle`, at
/// the mean pressure of its own inverse solution: the ticks that follow
/// find it in the memo and leave the memo as it was.
#[test]
fn moment_target_primes_the_bending_memo_for_the_ticks() {
    // The image users flash (the support crate's copy of this crate is
    // another crate: only its bytes cross over).
    let img = ocm_firmware_support::physics::default_image();
    let mut buf = vec![0u8; ocm_shared::lut::LUT_CAPACITY];
    let mut app = App::new(&mut buf, AppConfig::default());
    let crc32 = LUT_CRC.checksum(img);
    let total_len = img.len() as u32;
    send(&mut app, CommandBody::LutBegin { total_len, crc32 });
    for (k, c) in img.chunks(LUT_CHUNK).enumerate() {
        let data = Vec::from_slice(c).unwrap_or_default();
        let offset = (k * LUT_CHUNK) as u32;
        send(&mut app, CommandBody::LutChunk { offset, data });
    }
    assert!(matches!(
        send(&mut app, CommandBody::LutCommit),
        ReplyBody::LutLoaded { .. }
    ));
    let mut configs = Vec::new();
    let _ = configs.push(SegmentConfig {
        backbone_q24: 2_100_000,
        bend_q28: 80_000_000,
        direction_q28: 100_000_000,
    });
    let load = Load {
        payload_kg: 0.1,
        moment_x_newton_m: 0.01,
        moment_y_newton_m: -0.005,
        ..Load::default()
    };
    let target = Target {
        kind: TargetKind::Configuration(configs.clone()),
        load,
    };
    assert_eq!(
        send(&mut app, CommandBody::SetTarget(target)),
        ReplyBody::Ack
    );
    assert_eq!(
        send(&mut app, CommandBody::SetMode(Mode::OpenLoop)),
        ReplyBody::Ack
    );

    let fx = LoadFx::new(&load, &app.model).unwrap_or_default();
    let lut = app.lut().copied();
    let sol = lut.and_then(|l| {
        inverse(
            &l,
            &app.model,
            &fx,
            &configs,
            app.limits.min_q8,
            app.limits.max_q8,
        )
    });
    let want = sol.as_ref().map(segment_means);
    let held = app.target.as_ref().map(|t| t.bend_p_q8);
    assert!(want.is_some());
    assert_eq!(held, want);

    let primed = app.bend_memo.get();
    assert!(primed.iter().any(Option::is_some), "handle primed nothing");
    for k in 0..20i16 {
        let frame = SensorFrame {
            hall_codes: Vec::from_slice(&[10_000 + k, 10_500, 11_000]).unwrap_or_default(),
            imu_quat_q14: [16_384, 0, 0, 0],
            pressures_pa: Vec::from_slice(&[5_000, 6_000, 7_000]).unwrap_or_default(),
        };
        let r = send(&mut app, CommandBody::SensorFrame(frame));
        assert!(
            matches!(r, ReplyBody::Telemetry(ref t) if t.faults == 0),
            "{r:?}"
        );
        assert_eq!(app.bend_memo.get(), primed, "tick {k} missed the memo");
    }
}
