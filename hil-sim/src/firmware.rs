//! The firmware as an [`Mcu`]: the same command stream drives the
//! `ocm_firmware::app::App` linked in-process ([`InProcess`], mode a), a
//! board binary under QEMU or a real board on a serial port
//! ([`crate::serial::SerialLink`], modes b and c). One `SensorFrame` per
//! control tick; the `Telemetry` reply carries the commanded pressures.
//!
//! Setup mirrors what a host does over a serial port: geometry, LUT upload
//! in chunks with its CRC-32, limits and gains, one Hall calibration per
//! column (noise-free codes at known lengths, as on the tensile tester of
//! App. C), then a target and a mode. The reference is re-sent as a
//! `SetTarget` whenever it moves.

use crc::{CRC_32_ISO_HDLC, Crc, Table};
use heapless::Vec as HVec;
use ocm_firmware::app::{App, AppConfig};
use ocm_lutgen::OcmModel;
use ocm_lutgen::tables::{TableConfig, build_tables};
use ocm_shared::protocol::{
    CalPoint, Calibration, Command, CommandBody, Gains, Geometry, Info, LUT_CHUNK, Limits, Load,
    Mode, Mount, PROTOCOL_VERSION, Reply, ReplyBody, SafeAction, SafetyConfig, SegmentConfig,
    SensorFrame, Target, TargetKind,
};

use crate::SimError;
use crate::mcu::{Mcu, McuInput, PressureLimits};
use crate::pcc::Config;
use crate::plant::{Mounting, PlantParams};
use crate::sensors::{HallParams, round_ties_away};

/// LUT buffer size the boards reserve, bytes (the one shared constant).
pub use ocm_shared::lut::LUT_CAPACITY;

/// One request-reply exchange with a firmware instance.
pub trait Link {
    /// Sends `cmd` and returns the firmware's reply to it; `now_us` is the
    /// simulated time (an in-process app has no clock of its own).
    fn exchange(&mut self, cmd: &Command, now_us: u32) -> Result<Reply, SimError>;

    /// Sends `cmds` and appends their replies in order to `replies`. A byte
    /// link sends them back to back before it waits, paying the link's
    /// latency once. The caller owns `replies` so that a tick allocates
    /// nothing.
    fn exchange_all(
        &mut self,
        cmds: &[Command],
        now_us: u32,
        replies: &mut Vec<Reply>,
    ) -> Result<(), SimError> {
        for c in cmds {
            replies.push(self.exchange(c, now_us)?);
        }
        Ok(())
    }

    /// The link watchdog the lab sets on this firmware, us ([`LAB_SAFETY`]'s by default).
    fn link_timeout_us(&self) -> u32 {
        LAB_SAFETY.link_timeout_us
    }
}

/// The firmware app linked into this process: commands go straight to
/// `App::handle`, without the byte framing.
pub struct InProcess<'a> {
    app: App<'a>,
}

impl<'a> InProcess<'a> {
    /// A fresh app keeping its LUT in `lut_buf`, ticking every `period_us`.
    pub fn new(lut_buf: &'a mut [u8], period_us: u32) -> Self {
        let config = AppConfig {
            control_period_us: period_us,
            ..AppConfig::default()
        };
        Self {
            app: App::new(lut_buf, config),
        }
    }
}

impl Link for InProcess<'_> {
    fn exchange(&mut self, cmd: &Command, now_us: u32) -> Result<Reply, SimError> {
        Ok(self.app.handle(cmd, now_us))
    }
}

/// The LUT image's CRC-32, sixteen bytes a step: every boot of an
/// in-process firmware checksums the whole image, and the table is built
/// once, not at each boot.
static LUT_CRC: Crc<u32, Table<16>> = Crc::<u32, Table<16>>::new(&CRC_32_ISO_HDLC);

/// Safety settings the lab sends: a link timeout loose enough for a slow
/// host (a PIL run in a debug build), the default stuck-sensor check.
const LAB_SAFETY: SafetyConfig = SafetyConfig {
    link_timeout_us: 1_000_000,
    action: SafeAction::Hold,
    stuck_ticks: 200,
};

/// The firmware as a controller under test, over any [`Link`].
pub struct FirmwareMcu<L: Link> {
    link: L,
    seq: u16,
    now_us: u32,
    period_us: u32,
    last_target: Option<SegmentConfig>,
    /// The last target configuration and its conversion: the reference
    /// moves once per target update, not every tick.
    last_config: Option<(Config, SegmentConfig)>,
    load: Load,
    mode: Mode,
    name: String,
    /// Reply buffer reused by every exchange.
    replies: Vec<Reply>,
}

#[inline]
fn q(v: f64, bits: u32) -> i32 {
    round_ties_away(v * f64::from(1u32 << bits)).clamp(i64::from(i32::MIN), i64::from(i32::MAX))
        as i32
}

/// The LUT image for `plant`, with a pressure grid covering `limits`.
pub fn lut_image(plant: &PlantParams, limits: &PressureLimits) -> Result<Vec<u8>, SimError> {
    let model = OcmModel::new(plant.ocm).map_err(|e| SimError::Config(e.to_string()))?;
    let cfg = TableConfig {
        p_min_kpa: limits.min_pa / 1e3,
        p_max_kpa: limits.max_pa / 1e3,
        ..TableConfig::default()
    };
    let tables =
        build_tables(&model, &cfg, &|_, _| {}).map_err(|e| SimError::Config(e.to_string()))?;
    tables
        .encode(&model)
        .map_err(|e| SimError::Config(e.to_string()))
}

/// Refuses a firmware that speaks another protocol revision (its replies
/// would be misread) or ticks at another rate than the plant steps.
pub fn check_info(info: &Info, period_us: u32) -> Result<(), SimError> {
    if info.protocol_version != PROTOCOL_VERSION {
        let [a, b, c] = info.firmware_version;
        return Err(SimError::Config(format!(
            "the firmware (version {a}.{b}.{c}) speaks protocol version {} but this host speaks \
             version {PROTOCOL_VERSION}: flash a firmware built from the same ocm release",
            info.protocol_version
        )));
    }
    if info.control_period_us != period_us {
        return Err(SimError::Config(format!(
            "the firmware ticks every {} us but the plant steps every {period_us} us (plant.dt_s)",
            info.control_period_us
        )));
    }
    Ok(())
}

impl<'a> FirmwareMcu<InProcess<'a>> {
    /// The in-process firmware keeping its LUT in `lut_buf`, set up as
    /// [`FirmwareMcu::new`] does.
    pub fn in_process(
        lut_buf: &'a mut [u8],
        image: &[u8],
        cfg: &crate::SimConfig,
        closed_loop: bool,
    ) -> Result<Self, SimError> {
        let period_us = (cfg.plant.dt_s * 1e6).round() as u32;
        Self::new(InProcess::new(lut_buf, period_us), image, cfg, closed_loop)
    }
}

impl<L: Link> FirmwareMcu<L> {
    /// Configures the firmware behind `link` for `cfg`'s plant: geometry,
    /// LUT `image` upload, limits, gains, safety and Hall calibrations;
    /// `closed_loop` picks the mode entered at the first tick.
    pub fn new(
        link: L,
        image: &[u8],
        cfg: &crate::SimConfig,
        closed_loop: bool,
    ) -> Result<Self, SimError> {
        let (plant, hall, gains, limits) = (&cfg.plant, &cfg.hall, &cfg.gains, &cfg.limits);
        let period_us = (plant.dt_s * 1e6).round() as u32;
        let mut me = Self {
            link,
            seq: 0,
            now_us: 0,
            period_us,
            last_target: None,
            last_config: None,
            load: Load::default(),
            mode: if closed_loop {
                Mode::ClosedLoop
            } else {
                Mode::OpenLoop
            },
            name: if closed_loop {
                "firmware_cl"
            } else {
                "firmware_ol"
            }
            .to_string(),
            replies: Vec::with_capacity(3),
        };
        // A board may still run an earlier session: stop it, clear its
        // latched faults and check that it speaks this protocol and ticks
        // at the plant's rate.
        match me.expect_ok(CommandBody::GetInfo)? {
            ReplyBody::Info(info) => check_info(&info, period_us)?,
            other => return Err(me.unexpected(&other)),
        }
        me.expect_ack(CommandBody::SetMode(Mode::Idle))?;
        me.expect_ack(CommandBody::ClearFaults)?;
        let mount = match plant.mounting {
            Mounting::Upright => Mount::Upright,
            Mounting::Hanging => Mount::Hanging,
        };
        me.expect_ack(CommandBody::SetGeometry(Geometry {
            manipulator: plant.manipulator,
            ocm: plant.ocm,
            mount,
        }))?;
        let crc32 = LUT_CRC.checksum(image);
        me.expect_ok(CommandBody::LutBegin {
            total_len: image.len() as u32,
            crc32,
        })?;
        for (k, chunk) in image.chunks(LUT_CHUNK).enumerate() {
            let data = HVec::from_slice(chunk)
                .map_err(|_| SimError::Config("LUT chunk too long".into()))?;
            me.expect_ok(CommandBody::LutChunk {
                offset: (k * LUT_CHUNK) as u32,
                data,
            })?;
        }
        me.expect_ok(CommandBody::LutCommit)?;
        me.expect_ack(CommandBody::SetLimits(Limits {
            min_pa: limits.min_pa as f32,
            max_pa: limits.max_pa as f32,
            slew_pa_per_s: 200_000.0,
        }))?;
        me.expect_ack(CommandBody::SetGains(Gains {
            kp_pa_per_m: gains.kp_pa_per_m as f32,
            kd_pa_s_per_m: gains.kd_pa_s_per_m as f32,
            ki_pa_per_m_s: gains.ki_pa_per_m_s as f32,
            derivative_filter_s: gains.filter_s as f32,
        }))?;
        let safety = SafetyConfig {
            link_timeout_us: me.link.link_timeout_us(),
            ..LAB_SAFETY
        };
        me.expect_ack(CommandBody::SetSafety(safety))?;
        let ocms = f64::from(plant.manipulator.ocms_per_column);
        let col = ocms * plant.ocm.rest_length_m;
        for actuator in 0..3u8 {
            let points: HVec<CalPoint, { ocm_shared::protocol::MAX_CAL_POINTS }> = (0..12)
                .map(|k| {
                    let length = col * (0.5 + k as f64 / 11.0);
                    CalPoint {
                        code: HallParams::code(hall.voltage(length / ocms)),
                        length_q24: q(length, 24),
                    }
                })
                .collect();
            me.expect_ok(CommandBody::Calibrate(Calibration { actuator, points }))?;
        }
        Ok(me)
    }

    fn error(&self, message: String) -> SimError {
        SimError::Mcu {
            name: self.name.clone(),
            message,
        }
    }

    fn unexpected(&self, body: &ReplyBody) -> SimError {
        self.error(format!("unexpected reply {body:?}"))
    }

    /// Sends `bodies` in one batch under fresh sequence numbers, leaving
    /// the replies in `self.replies`; every reply must answer its own
    /// command and none may be an error.
    fn exchange(&mut self, bodies: impl IntoIterator<Item = CommandBody>) -> Result<(), SimError> {
        let mut cmds: HVec<Command, 3> = HVec::new();
        for body in bodies {
            self.seq = self.seq.wrapping_add(1);
            cmds.push(Command {
                seq: self.seq,
                body,
            })
            .map_err(|_| self.error("more than 3 commands in one batch".into()))?;
        }
        self.replies.clear();
        self.link
            .exchange_all(&cmds, self.now_us, &mut self.replies)?;
        if self.replies.len() != cmds.len() {
            return Err(self.error(format!(
                "{} replies to {} commands",
                self.replies.len(),
                cmds.len()
            )));
        }
        for (c, r) in cmds.iter().zip(&self.replies) {
            self.check_reply(c, r)?;
        }
        Ok(())
    }

    /// A reply must answer its own command and must not be an error.
    fn check_reply(&self, c: &Command, r: &Reply) -> Result<(), SimError> {
        if r.seq != c.seq {
            return Err(self.error(format!(
                "reply to command {} answers command {}: {:?}",
                c.seq, r.seq, r.body
            )));
        }
        if let ReplyBody::Error(e) = &r.body {
            let what = format!("{:?}", c.body);
            return Err(self.error(format!(
                "{e:?} in reply to {}",
                what.chars().take(60).collect::<String>()
            )));
        }
        Ok(())
    }

    /// The commanded pressures of a `Telemetry` reply, pascals.
    fn commanded(&self, body: &ReplyBody) -> Result<[f64; 3], SimError> {
        match body {
            ReplyBody::Telemetry(t) => {
                let mut out = [0.0; 3];
                for (o, p) in out.iter_mut().zip(t.commanded_pa_q8.iter()) {
                    *o = f64::from(*p) / 256.0;
                }
                Ok(out)
            }
            other => Err(self.unexpected(other)),
        }
    }

    fn expect_ok(&mut self, body: CommandBody) -> Result<ReplyBody, SimError> {
        self.exchange([body])?;
        self.replies
            .pop()
            .map(|r| r.body)
            .ok_or_else(|| self.error("no reply".into()))
    }

    fn expect_ack(&mut self, body: CommandBody) -> Result<(), SimError> {
        self.expect_ok(body).map(|_| ())
    }
}

impl<L: Link> Mcu for FirmwareMcu<L> {
    fn name(&self) -> &str {
        &self.name
    }

    fn tick(&mut self, input: &McuInput<'_>) -> Result<[f64; 3], SimError> {
        let c: Config = input.target;
        let target = match self.last_config {
            Some((last, t)) if last == c => t,
            _ => {
                let t = SegmentConfig {
                    backbone_q24: q(c.backbone_m, 24),
                    bend_q28: q(c.bend_rad(), 28),
                    direction_q28: q(c.bend_y_rad.atan2(c.bend_x_rad), 28),
                };
                self.last_config = Some((c, t));
                t
            }
        };
        let l = &input.expected_load;
        let load = Load {
            payload_kg: l.payload_kg as f32,
            force_z_n: l.force_n[2] as f32,
            moment_x_newton_m: 0.0,
            moment_y_newton_m: 0.0,
        };
        let mut bodies: HVec<CommandBody, 3> = HVec::new();
        if self.last_target != Some(target) || self.load != load {
            let mut v = HVec::new();
            v.push(target)
                .map_err(|_| SimError::Config("one segment".into()))?;
            let _ = bodies.push(CommandBody::SetTarget(Target {
                kind: TargetKind::Configuration(v),
                load,
            }));
            if self.last_target.is_none() {
                let _ = bodies.push(CommandBody::SetMode(self.mode));
            }
            self.last_target = Some(target);
            self.load = load;
        }
        let s = input.sensors;
        let quat = s.imu_quat.map(|v| q(v, 14).clamp(-32_768, 32_767) as i16);
        let frame = SensorFrame {
            hall_codes: s.hall_codes.iter().copied().collect(),
            imu_quat_q14: quat,
            pressures_pa: s
                .pressures_pa
                .iter()
                .map(|&p| round_ties_away(p).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32)
                .collect(),
        };
        self.now_us = self.now_us.wrapping_add(self.period_us);
        if bodies.is_empty() {
            // Most ticks: the frame alone, one exchange without the batch.
            self.seq = self.seq.wrapping_add(1);
            let cmd = Command {
                seq: self.seq,
                body: CommandBody::SensorFrame(frame),
            };
            let reply = self.link.exchange(&cmd, self.now_us)?;
            self.check_reply(&cmd, &reply)?;
            return self.commanded(&reply.body);
        }
        let _ = bodies.push(CommandBody::SensorFrame(frame));
        self.exchange(bodies)?;
        let (last, setup) = self
            .replies
            .split_last()
            .ok_or_else(|| self.error("no reply".into()))?;
        if let Some(bad) = setup.iter().find(|r| r.body != ReplyBody::Ack) {
            return Err(self.unexpected(&bad.body));
        }
        self.commanded(&last.body)
    }
}

/// Runs time-domain scenario `name` with the in-process firmware in open
/// loop (`firmware_ol`) and closed loop (`firmware_cl`), beside the host
/// oracle as the floor; `ol_rmse_mm` and `cl_rmse_mm` are the firmware's.
/// The three runs share nothing and go in parallel.
pub fn run_scenario_with_firmware(
    name: &str,
    cfg: &crate::SimConfig,
) -> Result<crate::ScenarioReport, SimError> {
    run_scenario_with_image(name, cfg, &lut_image(&cfg.plant, &cfg.limits)?)
}

/// [`run_scenario_with_firmware`] with the LUT `image` given (one built by
/// `ocm lut build`, or shared between scenarios).
pub fn run_scenario_with_image(
    name: &str,
    cfg: &crate::SimConfig,
    image: &[u8],
) -> Result<crate::ScenarioReport, SimError> {
    run_firmware_pair(name, cfg, true, |closed| {
        let mut buf = vec![0u8; LUT_CAPACITY];
        let mut fw = FirmwareMcu::in_process(&mut buf, image, cfg, closed)?;
        crate::run_with_mcu(name, cfg, &mut fw)
    })
}

/// Runs time-domain scenario `name` with the firmware behind links that
/// `open` makes, a fresh one for each run (open loop, closed loop), beside
/// the host oracle: PIL under QEMU, or a real board (`parallel` false: one
/// board serves one run at a time). `image` is the LUT uploaded to it.
pub fn run_scenario_over<L: Link>(
    name: &str,
    cfg: &crate::SimConfig,
    image: &[u8],
    parallel: bool,
    open: impl Fn() -> Result<L, SimError> + Sync,
) -> Result<crate::ScenarioReport, SimError> {
    run_firmware_pair(name, cfg, parallel, |closed| {
        let mut fw = FirmwareMcu::new(open()?, image, cfg, closed)?;
        crate::run_with_mcu(name, cfg, &mut fw)
    })
}

/// Runs `name` through `run` in open and closed loop (the argument says
/// which), labels the runs `firmware_ol` and `firmware_cl` and adds the
/// host oracle as the floor, on two threads when `parallel`. The report's
/// `realtime_factor` is the simulated time of the two firmware runs over
/// the wall time of all three.
pub fn run_firmware_pair(
    name: &str,
    cfg: &crate::SimConfig,
    parallel: bool,
    run: impl Fn(bool) -> Result<crate::RunReport, SimError> + Sync,
) -> Result<crate::ScenarioReport, SimError> {
    let oracle_cfg = crate::SimConfig {
        controllers: vec![crate::ControllerKind::Oracle],
        ..cfg.clone()
    };
    let start = std::time::Instant::now();
    let (ol, cl, oracle) = if parallel {
        std::thread::scope(|s| {
            let ol = s.spawn(|| run(false));
            let oracle = s.spawn(|| crate::run_scenario(name, &oracle_cfg));
            let cl = run(true);
            let lost = |what: &str| SimError::Mcu {
                name: what.into(),
                message: "the run's thread panicked".into(),
            };
            (
                ol.join().unwrap_or_else(|_| Err(lost("firmware_ol"))),
                cl,
                oracle.join().unwrap_or_else(|_| Err(lost("oracle"))),
            )
        })
    } else {
        (
            run(false),
            run(true),
            crate::run_scenario(name, &oracle_cfg),
        )
    };
    let wall = start.elapsed().as_secs_f64();
    let mut report = oracle?;
    let mut runs = vec![ol?, cl?];
    runs[0].controller = "firmware_ol".into();
    runs[1].controller = "firmware_cl".into();
    report.ol_rmse_mm = Some(runs[0].rmse_mm);
    report.cl_rmse_mm = Some(runs[1].rmse_mm);
    let sim: f64 = runs.iter().map(|r| r.sim_s).sum();
    report.runs.extend(runs);
    report.realtime_factor = if wall > 0.0 { sim / wall } else { 0.0 };
    Ok(report)
}
