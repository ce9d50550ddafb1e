//! The control tick (Fig 3.7): safety checks on the sensor frame, Hall
//! lengths and IMU to a configuration estimate, the inverse model as feed
//! forward and the PD law per actuator, then telemetry.

use heapless::Vec;
use ocm_shared::protocol::{
    Field, MAX_ACTUATORS, Mode, ProtocolError, ReplyBody, SafeAction, SensorFrame, Telemetry, fault,
};

use super::{App, err};
use crate::control::TickConsts;
use crate::estimate::{estimate, imu_tilt};
use crate::kinematics::{forward_prepared, inverse_prepared, lengths_from_vector, tip_position};
use crate::maps::MemoBend;
use crate::safety::check_frame;

impl<'a> App<'a> {
    /// One control tick on a sensor sample (Fig 3.7).
    // Out of line, like the other big handlers: `handle` inlines the
    // rest, and its frame would hold the union of their locals.
    #[inline(never)]
    pub(super) fn control_tick(&mut self, f: &SensorFrame) -> ReplyBody {
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
    pub(super) fn drive(&mut self, measured: &[i32; MAX_ACTUATORS], have_estimate: bool) {
        let dt = self.config.control_period_us;
        let (Some(img), Some(t)) = (self.lut(), &self.target) else {
            self.faults |= fault::MODEL;
            self.enter_safe();
            return;
        };
        // The bending map runs once, at the target's own feedforward mean
        // pressure (its pressure dependence is weak), from the memo that
        // `handle` primed; the solution is kept until the next command.
        if self.feedforward.is_none() {
            let maps = MemoBend::new(img, &self.bend_memo);
            self.feedforward = inverse_prepared(
                &maps,
                &self.model,
                &t.load,
                &t.configs,
                (self.limits.min_q8, self.limits.max_q8),
                Some(&t.bend_p_q8),
            );
        }
        let Some(ff) = &self.feedforward else {
            self.faults |= fault::MODEL;
            self.enter_safe();
            return;
        };
        let closed = self.mode == Mode::ClosedLoop && have_estimate;
        let k = *self
            .tick_consts
            .get_or_insert_with(|| TickConsts::new(&self.gains, &self.limits, dt));
        for (i, &meas) in measured.iter().enumerate().take(3 * self.model.segments) {
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
}
