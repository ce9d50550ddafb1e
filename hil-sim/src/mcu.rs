//! The controller under test and the host's own controllers.
//!
//! An [`Mcu`] gets one [`McuInput`] per control tick (the raw sensor sample
//! a board would see, the reference and the load the operator announced)
//! and returns the commanded chamber pressures. The plant's hidden state
//! ([`GroundTruth`]) travels separately and reaches only the [`Oracle`]. The firmware, in-process or
//! over a serial link, is one implementation; this module provides three
//! host ones:
//!
//! - [`Oracle`]: the plant's exact static inverse as feed-forward, with the
//!   true load, spread, regulator offsets and hysteresis state, evaluated
//!   ahead by the regulator's dead time plus a lag lead. No feedback. It is
//!   the floor each controller is compared to.
//! - [`OpenLoop`]: the dissertation's model-only control (eq 3.27-3.29,
//!   3.33-3.36) on the OCM energy model, blind to the bending stiffness of
//!   the OCMs, the spread, the offsets and, unless told, the payload.
//! - [`HostPid`]: [`OpenLoop`] feed-forward plus PID on the column lengths
//!   read from the Hall sensors (Fig 3.7), a host-side stand-in for the
//!   firmware's closed loop.

use ocm_lutgen::OcmModel;
use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::pcc::Config;
use crate::plant::{Plant, PlateLoad};
use crate::reference::Path;
use crate::sensors::{HallParams, SensorSample};

/// What the controller under test sees at one tick: nothing a real
/// controller could not know.
#[derive(Debug, Clone, Copy)]
pub struct McuInput<'a> {
    /// Simulation time, seconds.
    pub time_s: f64,
    /// Raw sensor sample.
    pub sensors: &'a SensorSample,
    /// The reference being tracked (controllers may look ahead on it).
    pub reference: &'a Path,
    /// The target sent now: the reference `preview_s` ahead ([`crate::SimConfig::preview`]).
    pub target: Config,
    /// Load announced by the operator (what a `SetTarget` would carry).
    pub expected_load: PlateLoad,
}

/// The plant's hidden state at one tick, which only the [`Oracle`] reads:
/// [`tick`] hands it to the oracle and to no other controller.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroundTruth {
    /// The true load on the plate.
    pub load: PlateLoad,
    /// Hysteresis tensions of the columns, newtons.
    pub hysteresis_n: [f64; 3],
}

/// A controller under test.
pub trait Mcu {
    /// Name used in reports and logs.
    fn name(&self) -> &str;
    /// One control tick: commanded gauge pressures, pascals.
    fn tick(&mut self, input: &McuInput<'_>) -> Result<[f64; 3], SimError>;
    /// The oracle behind this controller, if it is one: [`tick`] then gives
    /// it the ground truth. Controllers under test keep the default.
    fn as_oracle(&mut self) -> Option<&mut Oracle> {
        None
    }
}

/// One control tick of `mcu`: the oracle gets `truth` beside the input,
/// every other controller only the input.
pub fn tick(
    mcu: &mut dyn Mcu,
    input: &McuInput<'_>,
    truth: &GroundTruth,
) -> Result<[f64; 3], SimError> {
    match mcu.as_oracle() {
        Some(oracle) => oracle.tick_with_truth(input, truth),
        None => mcu.tick(input),
    }
}

/// Pressure limits every controller clamps into.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PressureLimits {
    /// Lowest command, pascals.
    pub min_pa: f64,
    /// Highest command, pascals.
    pub max_pa: f64,
}

impl PressureLimits {
    fn clamp(&self, p: [f64; 3]) -> [f64; 3] {
        p.map(|v| {
            if v.is_finite() {
                v.clamp(self.min_pa, self.max_pa)
            } else {
                0.0_f64.clamp(self.min_pa, self.max_pa)
            }
        })
    }
}

/// The exact-inverse feed-forward controller.
#[derive(Debug, Clone)]
pub struct Oracle {
    plant: Plant,
    limits: PressureLimits,
    last: [f64; 3],
}

impl Oracle {
    /// An oracle for `plant` (a copy of the simulated plant itself).
    pub fn new(plant: Plant, limits: PressureLimits) -> Self {
        Self {
            plant,
            limits,
            last: [0.0; 3],
        }
    }

    fn holding(
        &self,
        t: f64,
        input: &McuInput<'_>,
        truth: &GroundTruth,
    ) -> Result<[f64; 3], SimError> {
        let q = input.reference.config_at(t);
        self.plant
            .pressures_for(&q, &truth.load, truth.hysteresis_n)
    }

    /// One tick with the plant's ground truth (see [`tick`]).
    pub fn tick_with_truth(
        &mut self,
        input: &McuInput<'_>,
        truth: &GroundTruth,
    ) -> Result<[f64; 3], SimError> {
        let r = self.plant.params().regulator;
        let ahead = input.time_s + r.dead_time_s;
        let h = 0.01;
        let (p0, p1) = match (
            self.holding(ahead, input, truth),
            self.holding(ahead + h, input, truth),
        ) {
            (Ok(a), Ok(b)) => (a, b),
            // Outside the reachable set: keep the last command.
            _ => return Ok(self.last),
        };
        let off = self.plant.regulator_offsets_pa();
        // The lag's inverse: u = p + tau dp/dt, on the delayed reference.
        let cmd: [f64; 3] =
            std::array::from_fn(|i| p0[i] + r.time_constant_s * (p1[i] - p0[i]) / h - off[i]);
        self.last = self.limits.clamp(cmd);
        Ok(self.last)
    }
}

impl Mcu for Oracle {
    fn name(&self) -> &str {
        "oracle"
    }

    /// Without the ground truth the oracle has nothing to invert.
    fn tick(&mut self, _input: &McuInput<'_>) -> Result<[f64; 3], SimError> {
        Err(SimError::Config(
            "the oracle needs the plant's ground truth: tick it through mcu::tick".into(),
        ))
    }

    fn as_oracle(&mut self) -> Option<&mut Oracle> {
        Some(self)
    }
}

/// The model-only inverse of eq 3.36 on the OCM energy model.
#[derive(Debug, Clone)]
pub struct OpenLoop {
    model: OcmModel,
    ocms: f64,
    d_m: f64,
    weight_z_n: f64,
    gravity_z: f64,
    knows_load: bool,
    limits: PressureLimits,
}

impl OpenLoop {
    /// The controller for `plant`'s nominal design; with `knows_load` it
    /// uses the announced load, otherwise only the manipulator's own weight
    /// (the dissertation's open loop assumes no external load).
    pub fn new(plant: &Plant, knows_load: bool, limits: PressureLimits) -> Result<Self, SimError> {
        let p = plant.params();
        let model = OcmModel::new(p.ocm).map_err(|e| SimError::Config(e.to_string()))?;
        let gz = p.mounting.gravity_z();
        Ok(Self {
            model,
            ocms: f64::from(p.manipulator.ocms_per_column),
            d_m: p.manipulator.column_radius_m,
            weight_z_n: plant.moving_mass_kg(&PlateLoad::default()) * gz,
            gravity_z: gz,
            knows_load,
            limits,
        })
    }

    /// Pressures that hold configuration `q` under the load (unclamped).
    pub fn pressures(&self, q: &Config, load: &PlateLoad) -> [f64; 3] {
        let mut fz = self.weight_z_n;
        if self.knows_load {
            fz += load.payload_kg * self.gravity_z + load.force_n[2];
        }
        // eq 3.29 without moments: the columns share the axial load.
        let tension = fz / 3.0;
        let l = q.column_lengths(self.d_m);
        let col = self.ocms * self.model.params().rest_length_m;
        l.map(|li| {
            let t = self.model.axial_terms(li / col - 1.0);
            (tension - t.bar_n - t.hinge_n) / t.pressure_n_per_pa
        })
    }
}

impl Mcu for OpenLoop {
    fn name(&self) -> &str {
        "open_loop"
    }

    fn tick(&mut self, input: &McuInput<'_>) -> Result<[f64; 3], SimError> {
        let q = input.target;
        Ok(self.limits.clamp(self.pressures(&q, &input.expected_load)))
    }
}

/// PID gains of [`HostPid`], on the column length error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PidGains {
    /// Proportional, pascals per metre.
    pub kp_pa_per_m: f64,
    /// Integral, pascals per metre second.
    pub ki_pa_per_m_s: f64,
    /// Derivative on the measured length rate, pascal seconds per metre.
    pub kd_pa_s_per_m: f64,
    /// Low-pass time constant of the length measurement, seconds.
    pub filter_s: f64,
}

impl Default for PidGains {
    fn default() -> Self {
        Self {
            kp_pa_per_m: 10_000.0,
            ki_pa_per_m_s: 400_000.0,
            kd_pa_s_per_m: 4_000.0,
            filter_s: 0.01,
        }
    }
}

/// Open-loop feed-forward plus PID on the Hall-measured column lengths.
#[derive(Debug, Clone)]
pub struct HostPid {
    ff: OpenLoop,
    hall: HallParams,
    gains: PidGains,
    dt_s: f64,
    integral: [f64; 3],
    filtered: Option<[f64; 3]>,
    rate: [f64; 3],
}

impl HostPid {
    /// A PID at control period `dt_s` reading Hall sensors with the nominal
    /// calibration `hall`.
    pub fn new(ff: OpenLoop, hall: HallParams, gains: PidGains, dt_s: f64) -> Self {
        Self {
            ff,
            hall,
            gains,
            dt_s,
            integral: [0.0; 3],
            filtered: None,
            rate: [0.0; 3],
        }
    }
}

impl Mcu for HostPid {
    fn name(&self) -> &str {
        "host_pid"
    }

    fn tick(&mut self, input: &McuInput<'_>) -> Result<[f64; 3], SimError> {
        let q = input.target;
        let ff = self.ff.pressures(&q, &input.expected_load);
        let target = q.column_lengths(self.ff.d_m);
        let meas = input
            .sensors
            .hall_codes
            .map(|c| self.ff.ocms * self.hall.distance_of_code(c));
        let a = self.dt_s / (self.gains.filter_s + self.dt_s);
        let prev = self.filtered.unwrap_or(meas);
        let filt: [f64; 3] = std::array::from_fn(|i| prev[i] + a * (meas[i] - prev[i]));
        for i in 0..3 {
            self.rate[i] = (filt[i] - prev[i]) / self.dt_s;
        }
        self.filtered = Some(filt);
        let lim = self.ff.limits;
        let mut out = [0.0; 3];
        for i in 0..3 {
            let e = target[i] - filt[i];
            let unsat = ff[i] + self.gains.kp_pa_per_m * e + self.integral[i]
                - self.gains.kd_pa_s_per_m * self.rate[i];
            // Conditional integration: no wind-up while saturated.
            let saturated = (unsat >= lim.max_pa && e > 0.0) || (unsat <= lim.min_pa && e < 0.0);
            if !saturated {
                self.integral[i] += self.gains.ki_pa_per_m_s * e * self.dt_s;
            }
            out[i] = unsat;
        }
        Ok(lim.clamp(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ground truth reaches the oracle through [`tick`] and changes its
    /// command; without it the oracle refuses to run, and a controller
    /// under test is never handed it.
    #[test]
    fn only_the_oracle_reads_the_ground_truth() {
        let cfg = crate::SimConfig::default();
        let plant = Plant::new(cfg.plant, 1).expect("plant");
        // A pose the plant reaches: its rest under mid-range pressures.
        let mid = 0.5 * (cfg.limits.min_pa + cfg.limits.max_pa);
        let span = cfg.limits.max_pa - cfg.limits.min_pa;
        let column_m =
            f64::from(cfg.plant.manipulator.ocms_per_column) * cfg.plant.ocm.rest_length_m;
        let guess = Config {
            backbone_m: column_m,
            bend_x_rad: 0.0,
            bend_y_rad: 0.0,
        };
        let held = plant
            .static_equilibrium(
                [mid - 0.1 * span, mid, mid + 0.1 * span],
                &PlateLoad::default(),
                guess,
            )
            .expect("rest pose");
        let path = Path::Hold(held);
        let sample = SensorSample {
            hall_codes: [0; 3],
            imu_quat: [1.0, 0.0, 0.0, 0.0],
            pressures_pa: [0.0; 3],
        };
        let input = McuInput {
            time_s: 0.0,
            sensors: &sample,
            reference: &path,
            target: path.config_at(0.0),
            expected_load: PlateLoad::default(),
        };
        let calm = GroundTruth::default();
        let loaded = GroundTruth {
            load: PlateLoad {
                payload_kg: 0.1,
                ..PlateLoad::default()
            },
            ..GroundTruth::default()
        };
        let mut oracle = Oracle::new(plant.clone(), cfg.limits);
        assert!(Mcu::tick(&mut oracle, &input).is_err());
        let a = tick(&mut oracle, &input, &calm).expect("oracle");
        let b = tick(&mut oracle, &input, &loaded).expect("oracle");
        assert_ne!(a, b, "the true payload must move the oracle's command");
        let mut direct = Oracle::new(plant.clone(), cfg.limits);
        assert_eq!(direct.tick_with_truth(&input, &loaded).expect("oracle"), b);

        let mut open = OpenLoop::new(&plant, true, cfg.limits).expect("open loop");
        assert!(open.as_oracle().is_none());
        let c = tick(&mut open, &input, &calm).expect("open loop");
        let d = tick(&mut open, &input, &loaded).expect("open loop");
        assert_eq!(c, d);
    }
}
