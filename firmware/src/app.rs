//! The firmware application: command handling, the control tick and the
//! main-loop service, generic over a [`Board`].
//!
//! [`App::handle`] is a pure function of the app state, a command and the
//! time: the same code answers frames from a UART on a board, from a pty
//! under QEMU, or from a simulator calling it in-process. Every rejected
//! command gets [`ReplyBody::Error`] and leaves the state untouched (only the
//! link watchdog's "last heard" time moves, since any valid frame proves the
//! link alive).
//!
//! The LUT is uploaded into a caller-provided buffer (a `static` of 32 KiB
//! on the boards). A committed image borrows that buffer for the rest of
//! the app's life, so one LUT can be loaded per boot; a second upload gets
//! [`ProtocolError::LutLocked`]. Failed uploads may be retried freely.

use crc::{CRC_32_ISO_HDLC, Crc};
use embedded_io::ReadReady;
use heapless::Vec;
use ocm_shared::lut::LutImage;
use ocm_shared::params::{ManipulatorParams, OcmParams};
use ocm_shared::protocol::{
    Calibration, Command, CommandBody, Field, FrameDecoder, Geometry, Info, MAX_ACTUATORS,
    MAX_SEGMENTS, Mode, Mount, PROTOCOL_VERSION, ProtocolError, Reply, ReplyBody, SafeAction,
    SafetyConfig, SegmentConfig, SensorFrame, Target, TargetKind, Telemetry, fault, write_frame,
};

use crate::calibration::{HallMap, LengthRange, calibrate};
use crate::control::{Controller, GainsFx, LimitsFx, TickConsts};
use crate::estimate::{estimate, imu_tilt};
use crate::fx::{PI_Q28, sat};
use crate::kinematics::{
    InverseSolution, LoadFx, Model, PreparedLoad, configs_for_tip, forward_prepared,
    inverse_prepared, lengths_from_vector, prime_bending, tip_position,
};
use crate::maps::{BendEntry, FastLut, MemoBend};
use crate::safety::{DEFAULT_SAFETY, StuckTracker, check_frame, link_lost};

const LUT_CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// What the app needs from the hardware (or from an emulation of it).
pub trait Board {
    /// The byte link to the host.
    type Link: embedded_io::Read + embedded_io::Write + embedded_io::ReadReady;
    /// The link.
    fn link(&mut self) -> &mut Self::Link;
    /// A free-running microsecond clock (wraps).
    fn now_us(&mut self) -> u32;
    /// A sample of the board's own sensors when one is due; boards whose
    /// sensors arrive over the link as [`CommandBody::SensorFrame`] return
    /// `None`.
    fn sample(&mut self) -> Option<SensorFrame>;
    /// Drives the pressure regulators, Pa Q24.8, one per actuator.
    fn set_pressures(&mut self, pa_q8: &[i32]);
}

/// Static settings of an app instance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AppConfig {
    /// Control period the PD law assumes, microseconds.
    pub control_period_us: u32,
    /// Send telemetry every this many board-sampled ticks (0: never).
    pub telemetry_every: u16,
    /// Share of the IMU in the bend estimate, Q1.15.
    pub imu_weight_q15: i32,
}

impl Default for AppConfig {
    fn default() -> Self {
        Self {
            control_period_us: 1_000,
            telemetry_every: 50,
            imu_weight_q15: 1 << 14,
        }
    }
}

/// The manipulator of Table 3.1 on an upright base.
pub const DEFAULT_GEOMETRY: Geometry = Geometry {
    manipulator: ManipulatorParams::TABLE_3_1,
    ocm: OcmParams::TABLE_3_1,
    mount: Mount::Upright,
};

enum Lut<'a> {
    Empty(&'a mut [u8]),
    Uploading {
        buf: &'a mut [u8],
        total: u32,
        crc32: u32,
        received: u32,
    },
    Loaded(FastLut<'a>),
}

struct TargetState {
    configs: Vec<SegmentConfig, MAX_SEGMENTS>,
    load: PreparedLoad,
    /// Mean pressure of each segment's feedforward solution, Pa Q24.8: the
    /// tick evaluates the bending map there. Fixed per target, load,
    /// geometry and limits, so the memo primed by `handle` always answers.
    bend_p_q8: [i32; MAX_SEGMENTS],
}

/// Mean pressure of each segment of an inverse solution, Pa Q24.8.
fn segment_means(sol: &InverseSolution) -> [i32; MAX_SEGMENTS] {
    let mut out = [0i32; MAX_SEGMENTS];
    for (o, p) in out.iter_mut().zip(sol.pressures_q8.chunks_exact(3)) {
        *o = sat((i64::from(p[0]) + i64::from(p[1]) + i64::from(p[2])) / 3);
    }
    out
}

/// The firmware application state.
pub struct App<'a> {
    lut: Lut<'a>,
    lut_capacity: u32,
    geometry: Geometry,
    model: Model,
    gains: GainsFx,
    limits: LimitsFx,
    safety: SafetyConfig,
    config: AppConfig,
    target: Option<TargetState>,
    hall: [Option<HallMap>; MAX_ACTUATORS],
    stuck: [StuckTracker; MAX_ACTUATORS],
    ctrl: Controller,
    mode: Mode,
    faults: u16,
    tick: u32,
    last_rx_us: u32,
    sampled_ticks: u16,
    decoder: FrameDecoder,
    bend_memo: core::cell::Cell<[BendEntry; 3]>,
}

const fn parse_version(s: &str) -> u8 {
    let b = s.as_bytes();
    let mut v: u32 = 0;
    let mut i = 0;
    while i < b.len() {
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    if v > 255 { 255 } else { v as u8 }
}

const FIRMWARE_VERSION: [u8; 3] = [
    parse_version(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_version(env!("CARGO_PKG_VERSION_MINOR")),
    parse_version(env!("CARGO_PKG_VERSION_PATCH")),
];

fn err(e: ProtocolError) -> ReplyBody {
    ReplyBody::Error(e)
}

impl<'a> App<'a> {
    /// A fresh app in Idle with the default geometry, gains, limits and
    /// safety settings; `lut_buf` receives uploaded LUT images.
    pub fn new(lut_buf: &'a mut [u8], config: AppConfig) -> Self {
        let lut_capacity = u32::try_from(lut_buf.len()).unwrap_or(u32::MAX);
        let model = Model::convert(&DEFAULT_GEOMETRY);
        let mut app = Self {
            lut: Lut::Empty(lut_buf),
            lut_capacity,
            geometry: DEFAULT_GEOMETRY,
            model,
            gains: GainsFx::DEFAULT,
            limits: LimitsFx::DEFAULT,
            safety: DEFAULT_SAFETY,
            config,
            target: None,
            hall: [None; MAX_ACTUATORS],
            stuck: [StuckTracker::default(); MAX_ACTUATORS],
            ctrl: Controller::default(),
            mode: Mode::Idle,
            faults: 0,
            tick: 0,
            last_rx_us: 0,
            sampled_ticks: 0,
            decoder: FrameDecoder::new(),
            bend_memo: core::cell::Cell::new([None; 3]),
        };
        app.vent();
        app
    }

    /// Current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Latched fault flags.
    pub fn faults(&self) -> u16 {
        self.faults
    }

    /// Pressure limits in force.
    pub fn limits(&self) -> LimitsFx {
        self.limits
    }

    /// Number of actuators in use.
    pub fn actuators(&self) -> usize {
        3 * self.model.segments
    }

    /// Commanded pressures of all actuator channels, Pa Q24.8 (the first
    /// [`Self::actuators`] are in use).
    pub fn commanded(&self) -> [i32; MAX_ACTUATORS] {
        self.ctrl.channels.map(|c| c.output_q8)
    }

    fn vent(&mut self) {
        let v = self.limits.clamp(0);
        for ch in self.ctrl.channels.iter_mut() {
            ch.output_q8 = v;
        }
    }

    fn enter_safe(&mut self) {
        self.mode = Mode::Safe;
        if self.safety.action == SafeAction::Vent {
            self.vent();
        }
    }

    fn lut(&self) -> Option<&FastLut<'a>> {
        match &self.lut {
            Lut::Loaded(img) => Some(img),
            _ => None,
        }
    }

    fn running(&self) -> bool {
        matches!(self.mode, Mode::OpenLoop | Mode::ClosedLoop)
    }

    /// Link watchdog: call often with the board clock. Enters the safe state
    /// when a running controller has not heard from the host in time.
    pub fn service(&mut self, now_us: u32) {
        if self.running() && link_lost(now_us, self.last_rx_us, self.safety.link_timeout_us) {
            self.faults |= fault::LINK_LOSS;
            self.enter_safe();
        }
    }

    /// Handles one decoded command at time `now_us` and returns the reply.
    pub fn handle(&mut self, cmd: &Command, now_us: u32) -> Reply {
        self.service(now_us);
        self.last_rx_us = now_us;
        let body = match &cmd.body {
            CommandBody::Ping { nonce } => ReplyBody::Pong { nonce: *nonce },
            CommandBody::GetInfo => ReplyBody::Info(self.info()),
            CommandBody::LutBegin { total_len, crc32 } => self.lut_begin(*total_len, *crc32),
            CommandBody::LutChunk { offset, data } => self.lut_chunk(*offset, data),
            CommandBody::LutCommit => self.lut_commit(),
            CommandBody::SetMode(m) => self.set_mode(*m),
            CommandBody::SetGains(g) => match GainsFx::new(g) {
                Some(g) => {
                    self.gains = g;
                    ReplyBody::Ack
                }
                None => err(ProtocolError::InvalidArgument { field: Field::Gain }),
            },
            CommandBody::SetLimits(l) => match LimitsFx::new(l) {
                Some(l) => {
                    self.limits = l;
                    for ch in self.ctrl.channels.iter_mut() {
                        ch.output_q8 = l.clamp(ch.output_q8);
                    }
                    self.refresh_bend_pressures();
                    ReplyBody::Ack
                }
                None => {
                    let field = if l.slew_pa_per_s.is_finite() && l.slew_pa_per_s > 0.0 {
                        Field::PressureLimit
                    } else {
                        Field::SlewRate
                    };
                    err(ProtocolError::InvalidArgument { field })
                }
            },
            CommandBody::SetSafety(s) => {
                if !(1_000..=10_000_000).contains(&s.link_timeout_us) {
                    err(ProtocolError::InvalidArgument {
                        field: Field::LinkTimeout,
                    })
                } else {
                    self.safety = *s;
                    ReplyBody::Ack
                }
            }
            CommandBody::SetGeometry(g) => self.set_geometry(g),
            CommandBody::SetTarget(t) => self.set_target(t),
            CommandBody::Calibrate(c) => self.calibrate(c),
            CommandBody::SensorFrame(f) => self.control_tick(f),
            CommandBody::ClearFaults => {
                self.faults = 0;
                self.stuck = [StuckTracker::default(); MAX_ACTUATORS];
                ReplyBody::Ack
            }
        };
        if !matches!(cmd.body, CommandBody::SensorFrame(_)) {
            self.prime_bend_memo();
        }
        Reply { seq: cmd.seq, body }
    }

    /// Runs the bending lookups the next control tick will make, so that a
    /// new target, load, geometry or LUT costs its bisection here rather
    /// than inside the tick (which still computes it on a memo miss).
    // Out of line: its frame stays out of `handle`'s.
    #[inline(never)]
    fn prime_bend_memo(&self) {
        let (Some(img), Some(t)) = (self.lut(), &self.target) else {
            return;
        };
        let maps = MemoBend::new(img, &self.bend_memo);
        prime_bending(&maps, &self.model, &t.load, &t.configs, &t.bend_p_q8);
    }

    /// Recomputes the target's bending pressures after the LUT, geometry or
    /// limits changed (kept as they were when the target is now out of
    /// reach: the next tick then reports the model fault).
    #[inline(never)]
    fn refresh_bend_pressures(&mut self) {
        let (Some(img), Some(t)) = (self.lut(), &self.target) else {
            return;
        };
        let sol = inverse_prepared(
            img,
            &self.model,
            &t.load,
            &t.configs,
            (self.limits.min_q8, self.limits.max_q8),
            None,
        );
        if let (Some(sol), Some(t)) = (sol, &mut self.target) {
            t.bend_p_q8 = segment_means(&sol);
        }
    }

    fn info(&self) -> Info {
        Info {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: FIRMWARE_VERSION,
            lut_capacity: self.lut_capacity,
            lut_loaded: self.lut().is_some(),
            segments: self.model.segments as u8,
            control_period_us: self.config.control_period_us,
            mode: self.mode,
        }
    }

    fn lut_begin(&mut self, total: u32, crc32: u32) -> ReplyBody {
        if total > self.lut_capacity {
            return err(ProtocolError::LutTooLarge {
                capacity: self.lut_capacity,
            });
        }
        let lut = core::mem::replace(&mut self.lut, Lut::Empty(Default::default()));
        let (next, reply) = match lut {
            Lut::Loaded(img) => (Lut::Loaded(img), err(ProtocolError::LutLocked)),
            Lut::Empty(buf) | Lut::Uploading { buf, .. } => (
                Lut::Uploading {
                    buf,
                    total,
                    crc32,
                    received: 0,
                },
                ReplyBody::LutProgress { received: 0 },
            ),
        };
        self.lut = next;
        reply
    }

    fn lut_chunk(&mut self, offset: u32, data: &[u8]) -> ReplyBody {
        match &mut self.lut {
            Lut::Uploading {
                buf,
                total,
                received,
                ..
            } => {
                if offset != *received {
                    return err(ProtocolError::LutOutOfOrder {
                        expected: *received,
                        got: offset,
                    });
                }
                let end = (offset as usize).saturating_add(data.len());
                if end > *total as usize {
                    return err(ProtocolError::LutTooLarge {
                        capacity: self.lut_capacity,
                    });
                }
                let Some(dst) = buf.get_mut(offset as usize..end) else {
                    return err(ProtocolError::LutTooLarge {
                        capacity: self.lut_capacity,
                    });
                };
                dst.copy_from_slice(data);
                *received = end as u32;
                ReplyBody::LutProgress {
                    received: *received,
                }
            }
            Lut::Loaded(_) => err(ProtocolError::LutLocked),
            Lut::Empty(_) => err(ProtocolError::LutNotStarted),
        }
    }

    #[inline(never)]
    fn lut_commit(&mut self) -> ReplyBody {
        let want_hash = self.geometry.ocm.hash();
        // Validate through a shared reborrow first, so a failure leaves the
        // upload exactly as it was.
        match &self.lut {
            Lut::Uploading {
                buf,
                total,
                crc32,
                received,
            } => {
                if received != total {
                    return err(ProtocolError::LutIncomplete {
                        received: *received,
                        total: *total,
                    });
                }
                let bytes = buf.get(..*total as usize).unwrap_or(&[]);
                if LUT_CRC.checksum(bytes) != *crc32 {
                    return err(ProtocolError::LutCrc);
                }
                match LutImage::parse(bytes) {
                    Ok(img) if img.param_hash() != want_hash => {
                        return err(ProtocolError::LutParamMismatch);
                    }
                    Ok(_) => {}
                    Err(_) => return err(ProtocolError::LutInvalid),
                }
            }
            Lut::Loaded(_) => return err(ProtocolError::LutLocked),
            Lut::Empty(_) => return err(ProtocolError::LutNotStarted),
        }
        let lut = core::mem::replace(&mut self.lut, Lut::Empty(Default::default()));
        let Lut::Uploading { buf, total, .. } = lut else {
            self.lut = lut;
            return err(ProtocolError::LutNotStarted);
        };
        let frozen: &'a [u8] = buf;
        let bytes = frozen.get(..total as usize).unwrap_or(&[]);
        match LutImage::parse(bytes) {
            Ok(img) => {
                self.lut = Lut::Loaded(FastLut::new(img));
                self.refresh_bend_pressures();
                ReplyBody::LutLoaded {
                    param_hash: img.param_hash(),
                    len: total,
                }
            }
            // Unreachable after the check above; keep the app consistent
            // (and panic-free) anyway: the buffer is lost, not the app.
            Err(_) => err(ProtocolError::LutInvalid),
        }
    }

    fn set_mode(&mut self, m: Mode) -> ReplyBody {
        match m {
            Mode::Idle => {
                self.mode = Mode::Idle;
                self.ctrl.reset_dynamics();
                self.vent();
                return ReplyBody::Ack;
            }
            Mode::Safe => {
                self.enter_safe();
                return ReplyBody::Ack;
            }
            Mode::OpenLoop | Mode::ClosedLoop => {}
        }
        if self.faults != 0 {
            return err(ProtocolError::FaultsActive {
                faults: self.faults,
            });
        }
        if self.lut().is_none() {
            return err(ProtocolError::NoLut);
        }
        if self.target.is_none() {
            return err(ProtocolError::NoTarget);
        }
        if m == Mode::ClosedLoop && self.hall.iter().take(self.actuators()).any(Option::is_none) {
            return err(ProtocolError::NotCalibrated);
        }
        if self.mode != m {
            self.ctrl.reset_dynamics();
        }
        self.mode = m;
        ReplyBody::Ack
    }

    fn set_geometry(&mut self, g: &Geometry) -> ReplyBody {
        if self.running() {
            return err(ProtocolError::WrongMode { mode: self.mode });
        }
        let Ok(model) = Model::new(g) else {
            return err(ProtocolError::InvalidArgument {
                field: Field::Geometry,
            });
        };
        if let Some(img) = self.lut()
            && img.image.param_hash() != g.ocm.hash()
        {
            return err(ProtocolError::LutParamMismatch);
        }
        if model.segments != self.model.segments {
            self.target = None;
        }
        self.geometry = *g;
        self.model = model;
        self.refresh_bend_pressures();
        ReplyBody::Ack
    }

    fn column_range(&self) -> LengthRange {
        let c = i64::from(self.model.column_q24);
        LengthRange {
            min_q24: sat(c / 5),
            max_q24: sat(c * 5 / 2),
        }
    }

    #[inline(never)]
    fn set_target(&mut self, t: &Target) -> ReplyBody {
        let Some(load) = LoadFx::new(&t.load, &self.model) else {
            return err(ProtocolError::InvalidArgument { field: Field::Load });
        };
        let configs = match &t.kind {
            TargetKind::Configuration(v) => {
                if v.len() != self.model.segments {
                    return err(ProtocolError::InvalidArgument {
                        field: Field::TargetSegments,
                    });
                }
                let range = self.column_range();
                let ok = v.iter().all(|c| {
                    (range.min_q24..=range.max_q24).contains(&c.backbone_q24)
                        && c.bend_q28.unsigned_abs() <= PI_Q28.unsigned_abs()
                });
                if !ok {
                    return err(ProtocolError::InvalidArgument {
                        field: Field::TargetValue,
                    });
                }
                v.clone()
            }
            TargetKind::TipPosition {
                x_q24,
                y_q24,
                z_q24,
            } => match configs_for_tip(&self.model, [*x_q24, *y_q24, *z_q24]) {
                Some(c) => c,
                None => {
                    return err(ProtocolError::InvalidArgument {
                        field: Field::TargetValue,
                    });
                }
            },
        };
        let load = PreparedLoad::new(&load);
        let mut bend_p_q8 = [0; MAX_SEGMENTS];
        if let Some(img) = self.lut() {
            let Some(sol) = inverse_prepared(
                img,
                &self.model,
                &load,
                &configs,
                (self.limits.min_q8, self.limits.max_q8),
                None,
            ) else {
                return err(ProtocolError::Unreachable);
            };
            bend_p_q8 = segment_means(&sol);
        }
        self.target = Some(TargetState {
            configs,
            load,
            bend_p_q8,
        });
        ReplyBody::Ack
    }

    #[inline(never)]
    fn calibrate(&mut self, c: &Calibration) -> ReplyBody {
        if self.running() {
            return err(ProtocolError::WrongMode { mode: self.mode });
        }
        let i = usize::from(c.actuator);
        if i >= self.actuators() {
            return err(ProtocolError::InvalidArgument {
                field: Field::Actuator,
            });
        }
        match calibrate(c.actuator, &c.points, self.column_range()) {
            Ok((map, report)) => {
                self.hall[i] = Some(map);
                ReplyBody::Calibrated(report)
            }
            Err(e) => err(ProtocolError::CalibrationFailed(e)),
        }
    }

    /// One control tick on a sensor sample (Fig 3.7).
    // Out of line, like the other big handlers: `handle` inlines the
    // rest, and its frame would hold the union of their locals.
    #[inline(never)]
    fn control_tick(&mut self, f: &SensorFrame) -> ReplyBody {
        let n = self.actuators();
        if f.hall_codes.len() != n || f.pressures_pa.len() != n {
            return err(ProtocolError::InvalidArgument {
                field: Field::SensorChannels,
            });
        }
        let use_imu = self.config.imu_weight_q15 > 0;
        let window = (self.limits.min_q8, self.limits.max_q8);
        self.faults |= check_frame(f, n, &self.hall, window, use_imu);
        if self.running() {
            for i in 0..n {
                let out = self.ctrl.channels[i].output_q8;
                if self.stuck[i].update(f.hall_codes[i], out, self.safety.stuck_ticks) {
                    self.faults |= fault::HALL_STUCK;
                }
            }
        }
        // Hall lengths -> configuration estimate (App. C, B.2).
        let calibrated = self.hall.iter().take(n).all(Option::is_some);
        let mut lengths = [0i32; MAX_ACTUATORS];
        for (i, l) in lengths.iter_mut().enumerate().take(n) {
            if let Some(m) = &self.hall[i] {
                *l = m.length_q24(f.hall_codes[i]);
            }
        }
        let imu = if use_imu && self.faults & fault::IMU_INVALID == 0 {
            Some(imu_tilt(f.imu_quat_q14).0)
        } else {
            None
        };
        let mut measured = [0i32; MAX_ACTUATORS];
        let est = if calibrated {
            let (vecs, configs) =
                estimate(&self.model, &lengths[..n], imu, self.config.imu_weight_q15);
            for (seg, v) in vecs.iter().enumerate() {
                let l = lengths_from_vector(&self.model, v);
                measured[3 * seg..3 * seg + 3].copy_from_slice(&l);
            }
            configs
        } else {
            // Without Hall maps the model itself (eq 3.35) is the estimate.
            let commanded = self.commanded();
            match (self.lut(), &self.target) {
                (Some(img), Some(t)) => {
                    forward_prepared(img, &self.model, &t.load, &commanded[..n]).unwrap_or_default()
                }
                _ => Vec::new(),
            }
        };
        if self.faults != 0 && self.running() {
            self.enter_safe();
        }
        if self.running() {
            self.drive(&measured, calibrated && est.len() == self.model.segments);
        } else if self.mode == Mode::Idle || self.safety.action == SafeAction::Vent {
            self.vent();
        }
        self.tick = self.tick.wrapping_add(1);
        let commanded = self.commanded();
        let tip = tip_position(&est);
        ReplyBody::Telemetry(Telemetry {
            tick: self.tick,
            mode: self.mode,
            faults: self.faults,
            estimate: est,
            tip_q24: tip,
            commanded_pa_q8: commanded.iter().take(n).copied().collect(),
            loop_time_us: 0,
        })
    }

    /// Open- or closed-loop outputs from the inverse model and the
    /// measured (fused) column lengths.
    fn drive(&mut self, measured: &[i32; MAX_ACTUATORS], have_estimate: bool) {
        let dt = self.config.control_period_us;
        let (Some(img), Some(t)) = (self.lut(), &self.target) else {
            self.faults |= fault::MODEL;
            self.enter_safe();
            return;
        };
        // The bending map runs once, at the target's own feedforward mean
        // pressure (its pressure dependence is weak), from the memo that
        // `handle` primed.
        let maps = MemoBend::new(img, &self.bend_memo);
        let ff: Option<InverseSolution> = inverse_prepared(
            &maps,
            &self.model,
            &t.load,
            &t.configs,
            (self.limits.min_q8, self.limits.max_q8),
            Some(&t.bend_p_q8),
        );
        let Some(ff) = ff else {
            self.faults |= fault::MODEL;
            self.enter_safe();
            return;
        };
        let closed = self.mode == Mode::ClosedLoop && have_estimate;
        let k = TickConsts::new(&self.gains, &self.limits, dt);
        for (i, &meas) in measured.iter().enumerate().take(self.actuators()) {
            let p_ff = ff.pressures_q8.get(i).copied().unwrap_or(0);
            if closed {
                let target = ff.lengths_q24.get(i).copied().unwrap_or(0);
                self.ctrl
                    .closed_loop_with(i, p_ff, target, meas, &self.limits, &k);
            } else {
                self.ctrl.open_loop_with(i, p_ff, &self.limits, &k);
            }
        }
    }

    /// Feeds received bytes through the frame decoder; for every complete
    /// frame, handles it and writes the reply with `send`.
    pub fn receive_bytes(&mut self, bytes: &[u8], now_us: u32, mut send: impl FnMut(&Reply)) {
        for &b in bytes {
            match self.decoder.push::<Command>(b) {
                None => {}
                Some(Ok(cmd)) => {
                    let reply = self.handle(&cmd, now_us);
                    send(&reply);
                }
                Some(Err(e)) => send(&Reply {
                    seq: 0,
                    body: err(ProtocolError::Frame(e)),
                }),
            }
        }
    }

    /// One pass of the main loop: watchdog, link input, board-sampled
    /// tick, outputs. Never blocks on the link's input.
    pub fn poll<B: Board>(&mut self, board: &mut B) {
        let now = board.now_us();
        self.service(now);
        let mut buf = [0u8; 64];
        loop {
            let ready = board.link().read_ready().unwrap_or(false);
            if !ready {
                break;
            }
            let n = match embedded_io::Read::read(board.link(), &mut buf) {
                Ok(n) if n > 0 => n,
                _ => break,
            };
            for &b in &buf[..n] {
                let reply = match self.decoder.push::<Command>(b) {
                    None => continue,
                    Some(Ok(cmd)) => {
                        let t0 = board.now_us();
                        let mut r = self.handle(&cmd, t0);
                        if let ReplyBody::Telemetry(t) = &mut r.body {
                            t.loop_time_us = board.now_us().wrapping_sub(t0);
                        }
                        r
                    }
                    Some(Err(e)) => Reply {
                        seq: 0,
                        body: err(ProtocolError::Frame(e)),
                    },
                };
                let _ = write_frame(board.link(), &reply);
            }
            let out = self.commanded();
            board.set_pressures(&out[..self.actuators()]);
        }
        if let Some(frame) = board.sample() {
            let t0 = board.now_us();
            let body = self.control_tick(&frame);
            let t1 = board.now_us();
            self.sampled_ticks = self.sampled_ticks.wrapping_add(1);
            let every = self.config.telemetry_every;
            if every > 0 && self.sampled_ticks.is_multiple_of(every) {
                let mut reply = Reply { seq: 0, body };
                if let ReplyBody::Telemetry(t) = &mut reply.body {
                    t.loop_time_us = t1.wrapping_sub(t0);
                }
                let _ = write_frame(board.link(), &reply);
            }
        }
        let out = self.commanded();
        board.set_pressures(&out[..self.actuators()]);
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::kinematics::inverse;
    use ocm_shared::protocol::{LUT_CHUNK, Load};
    use std::vec;

    fn send(app: &mut App<'_>, body: CommandBody) -> ReplyBody {
        app.handle(&Command { seq: 1, body }, 0).body
    }

    /// A new moment target is looked up in the bending map by `handle`, at
    /// the mean pressure of its own inverse solution: the ticks that follow
    /// find it in the memo and leave the memo as it was.
    #[test]
    fn moment_target_primes_the_bending_memo_for_the_ticks() {
        let mut img = vec![0u8; 32 * 1024];
        let n = crate::bringup::write_image(&DEFAULT_GEOMETRY.ocm, &mut img).unwrap_or(0);
        img.truncate(n);
        let mut buf = vec![0u8; 32 * 1024];
        let mut app = App::new(&mut buf, AppConfig::default());
        let crc32 = LUT_CRC.checksum(&img);
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
}
