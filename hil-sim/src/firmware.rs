//! The firmware linked in-process as an [`Mcu`] (issue mode a): the same
//! `ocm_firmware::app::App` a board runs, driven through the wire
//! protocol's messages (`Command` in, `Reply` out) without the byte
//! framing, one `SensorFrame` per control tick.
//!
//! Setup mirrors what a host does over a serial port: geometry, LUT upload
//! in chunks with its CRC-32, limits and gains, one Hall calibration per
//! column (noise-free codes at known lengths, as on the tensile tester of
//! App. C), then a target and a mode. The reference is re-sent as a
//! `SetTarget` whenever it moves.

use crc::{CRC_32_ISO_HDLC, Crc};
use heapless::Vec as HVec;
use ocm_firmware::app::{App, AppConfig};
use ocm_lutgen::OcmModel;
use ocm_lutgen::tables::{TableConfig, build_tables};
use ocm_shared::protocol::{
    CalPoint, Calibration, Command, CommandBody, Gains, Geometry, LUT_CHUNK, Limits, Load, Mode,
    Mount, Reply, ReplyBody, SegmentConfig, SensorFrame, Target, TargetKind,
};

use crate::SimError;
use crate::mcu::{Mcu, McuInput, PidGains, PressureLimits};
use crate::pcc::Config;
use crate::plant::{Mounting, PlantParams};
use crate::sensors::HallParams;

/// LUT buffer size the boards reserve, bytes.
pub const LUT_CAPACITY: usize = 32 * 1024;

/// The firmware app as a controller under test.
pub struct FirmwareMcu<'a> {
    app: App<'a>,
    seq: u16,
    now_us: u32,
    period_us: u32,
    last_target: Option<SegmentConfig>,
    load: Load,
    mode: Mode,
    name: String,
}

fn q(v: f64, bits: u32) -> i32 {
    (v * f64::from(1u32 << bits))
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
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

impl<'a> FirmwareMcu<'a> {
    /// Boots the app in `lut_buf`, uploads `image` and configures it;
    /// `closed_loop` picks the mode entered at the first tick.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        lut_buf: &'a mut [u8],
        image: &[u8],
        plant: &PlantParams,
        hall: &HallParams,
        gains: &PidGains,
        limits: &PressureLimits,
        closed_loop: bool,
    ) -> Result<Self, SimError> {
        let period_us = (plant.dt_s * 1e6).round() as u32;
        let config = AppConfig {
            control_period_us: period_us,
            ..AppConfig::default()
        };
        let mut me = Self {
            app: App::new(lut_buf, config),
            seq: 0,
            now_us: 0,
            period_us,
            last_target: None,
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
        };
        let mount = match plant.mounting {
            Mounting::Upright => Mount::Upright,
            Mounting::Hanging => Mount::Hanging,
        };
        me.expect_ack(CommandBody::SetGeometry(Geometry {
            manipulator: plant.manipulator,
            ocm: plant.ocm,
            mount,
        }))?;
        let crc32 = Crc::<u32>::new(&CRC_32_ISO_HDLC).checksum(image);
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

    fn send(&mut self, body: CommandBody) -> Reply {
        self.seq = self.seq.wrapping_add(1);
        self.app.handle(
            &Command {
                seq: self.seq,
                body,
            },
            self.now_us,
        )
    }

    fn expect_ok(&mut self, body: CommandBody) -> Result<ReplyBody, SimError> {
        match self.send(body).body {
            ReplyBody::Error(e) => Err(SimError::Mcu {
                name: "firmware".into(),
                message: format!("{e:?}"),
            }),
            other => Ok(other),
        }
    }

    fn expect_ack(&mut self, body: CommandBody) -> Result<(), SimError> {
        self.expect_ok(body).map(|_| ())
    }
}

impl Mcu for FirmwareMcu<'_> {
    fn name(&self) -> &str {
        &self.name
    }

    fn tick(&mut self, input: &McuInput<'_>) -> Result<[f64; 3], SimError> {
        let c: Config = input.target;
        let target = SegmentConfig {
            backbone_q24: q(c.backbone_m, 24),
            bend_q28: q(c.bend_rad(), 28),
            direction_q28: q(c.bend_y_rad.atan2(c.bend_x_rad), 28),
        };
        let l = &input.expected_load;
        let load = Load {
            payload_kg: l.payload_kg as f32,
            force_z_n: l.force_n[2] as f32,
            moment_x_newton_m: 0.0,
            moment_y_newton_m: 0.0,
        };
        if self.last_target != Some(target) || self.load != load {
            let mut v = HVec::new();
            v.push(target)
                .map_err(|_| SimError::Config("one segment".into()))?;
            self.expect_ack(CommandBody::SetTarget(Target {
                kind: TargetKind::Configuration(v),
                load,
            }))?;
            if self.last_target.is_none() {
                self.expect_ack(CommandBody::SetMode(self.mode))?;
            }
            self.last_target = Some(target);
            self.load = load;
        }
        let s = input.sensors;
        let quat = s.imu_quat.map(|v| q(v, 14).clamp(-32_768, 32_767) as i16);
        let frame = SensorFrame {
            hall_codes: s.hall_codes.iter().copied().collect(),
            imu_quat_q14: quat,
            pressures_pa: s.pressures_pa.iter().map(|p| p.round() as i32).collect(),
        };
        self.now_us = self.now_us.wrapping_add(self.period_us);
        match self.send(CommandBody::SensorFrame(frame)).body {
            ReplyBody::Telemetry(t) => {
                let mut out = [0.0; 3];
                for (o, p) in out.iter_mut().zip(t.commanded_pa_q8.iter()) {
                    *o = f64::from(*p) / 256.0;
                }
                Ok(out)
            }
            other => Err(SimError::Mcu {
                name: self.name.clone(),
                message: format!("unexpected reply {other:?}"),
            }),
        }
    }
}

/// Runs time-domain scenario `name` with the in-process firmware in open
/// loop (`firmware_ol`) and closed loop (`firmware_cl`), beside the host
/// oracle as the floor; `ol_rmse_mm` and `cl_rmse_mm` are the firmware's.
pub fn run_scenario_with_firmware(
    name: &str,
    cfg: &crate::SimConfig,
) -> Result<crate::ScenarioReport, SimError> {
    let image = lut_image(&cfg.plant, &cfg.limits)?;
    let mut runs = Vec::new();
    for (closed, label) in [(false, "firmware_ol"), (true, "firmware_cl")] {
        let mut buf = vec![0u8; LUT_CAPACITY];
        let mut fw = FirmwareMcu::new(
            &mut buf,
            &image,
            &cfg.plant,
            &cfg.hall,
            &cfg.gains,
            &cfg.limits,
            closed,
        )?;
        let mut run = crate::run_with_mcu(name, cfg, &mut fw)?;
        run.controller = label.to_string();
        runs.push(run);
    }
    let oracle_cfg = crate::SimConfig {
        controllers: vec![crate::ControllerKind::Oracle],
        ..cfg.clone()
    };
    let mut report = crate::run_scenario(name, &oracle_cfg)?;
    report.ol_rmse_mm = Some(runs[0].rmse_mm);
    report.cl_rmse_mm = Some(runs[1].rmse_mm);
    let (sim, wall) = runs.iter().fold((0.0, 0.0), |(s, w), r| {
        (s + r.sim_s, w + r.sim_s / r.realtime_factor.max(1e-12))
    });
    report.realtime_factor = if wall > 0.0 { sim / wall } else { 0.0 };
    report.runs.extend(runs);
    Ok(report)
}
