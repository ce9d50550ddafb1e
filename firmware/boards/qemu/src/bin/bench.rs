//! Instruction count of the control tick under QEMU.
//!
//! Run under `qemu-system-arm ... -icount shift=0`: every guest instruction
//! then advances virtual time by 1 ns, and SysTick (25 MHz core clock, one
//! count per 40 ns) counts instructions / 40. The bench loads the default
//! physics LUT (the image users flash), calibrates three Hall channels,
//! enters closed loop and times `TICKS` sensor-frame ticks (Hall
//! calibration, estimate with IMU, inverse kinematics for 3 chambers, PD,
//! telemetry), then prints the figures over semihosting and exits with
//! failure when the setup fails, a tick faults or the worst tick exceeds
//! `TICK_BUDGET` instructions.
#![no_std]
#![no_main]

use core::ptr::addr_of_mut;

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use ocm_board_qemu::{Cycles, LUT_CAPACITY};
use ocm_firmware::app::{App, AppConfig};
use ocm_shared::protocol::*;
use panic_halt as _;

static IMAGE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/default_lut.bin"));
static mut LUT_BUF: [u8; LUT_CAPACITY] = [0; LUT_CAPACITY];
const TICKS: u32 = 1_000;
/// Instructions one control tick may take (the 1 kHz loop's goal).
const TICK_BUDGET: u64 = 10_000;
/// Nanoseconds of virtual time per SysTick count at 25 MHz.
const NS_PER_COUNT: u64 = 40;

fn crc32(b: &[u8]) -> u32 {
    crc32_ieee(b)
}

/// Bitwise CRC-32/ISO-HDLC (the bench only needs it once).
fn crc32_ieee(b: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &x in b {
        c ^= u32::from(x);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xedb8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn cmd(body: CommandBody) -> Command {
    Command { seq: 1, body }
}

/// Times `f` over 200 calls; instructions per call.
fn time(clock: &mut Cycles, mut f: impl FnMut(i32) -> i32) -> u64 {
    let mut acc = 0i32;
    let t0 = clock.now();
    for k in 0..200 {
        acc = acc.wrapping_add(f(core::hint::black_box(k * 1_234_567)));
    }
    let dt = clock.now() - t0;
    core::hint::black_box(acc);
    dt * NS_PER_COUNT / 200
}

fn primitives(clock: &mut Cycles) {
    use ocm_firmware::fx;
    use ocm_firmware::maps::OcmMaps;
    let lut = ocm_shared::lut::LutImage::parse(IMAGE).ok();
    let sc = time(clock, |a| fx::sin_cos_q28(a).0);
    let at = time(clock, |a| fx::atan2_q28(i64::from(a), 300_000_000));
    let hy = time(clock, |a| fx::hypot(i64::from(a), 300_000_000) as i32);
    let dv = time(clock, |a| {
        fx::div_round(i64::from(a) << 20, 1_000_003).unwrap_or(0) as i32
    });
    let (mut af, mut st, mut bd) = (0, 0, 0);
    if let Some(l) = lut {
        af = time(clock, |a| l.force(a & 0x7fff, 2_560_000).unwrap_or(0));
        st = time(clock, |a| l.strain(a & 0xffff, 2_560_000).unwrap_or(0));
        bd = time(clock, |a| {
            l.bend(a & 0x3ffff, 700_000, 2_560_000).unwrap_or(0)
        });
    }
    if let Some(l) = lut {
        use ocm_firmware::kinematics as k;
        let fast = ocm_firmware::maps::FastLut::new(l);
        let model = k::Model::convert(&ocm_firmware::app::DEFAULT_GEOMETRY);
        let load = k::LoadFx {
            fz_q16: -100_000,
            mx_q24: 0,
            my_q24: 0,
        };
        let target = [SegmentConfig {
            backbone_q24: 2_100_000,
            bend_q28: 80_000_000,
            direction_q28: 100_000_000,
        }];
        let inv = time(clock, |a| {
            let t = [SegmentConfig {
                backbone_q24: target[0].backbone_q24 + (a & 0xff),
                ..target[0]
            }];
            k::inverse(&fast, &model, &load, &t, -5_120_000, 8_960_000)
                .map(|s| s.pressures_q8[0])
                .unwrap_or(0)
        });
        let est = time(clock, |a| {
            let l = [2_000_000 + (a & 0xfff), 2_050_000, 2_100_000];
            let (v, c) =
                ocm_firmware::estimate::estimate(&model, &l, Some((1_000_000, 2_000_000)), 1 << 14);
            v[0].x_q28 + c[0].bend_q28
        });
        let imu = time(clock, |a| {
            ocm_firmware::estimate::imu_tilt([16_300, 200 + (a & 0xff) as i16, -300, 0])
                .0
                .0
        });
        let tip = time(clock, |a| {
            k::tip_position(&[SegmentConfig {
                bend_q28: a & 0x0fff_ffff,
                ..target[0]
            }])[0]
        });
        hprintln!(
            "ocm-bench stages inverse={} estimate={} imu_tilt={} tip_position={}",
            inv,
            est,
            imu,
            tip
        );
    }
    hprintln!(
        "ocm-bench primitives sin_cos={} atan2={} hypot={} div64={} lut_force={} lut_strain={} lut_bend={}",
        sc,
        at,
        hy,
        dv,
        af,
        st,
        bd
    );
}

unsafe extern "C" {
    static mut __ebss: u32;
}

/// Fills the free RAM between the end of .bss and the current stack
/// pointer (minus a margin) with a pattern; returns the painted range.
fn paint_stack() -> (usize, usize) {
    let lo = core::ptr::addr_of_mut!(__ebss) as usize;
    let sp = cortex_m::register::msp::read() as usize - 64;
    let mut a = lo;
    while a < sp {
        // SAFETY: [lo, sp) is unused RAM below the live stack frame.
        unsafe { (a as *mut u32).write_volatile(0xDEAD_BEEF) };
        a += 4;
    }
    (lo, sp)
}

/// Lowest address whose pattern was overwritten: the stack's high-water mark.
fn stack_low_water((lo, sp): (usize, usize)) -> usize {
    let mut a = lo;
    // SAFETY: reads of RAM painted above.
    while a < sp && unsafe { (a as *const u32).read_volatile() } == 0xDEAD_BEEF {
        a += 4;
    }
    a
}

#[entry]
fn main() -> ! {
    let painted = paint_stack();
    let Some(cp) = cortex_m::Peripherals::take() else {
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    };
    let mut clock = Cycles::new(cp.SYST);
    // SAFETY: only `main` touches LUT_BUF.
    let buf: &'static mut [u8] = unsafe { &mut *addr_of_mut!(LUT_BUF) };
    let mut app = App::new(buf, AppConfig::default());
    let mut ok = true;
    let mut check = |r: Reply| ok &= !matches!(r.body, ReplyBody::Error(_));
    check(app.handle(
        &cmd(CommandBody::LutBegin {
            total_len: IMAGE.len() as u32,
            crc32: crc32(IMAGE),
        }),
        0,
    ));
    for (k, c) in IMAGE.chunks(LUT_CHUNK).enumerate() {
        let data = heapless::Vec::from_slice(c).unwrap_or_default();
        check(app.handle(
            &cmd(CommandBody::LutChunk {
                offset: (k * LUT_CHUNK) as u32,
                data,
            }),
            0,
        ));
    }
    check(app.handle(&cmd(CommandBody::LutCommit), 0));
    for a in 0..3u8 {
        let points = (0..8)
            .map(|k| CalPoint {
                code: 8_000 + 1_000 * k,
                length_q24: 1_600_000 + 50_000 * i32::from(k),
            })
            .collect();
        check(app.handle(
            &cmd(CommandBody::Calibrate(Calibration {
                actuator: a,
                points,
            })),
            0,
        ));
    }
    let mut v = heapless::Vec::new();
    let _ = v.push(SegmentConfig {
        backbone_q24: 2_100_000,
        bend_q28: 80_000_000,
        direction_q28: 100_000_000,
    });
    check(app.handle(
        &cmd(CommandBody::SetTarget(Target {
            kind: TargetKind::Configuration(v),
            load: Load {
                payload_kg: 0.1,
                ..Load::default()
            },
        })),
        0,
    ));
    check(app.handle(&cmd(CommandBody::SetMode(Mode::ClosedLoop)), 0));
    let setup_low = stack_low_water(painted);
    let painted = paint_stack();
    let (plain, worst1, f1, ok1) = run_ticks(&mut app, &mut clock, 0);
    ok &= ok1;
    // Same target under an external moment: the bending map joins the tick.
    let mut v = heapless::Vec::new();
    let _ = v.push(SegmentConfig {
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
    let r = app.handle(
        &cmd(CommandBody::SetTarget(Target {
            kind: TargetKind::Configuration(v),
            load,
        })),
        TICKS * 1_000,
    );
    ok &= !matches!(r.body, ReplyBody::Error(_));
    let (moment, worst2, f2, ok2) = run_ticks(&mut app, &mut clock, TICKS);
    ok &= ok2;
    let low = stack_low_water(painted);
    primitives(&mut clock);
    hprintln!(
        "ocm-bench stack: peak {} B in setup (LUT upload, calibration), {} B in ticks, of {} B free above .bss (App itself: {} B)",
        0x2000_8000 - setup_low,
        0x2000_8000 - low,
        0x2000_8000 - painted.0,
        core::mem::size_of::<App>()
    );
    hprintln!(
        "ocm-bench ticks={} setup_ok={} faults={:#x} mode={:?}",
        TICKS,
        ok,
        f1 | f2,
        app.mode()
    );
    hprintln!(
        "ocm-bench instructions_per_tick={} worst={} (payload only)",
        plain,
        worst1
    );
    hprintln!(
        "ocm-bench instructions_per_tick={} worst={} (payload and moment)",
        moment,
        worst2
    );
    let within = worst1 <= TICK_BUDGET && worst2 <= TICK_BUDGET;
    hprintln!(
        "ocm-bench budget={} instructions per tick: {}",
        TICK_BUDGET,
        if within { "met" } else { "EXCEEDED" }
    );
    let clean = f1 | f2 == 0;
    debug::exit(if ok && within && clean {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}

/// Runs `TICKS` closed-loop ticks: mean and worst instructions per tick
/// (SysTick resolution 40), the faults seen, and whether all were telemetry.
fn run_ticks(app: &mut App, clock: &mut Cycles, start: u32) -> (u64, u64, u16, bool) {
    let mut ok = true;
    let mut total = 0u64;
    let mut worst = 0u64;
    let mut faults = 0u16;
    for k in start..start + TICKS {
        let j = (k % 50) as i16;
        let frame = SensorFrame {
            hall_codes: heapless::Vec::from_slice(&[10_000 + j, 10_500 - j, 11_000 + 2 * j])
                .unwrap_or_default(),
            imu_quat_q14: [16_300, 200 + j, -300, 0],
            pressures_pa: heapless::Vec::from_slice(&[5_000, 6_000, 7_000]).unwrap_or_default(),
        };
        let c = cmd(CommandBody::SensorFrame(frame));
        let t0 = clock.now();
        let r = app.handle(&c, k * 1_000);
        let dt = clock.now() - t0;
        total += dt;
        worst = worst.max(dt);
        if let ReplyBody::Telemetry(t) = r.body {
            faults |= t.faults;
        } else {
            ok = false;
        }
    }
    (
        total * NS_PER_COUNT / u64::from(TICKS),
        worst * NS_PER_COUNT,
        faults,
        ok,
    )
}
