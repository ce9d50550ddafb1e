//! The firmware application: the state of one app instance and the
//! dispatch of commands to their handlers, generic over a [`Board`].
//!
//! [`App::handle`] is a pure function of the app state, a command and the
//! time: the same code answers frames from a UART on a board, from a pty
//! under QEMU, or from a simulator calling it in-process. Every rejected
//! command gets [`ReplyBody::Error`] and leaves the state untouched (only the
//! link watchdog's "last heard" time moves, since any valid frame proves the
//! link alive).
//!
//! The rooms: `board` (what the app needs from the hardware), `config`
//! (static settings), `upload` (the LUT upload), `setup` (mode, geometry,
//! target and calibration commands), `tick` (the control tick of Fig 3.7)
//! and `link` (bytes in, replies out, the main loop).

mod board;
mod config;
mod link;
mod setup;
mod tick;
mod upload;

pub use board::Board;
pub use config::{AppConfig, DEFAULT_GEOMETRY};

use heapless::Vec;
use ocm_shared::protocol::{
    Command, CommandBody, Field, FrameDecoder, Geometry, Info, MAX_ACTUATORS, MAX_SEGMENTS, Mode,
    PROTOCOL_VERSION, ProtocolError, Reply, ReplyBody, SafeAction, SafetyConfig, SegmentConfig,
    fault,
};

use crate::calibration::HallMap;
use crate::control::{Controller, GainsFx, LimitsFx, TickConsts};
use crate::fx::sat;
use crate::kinematics::{InverseSolution, Model, PreparedLoad, inverse_prepared, prime_bending};
use crate::maps::{BendEntry, FastLut, MemoBend};
use crate::safety::{DEFAULT_SAFETY, StuckTracker, link_lost};

use config::FIRMWARE_VERSION;
use upload::Lut;

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
    /// The feedforward solution of the target in force, computed by
    /// `SetTarget` (without a moment) or the first control tick after any
    /// other command, and reused until the next one: it depends only on
    /// what commands set (target, load, geometry, limits, LUT), so every
    /// tick in between would recompute the same integers.
    feedforward: Option<InverseSolution>,
    /// The control law's per-tick constants (four 64-bit divisions), kept
    /// like `feedforward` until the next command other than a frame.
    tick_consts: Option<TickConsts>,
}

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
            feedforward: None,
            tick_consts: None,
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
        let setup = !matches!(cmd.body, CommandBody::SensorFrame(_));
        if setup {
            self.feedforward = None;
            self.tick_consts = None;
        }
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
        if setup {
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
}

#[cfg(test)]
mod tests;
