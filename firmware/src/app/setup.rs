//! Commands that set the app up: mode changes (with their preconditions),
//! geometry, target and load, and the Hall calibration of one column.

use ocm_shared::protocol::{
    Calibration, Field, Geometry, MAX_SEGMENTS, Mode, ProtocolError, ReplyBody, Target, TargetKind,
};

use super::{App, TargetState, err, segment_means};
use crate::calibration::{LengthRange, calibrate};
use crate::fx::{PI_Q28, sat};
use crate::kinematics::{LoadFx, Model, PreparedLoad, configs_for_tip, inverse_prepared};

impl<'a> App<'a> {
    pub(super) fn set_mode(&mut self, m: Mode) -> ReplyBody {
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

    pub(super) fn set_geometry(&mut self, g: &Geometry) -> ReplyBody {
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

    pub(super) fn column_range(&self) -> LengthRange {
        let c = i64::from(self.model.column_q24);
        LengthRange {
            min_q24: sat(c / 5),
            max_q24: sat(c * 5 / 2),
        }
    }

    #[inline(never)]
    pub(super) fn set_target(&mut self, t: &Target) -> ReplyBody {
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
            // Without a moment the tick's solution ignores the bending hint
            // and is this one: no need to solve again at the first tick.
            if load.moment.m_q24 == 0 {
                self.feedforward = Some(sol);
            }
        }
        self.target = Some(TargetState {
            configs,
            load,
            bend_p_q8,
        });
        ReplyBody::Ack
    }

    #[inline(never)]
    pub(super) fn calibrate(&mut self, c: &Calibration) -> ReplyBody {
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
}
