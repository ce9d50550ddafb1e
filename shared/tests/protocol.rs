//! Protocol framing: round trips, corruption detection and decoder
//! robustness.

use ocm_shared::protocol::*;
use proptest::prelude::*;

fn decode_all<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Vec<Result<T, FrameError>> {
    let mut d = FrameDecoder::new();
    bytes.iter().filter_map(|&b| d.push::<T>(b)).collect()
}

fn arb_sensor() -> impl Strategy<Value = SensorFrame> {
    (
        proptest::collection::vec(any::<i16>(), 0..=MAX_ACTUATORS),
        any::<[i16; 4]>(),
        proptest::collection::vec(any::<i32>(), 0..=MAX_ACTUATORS),
    )
        .prop_map(|(h, q, p)| SensorFrame {
            hall_codes: heapless::Vec::from_slice(&h).unwrap(),
            imu_quat_q14: q,
            pressures_pa: heapless::Vec::from_slice(&p).unwrap(),
        })
}

fn arb_command() -> impl Strategy<Value = Command> {
    let body = prop_oneof![
        any::<u32>().prop_map(|nonce| CommandBody::Ping { nonce }),
        Just(CommandBody::GetInfo),
        (any::<u32>(), any::<u32>())
            .prop_map(|(total_len, crc32)| CommandBody::LutBegin { total_len, crc32 }),
        (
            any::<u32>(),
            proptest::collection::vec(any::<u8>(), 0..=LUT_CHUNK)
        )
            .prop_map(|(offset, d)| {
                CommandBody::LutChunk {
                    offset,
                    data: heapless::Vec::from_slice(&d).unwrap(),
                }
            }),
        Just(CommandBody::LutCommit),
        Just(CommandBody::SetMode(Mode::ClosedLoop)),
        (any::<f32>(), any::<f32>(), any::<f32>(), any::<f32>()).prop_map(|(a, b, c, d)| {
            CommandBody::SetGains(Gains {
                kp_pa_per_m: a,
                kd_pa_s_per_m: b,
                ki_pa_per_m_s: c,
                derivative_filter_s: d,
            })
        }),
        arb_sensor().prop_map(CommandBody::SensorFrame),
        (any::<i32>(), any::<i32>(), any::<i32>(), any::<f32>()).prop_map(|(x, y, z, m)| {
            CommandBody::SetTarget(Target {
                kind: TargetKind::TipPosition {
                    x_q24: x,
                    y_q24: y,
                    z_q24: z,
                },
                load: Load {
                    payload_kg: m,
                    ..Load::default()
                },
            })
        }),
        proptest::collection::vec((any::<i16>(), any::<i32>()), 0..=MAX_CAL_POINTS).prop_map(|p| {
            CommandBody::Calibrate(Calibration {
                actuator: 1,
                points: p
                    .into_iter()
                    .map(|(code, length_q24)| CalPoint { code, length_q24 })
                    .collect(),
            })
        }),
    ];
    (any::<u16>(), body).prop_map(|(seq, body)| Command { seq, body })
}

fn encoded(c: &Command) -> Vec<u8> {
    let mut buf = [0u8; MAX_PAYLOAD];
    postcard::to_slice(c, &mut buf).unwrap().to_vec()
}

fn same(a: &Command, b: &Command) -> bool {
    // NaN payloads compare unequal; compare the encodings instead.
    encoded(a) == encoded(b)
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x7072_6f74),
        ..ProptestConfig::default()
    })]

    #[test]
    fn every_command_round_trips_through_a_frame(cmd in arb_command()) {
        let mut buf = [0u8; MAX_ENCODED_FRAME];
        let n = encode_frame(&cmd, &mut buf).unwrap();
        prop_assert!(n <= MAX_ENCODED_FRAME);
        prop_assert_eq!(buf[n - 1], 0);
        prop_assert!(buf[..n - 1].iter().all(|&b| b != 0), "COBS leaves no zero inside a frame");
        let got = decode_all::<Command>(&buf[..n]);
        prop_assert_eq!(got.len(), 1);
        prop_assert!(same(got[0].as_ref().unwrap(), &cmd));
    }

    #[test]
    fn any_single_bit_flip_is_rejected_or_harmless(cmd in arb_command(), at in any::<usize>(), bit in 0u8..8) {
        let mut buf = [0u8; MAX_ENCODED_FRAME];
        let n = encode_frame(&cmd, &mut buf).unwrap();
        let i = at % (n - 1);
        buf[i] ^= 1 << bit;
        // A flip may create a zero (splitting the frame) or move COBS
        // boundaries, but must never yield a different valid command: the
        // CRC-16 makes that a 2^-16 event, and the seeded cases hold none.
        for c in decode_all::<Command>(&buf[..n]).into_iter().flatten() {
            prop_assert!(same(&c, &cmd));
        }
    }

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2_000)) {
        let _ = decode_all::<Command>(&bytes);
        let _ = decode_all::<Reply>(&bytes);
    }
}

#[test]
fn oversized_and_truncated_frames_are_named() {
    let long = vec![7u8; MAX_ENCODED_FRAME + 10];
    let mut bytes = long.clone();
    bytes.push(0);
    assert_eq!(
        decode_all::<Command>(&bytes),
        vec![Err(FrameError::Oversized)]
    );
    // The decoder recovers for the next frame.
    let mut buf = [0u8; MAX_ENCODED_FRAME];
    let n = encode_frame(
        &Command {
            seq: 9,
            body: CommandBody::GetInfo,
        },
        &mut buf,
    )
    .unwrap();
    bytes.extend_from_slice(&buf[..n]);
    let got = decode_all::<Command>(&bytes);
    assert_eq!(got.len(), 2);
    assert_eq!(
        got[1],
        Ok(Command {
            seq: 9,
            body: CommandBody::GetInfo
        })
    );
    // One byte of payload: shorter than the CRC.
    assert_eq!(
        decode_all::<Command>(&[0x02, 0x05, 0x00]),
        vec![Err(FrameError::Truncated)]
    );
    // Empty frames are ignored (resynchronisation).
    assert!(decode_all::<Command>(&[0, 0, 0]).is_empty());
}

#[test]
fn crc_matches_the_published_check_value() {
    // CRC-16/IBM-3740 of "123456789" is 0x29B1 (CRC catalogue check value):
    // a frame carrying exactly those bytes must end in B1 29 before COBS.
    let crc = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);
    assert_eq!(crc.checksum(b"123456789"), 0x29b1);
    let payload = encoded(&Command {
        seq: 1,
        body: CommandBody::LutCommit,
    });
    let mut buf = [0u8; MAX_ENCODED_FRAME];
    let n = encode_frame(
        &Command {
            seq: 1,
            body: CommandBody::LutCommit,
        },
        &mut buf,
    )
    .unwrap();
    let mut raw = buf[..n - 1].to_vec();
    let m = cobs::decode_in_place(&mut raw).unwrap();
    assert_eq!(&raw[..m - 2], &payload[..]);
    assert_eq!(
        u16::from_le_bytes([raw[m - 2], raw[m - 1]]),
        crc.checksum(&payload)
    );
}

#[test]
fn largest_messages_fit_a_frame() {
    let full = Command {
        seq: u16::MAX,
        body: CommandBody::LutChunk {
            offset: u32::MAX,
            data: heapless::Vec::from_slice(&[0xff; LUT_CHUNK]).unwrap(),
        },
    };
    let mut buf = [0u8; MAX_ENCODED_FRAME];
    assert!(encode_frame(&full, &mut buf).is_ok());
    let cal = Command {
        seq: u16::MAX,
        body: CommandBody::Calibrate(Calibration {
            actuator: 255,
            points: (0..MAX_CAL_POINTS)
                .map(|_| CalPoint {
                    code: i16::MIN,
                    length_q24: i32::MIN,
                })
                .collect(),
        }),
    };
    assert!(encode_frame(&cal, &mut buf).is_ok());
    let tele = Reply {
        seq: u16::MAX,
        body: ReplyBody::Telemetry(Telemetry {
            tick: u32::MAX,
            mode: Mode::ClosedLoop,
            faults: u16::MAX,
            estimate: (0..MAX_SEGMENTS)
                .map(|_| SegmentConfig {
                    backbone_q24: i32::MIN,
                    bend_q28: i32::MIN,
                    direction_q28: i32::MIN,
                })
                .collect(),
            tip_q24: [i32::MIN; 3],
            commanded_pa_q8: (0..MAX_ACTUATORS).map(|_| i32::MIN).collect(),
            loop_time_us: u32::MAX,
        }),
    };
    assert!(encode_frame(&tele, &mut buf).is_ok());
}
