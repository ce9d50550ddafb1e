//! Settings of a lab run and the command range they default to.

use serde::{Deserialize, Serialize};

use ocm_lutgen::OcmModel;
use ocm_shared::params::ParamPreset;

use crate::SimError;
use crate::effects::Effects;
use crate::mcu::{PidGains, PressureLimits};
use crate::plant::{PlantParams, PlateLoad};
use crate::sensors::{HallParams, ImuParams};

/// The host controllers a scenario can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ControllerKind {
    /// Exact plant inverse, no feedback (the floor).
    Oracle,
    /// Model-only inverse (OL).
    OpenLoop,
    /// Model feed-forward plus PID on the Hall lengths (host CL).
    HostPid,
}

impl ControllerKind {
    /// Report label.
    pub fn label(self) -> &'static str {
        match self {
            Self::Oracle => "oracle",
            Self::OpenLoop => "open_loop",
            Self::HostPid => "host_pid",
        }
    }
}

/// Settings of a simulation run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Seed of every random draw (effects, sensor noise, targets).
    pub seed: u64,
    /// The plant; its `effects` default to the rig's magnitudes.
    pub plant: PlantParams,
    /// Hall sensors.
    pub hall: HallParams,
    /// IMU.
    pub imu: ImuParams,
    /// Gains of the host PID.
    pub gains: PidGains,
    /// Command limits of every controller, pascals ([`working_limits`] by default).
    pub limits: PressureLimits,
    /// Shortened runs (one lap, three points, a 6 s ramp): for tests.
    pub short: bool,
    /// Pressure levels per chamber in `rom`.
    pub rom_levels: usize,
    /// Pressure range of `rom`, pascals; `None` steps through the command
    /// limits, as the dissertation steps its regulators through 0-30 kPa.
    pub rom_pressure_pa: Option<(f64, f64)>,
    /// Whether every controller is told the payload and tip force in every
    /// scenario (by default only `points` and `orientation` announce theirs).
    pub ol_knows_load: bool,
    /// Controllers to run.
    pub controllers: Vec<ControllerKind>,
    /// Log decimation: one CSV row every this many control ticks.
    pub log_every: usize,
    /// Reference preview, seconds: controllers are sent the target this far
    /// ahead of the reference they are scored against, as a host streams a
    /// planned path ahead by the actuators' response time. `None` takes the
    /// regulators' dead time plus time constant (their data-sheet lag).
    pub preview_s: Option<f64>,
    /// Cuts every time-domain scenario after this many seconds (a quick
    /// look, or a PIL smoke run); `None` runs them whole.
    pub duration_cap_s: Option<f64>,
    /// Period of target updates, seconds: the host streams the reference at
    /// this rate (a board's own loop runs at `plant.dt_s`); 0 sends one
    /// every control tick.
    pub target_period_s: f64,
}

/// The heaviest load any scenario puts on the plate, kilograms and newtons
/// along gravity: the `points` payload with the end of the `orientation`
/// force ramp.
const HEAVIEST_LOAD: (f64, f64) = (0.250, 1.80);

/// Column strain the working pressure range reaches at either end.
const WORKING_STRAIN: f64 = 0.6;

/// The working pressure range of `plant`: every pressure that holds the
/// columns within strain -0.6..0.6 (the model's strain range), unloaded or
/// under the heaviest scenario load, inside the regulator range.
///
/// Why not the regulator's own range: the OCMs use a few kilopascals of
/// it; a controller allowed the rest (a winding integrator, a chamber cut)
/// crushes the columns onto their end stops and out of the Hall sensors'
/// range, which the firmware rightly treats as a sensor fault.
pub fn working_limits(plant: &PlantParams) -> PressureLimits {
    let reg = PressureLimits {
        min_pa: plant.regulator.min_pa,
        max_pa: plant.regulator.max_pa,
    };
    // The energy model alone: building a plant would fit its potential.
    let Ok(model) = OcmModel::new(plant.ocm) else {
        return reg;
    };
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let heaviest = PlateLoad {
        payload_kg: HEAVIEST_LOAD.0,
        force_n: [
            0.0,
            0.0,
            plant.mounting.gravity_z().signum() * HEAVIEST_LOAD.1,
        ],
    };
    for load in [PlateLoad::default(), heaviest] {
        let tension = plant.external_force_n(&load)[2] / 3.0;
        for eps in [-WORKING_STRAIN, WORKING_STRAIN] {
            let t = model.axial_terms(eps);
            let pa = (tension - t.bar_n - t.hinge_n) / t.pressure_n_per_pa;
            lo = lo.min(pa);
            hi = hi.max(pa);
        }
    }
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return reg;
    }
    PressureLimits {
        min_pa: lo.max(reg.min_pa),
        max_pa: hi.min(reg.max_pa),
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        let plant = PlantParams {
            effects: Effects::RIG,
            ..PlantParams::default()
        };
        Self {
            seed: 1,
            limits: working_limits(&plant),
            plant,
            hall: HallParams::default(),
            imu: ImuParams::default(),
            gains: LAB_GAINS,
            short: false,
            rom_levels: 16,
            rom_pressure_pa: None,
            ol_knows_load: false,
            controllers: vec![
                ControllerKind::OpenLoop,
                ControllerKind::HostPid,
                ControllerKind::Oracle,
            ],
            log_every: 10,
            preview_s: None,
            duration_cap_s: None,
            target_period_s: 0.01,
        }
    }
}

/// The PID gains of the lab on the calibrated plant (pascals per metre of
/// column length), tuned on the short tracking scenarios: the integral
/// matters most (0.5 MPa/(m s) leaves a lag, 2 MPa/(m s) rings with the
/// regulators' 70 ms lag); the Table 3.1 gains scaled by the stiffness
/// ratio (200 kPa/m) make the loop unstable.
pub const LAB_GAINS: PidGains = PidGains {
    kp_pa_per_m: 45_000.0,
    ki_pa_per_m_s: 1_000_000.0,
    kd_pa_s_per_m: 2_000.0,
    filter_s: 0.01,
};

impl SimConfig {
    /// The lab's defaults on the OCM parameter set `preset`. Table 3.1
    /// reaches strain +0.6 at 0.24 kPa and needs vacuum to shorten, so its
    /// plant gets a vacuum-capable regulator (-20..35 kPa), the damping and
    /// hysteresis scale of its own forces (1 N s/m, 2 N) and the gains tuned
    /// on it; the limits follow from the plant either way.
    pub fn with_preset(preset: ParamPreset) -> Self {
        let mut cfg = Self::default();
        cfg.plant.ocm = preset.ocm();
        if preset == ParamPreset::Table31 {
            cfg.plant.regulator.min_pa = -20_000.0;
            cfg.plant.regulator.max_pa = 35_000.0;
            cfg.plant.column_damping_n_s_per_m = 1.0;
            cfg.plant.effects.hysteresis_reference_n = 2.0;
            cfg.gains = PidGains {
                kp_pa_per_m: 10_000.0,
                ki_pa_per_m_s: 400_000.0,
                kd_pa_s_per_m: 4_000.0,
                filter_s: 0.01,
            };
        }
        cfg.limits = working_limits(&cfg.plant);
        cfg
    }

    /// The reference preview in effect, seconds.
    pub fn preview(&self) -> f64 {
        self.preview_s
            .unwrap_or(self.plant.regulator.dead_time_s + self.plant.regulator.time_constant_s)
    }

    /// Checks the settings the plant does not check itself.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |what: &str, v: f64| SimError::Config(format!("{what} = {v} is out of range"));
        let l = &self.limits;
        if !(l.min_pa.is_finite() && l.max_pa.is_finite() && l.min_pa < l.max_pa) {
            return Err(SimError::Config(format!(
                "limits: min_pa {} must be below max_pa {}",
                l.min_pa, l.max_pa
            )));
        }
        let h = &self.hall;
        if !(h.sensitivity_v_per_m.is_finite() && h.sensitivity_v_per_m != 0.0) {
            return Err(bad("hall.sensitivity_v_per_m", h.sensitivity_v_per_m));
        }
        for (what, v) in [
            ("hall.noise_v", h.noise_v),
            ("hall.tilt_error_gain", h.tilt_error_gain),
            ("imu.bias_rad", self.imu.bias_rad),
            ("imu.noise_rad", self.imu.noise_rad),
            ("gains.filter_s", self.gains.filter_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(what, v));
            }
        }
        for (what, v) in [
            ("gains.kp_pa_per_m", self.gains.kp_pa_per_m),
            ("gains.ki_pa_per_m_s", self.gains.ki_pa_per_m_s),
            ("gains.kd_pa_s_per_m", self.gains.kd_pa_s_per_m),
            ("hall.center_v", h.center_v),
            ("hall.center_distance_m", h.center_distance_m),
        ] {
            if !v.is_finite() {
                return Err(bad(what, v));
            }
        }
        if !(2..=64).contains(&self.rom_levels) {
            return Err(bad("rom_levels", self.rom_levels as f64));
        }
        if !(self.target_period_s.is_finite() && (0.0..=1.0).contains(&self.target_period_s)) {
            return Err(bad("target_period_s", self.target_period_s));
        }
        if let Some(d) = self.duration_cap_s
            && !(d.is_finite() && d > 0.0)
        {
            return Err(bad("duration_cap_s", d));
        }
        if let Some(p) = self.preview_s
            && !(p.is_finite() && (0.0..=2.0).contains(&p))
        {
            return Err(bad("preview_s", p));
        }
        if let Some((a, b)) = self.rom_pressure_pa
            && !(a.is_finite() && b.is_finite() && a < b)
        {
            return Err(SimError::Config(format!(
                "rom_pressure_pa ({a}, {b}) must be finite and increasing"
            )));
        }
        Ok(())
    }
}
