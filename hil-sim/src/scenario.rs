//! The dissertation's experiments as scenarios (Ch. 3.3.7, 3.4.2 and
//! 4.10.4), each run with every requested controller on the same seeded
//! plant and sensors.
//!
//! | name | what | dissertation |
//! |---|---|---|
//! | `rom` | 16^3 pressure combinations, model against plant | Fig 3.12-A, eq 3.40-3.43 |
//! | `triangle`, `circle` | z-plane tracking, 10 s per lap | Fig 3.12-B..D |
//! | `points` | 10 random targets, 250 g payload, 10 s each | Fig 3.13 |
//! | `orientation` | hold a bent pose, tip load 0.75 -> 1.80 N over 25 s | Fig 3.11 |
//! | `disconnect` | circle, one chamber cut for 5 s | Fig 4.26-B |
//! | `step_load` | hold a pose, 250 g payload added at once | issue 4 (PD rejects a step load) |
//!
//! Positions are in the base frame with z along the unbent backbone, away
//! from the base; for the default hanging mount the plane z = 100 mm is the
//! dissertation's z = -100 mm.

use std::collections::BTreeMap;
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use ocm_lutgen::OcmModel;

use crate::SimError;
use crate::effects::Effects;
use crate::mcu::{HostPid, Mcu, McuInput, OpenLoop, Oracle, PidGains, PressureLimits};
use crate::metrics::{distance, mean, rms, step_times, workspace_diagonal};
use crate::pcc::{Config, quaternion_error_rad};
use crate::plant::{Plant, PlantParams, PlateLoad};
use crate::reference::Path;
use crate::sensors::{HallParams, ImuParams, Sensors};

/// Names of all scenarios, in the order `all` runs them.
pub const SCENARIOS: &[&str] = &[
    "rom",
    "triangle",
    "circle",
    "points",
    "orientation",
    "disconnect",
    "step_load",
];

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
    /// Pressure range of `rom`, pascals; `None` derives the range that
    /// spans column strains -0.45 .. 0.45 at rest under the plate weight.
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
            gains: PidGains::default(),
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

impl SimConfig {
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

/// One logged sample (CSV row; units in the column names).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LogRow {
    /// Time, s.
    pub t_s: f64,
    /// Reference tip x, mm.
    pub ref_x_mm: f64,
    /// Reference tip y, mm.
    pub ref_y_mm: f64,
    /// Reference tip z, mm.
    pub ref_z_mm: f64,
    /// Plate x, mm.
    pub x_mm: f64,
    /// Plate y, mm.
    pub y_mm: f64,
    /// Plate z, mm.
    pub z_mm: f64,
    /// Position error, mm.
    pub err_mm: f64,
    /// Orientation error against the reference configuration, rad (eq 3.42).
    pub q_err_rad: f64,
    /// Commanded pressure 1, Pa.
    pub cmd1_pa: f64,
    /// Commanded pressure 2, Pa.
    pub cmd2_pa: f64,
    /// Commanded pressure 3, Pa.
    pub cmd3_pa: f64,
    /// Chamber pressure 1, Pa.
    pub p1_pa: f64,
    /// Chamber pressure 2, Pa.
    pub p2_pa: f64,
    /// Chamber pressure 3, Pa.
    pub p3_pa: f64,
    /// Hall code 1.
    pub hall1: i16,
    /// Hall code 2.
    pub hall2: i16,
    /// Hall code 3.
    pub hall3: i16,
    /// Tip force along z, N.
    pub load_z_n: f64,
}

/// Result of one controller on one scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Controller name.
    pub controller: String,
    /// Position RMSE over the scored part, mm.
    pub rmse_mm: f64,
    /// Largest position error over the scored part, mm.
    pub max_err_mm: f64,
    /// Scenario-specific figures (names carry units).
    pub figures: BTreeMap<String, f64>,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Simulated seconds per wall second.
    pub realtime_factor: f64,
    /// Decimated log.
    #[serde(skip)]
    pub log: Vec<LogRow>,
}

impl RunReport {
    /// The log as CSV bytes.
    pub fn csv_bytes(&self) -> Result<Vec<u8>, SimError> {
        let mut w = csv::Writer::from_writer(Vec::new());
        for r in &self.log {
            w.serialize(r).map_err(|e| SimError::Io {
                path: "<memory>".into(),
                message: format!("writing: {e}"),
            })?;
        }
        w.into_inner().map_err(|e| SimError::Io {
            path: "<memory>".into(),
            message: format!("writing: {e}"),
        })
    }
}

/// Summary of one scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScenarioReport {
    /// Scenario name.
    pub name: String,
    /// Seed used.
    pub seed: u64,
    /// Open-loop RMSE, mm, when the open loop ran.
    pub ol_rmse_mm: Option<f64>,
    /// Host closed-loop RMSE, mm, when it ran.
    pub cl_rmse_mm: Option<f64>,
    /// Oracle RMSE, mm, when it ran.
    pub oracle_rmse_mm: Option<f64>,
    /// Simulated seconds per wall second over all runs.
    pub realtime_factor: f64,
    /// Scenario-level figures (the `rom` metrics live here).
    pub figures: BTreeMap<String, f64>,
    /// One entry per controller.
    pub runs: Vec<RunReport>,
    /// `rom` only: every solved pressure combination.
    #[serde(skip)]
    pub cloud: Vec<RomPoint>,
}

/// One `rom` pressure combination: where the plant settles and where the
/// model puts it (CSV row; units in the column names).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RomPoint {
    /// Chamber pressure 1, Pa.
    pub p1_pa: f64,
    /// Chamber pressure 2, Pa.
    pub p2_pa: f64,
    /// Chamber pressure 3, Pa.
    pub p3_pa: f64,
    /// Plant tip x, mm.
    pub x_mm: f64,
    /// Plant tip y, mm.
    pub y_mm: f64,
    /// Plant tip z, mm.
    pub z_mm: f64,
    /// Model tip x, mm.
    pub model_x_mm: f64,
    /// Model tip y, mm.
    pub model_y_mm: f64,
    /// Model tip z, mm.
    pub model_z_mm: f64,
    /// Position error, mm.
    pub err_mm: f64,
    /// Orientation error, rad (eq 3.42).
    pub q_err_rad: f64,
}

impl ScenarioReport {
    /// Writes one CSV log per run as `DIR/<scenario>_<controller>.csv`, and
    /// the `rom` cloud as `DIR/rom_cloud.csv`.
    pub fn write_csv(&self, dir: &std::path::Path) -> Result<(), SimError> {
        if !self.cloud.is_empty() {
            let path = dir.join("rom_cloud.csv");
            let io = |e: String| SimError::Io {
                path: path.display().to_string(),
                message: e,
            };
            std::fs::create_dir_all(dir).map_err(|e| io(format!("writing: {e}")))?;
            let mut w = csv::Writer::from_path(&path).map_err(|e| io(format!("writing: {e}")))?;
            for p in &self.cloud {
                w.serialize(p).map_err(|e| io(format!("writing: {e}")))?;
            }
            w.flush().map_err(|e| io(format!("writing: {e}")))?;
        }
        for r in &self.runs {
            let path = dir.join(format!("{}_{}.csv", self.name, r.controller));
            let io = |e: std::io::Error| SimError::Io {
                path: path.display().to_string(),
                message: format!("writing: {e}"),
            };
            std::fs::create_dir_all(dir).map_err(io)?;
            std::fs::write(&path, r.csv_bytes()?).map_err(io)?;
        }
        Ok(())
    }
}

/// A time-varying experiment.
#[derive(Debug, Clone)]
struct Setup {
    path: Path,
    duration_s: f64,
    score_from_s: f64,
    payload_kg: f64,
    /// Tip force along gravity: from `(t0, f0)` to `(t1, f1)` linearly.
    force_ramp: Option<(f64, f64, f64, f64)>,
    /// Chamber cut: `(chamber, from, to)`.
    cut: Option<(usize, f64, f64)>,
    /// Payload added at this time, kilograms: `(time, mass)`.
    payload_step: Option<(f64, f64)>,
    /// Whether the operator announces the load to the controller (the
    /// experiment's own payload and force, as in the dissertation); an
    /// unannounced load is a disturbance the feedback must reject.
    announced: bool,
}

impl Setup {
    fn load_at(&self, t: f64, cfg: &SimConfig) -> PlateLoad {
        let mut force = 0.0;
        if let Some((t0, f0, t1, f1)) = self.force_ramp {
            let u = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
            force = f0 + u * (f1 - f0);
        }
        // Along gravity.
        let sign = cfg.plant.mounting.gravity_z().signum();
        let step = match self.payload_step {
            Some((at, kg)) if t >= at => kg,
            _ => 0.0,
        };
        PlateLoad {
            payload_kg: self.payload_kg + step,
            force_n: [0.0, 0.0, sign * force],
        }
    }
}

fn setup(name: &str, cfg: &SimConfig) -> Result<Setup, SimError> {
    let laps = if cfg.short { 1.0 } else { 2.0 };
    let settle = 3.0;
    let z = 0.100;
    let r = 0.030;
    Ok(match name {
        "circle" | "disconnect" => {
            let laps = if name == "disconnect" { 2.5 } else { laps };
            Setup {
                path: Path::Circle {
                    center_m: [0.0, 0.0, z],
                    radius_m: r,
                    period_s: 10.0,
                    start_s: settle,
                },
                duration_s: settle + 10.0 * laps,
                score_from_s: settle,
                payload_kg: 0.0,
                force_ramp: None,
                cut: (name == "disconnect").then_some((0, settle + 5.0, settle + 10.0)),
                payload_step: None,
                announced: false,
            }
        }
        "triangle" => {
            let v = |deg: f64| {
                let a = deg.to_radians();
                [r * a.cos(), r * a.sin(), z]
            };
            Setup {
                path: Path::Polygon {
                    vertices_m: vec![v(90.0), v(210.0), v(330.0)],
                    period_s: 10.0,
                    start_s: settle,
                },
                duration_s: settle + 10.0 * laps,
                score_from_s: settle,
                payload_kg: 0.0,
                force_ramp: None,
                cut: None,
                payload_step: None,
                announced: false,
            }
        }
        "points" => {
            let n = if cfg.short { 3 } else { 10 };
            let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(0x5eed));
            let targets: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    [
                        rng.random_range(-0.025..0.025),
                        rng.random_range(-0.025..0.025),
                        rng.random_range(0.090..0.125),
                    ]
                })
                .collect();
            Setup {
                duration_s: 10.0 * n as f64,
                path: Path::Points {
                    targets_m: targets,
                    dwell_s: 10.0,
                },
                score_from_s: 0.0,
                payload_kg: 0.250,
                force_ramp: None,
                cut: None,
                payload_step: None,
                announced: true,
            }
        }
        "orientation" => {
            let ramp = if cfg.short { 6.0 } else { 25.0 };
            Setup {
                path: Path::Hold(Config::from_polar(0.110, 0.30, 0.0)),
                duration_s: settle + ramp + 3.0,
                score_from_s: settle,
                payload_kg: 0.0,
                force_ramp: Some((settle, 0.75, settle + ramp, 1.80)),
                cut: None,
                payload_step: None,
                announced: true,
            }
        }
        "step_load" => Setup {
            path: Path::Hold(Config::from_polar(0.110, 0.20, 0.5)),
            duration_s: settle + 10.0,
            score_from_s: settle,
            payload_kg: 0.0,
            force_ramp: None,
            cut: None,
            payload_step: Some((settle, 0.250)),
            announced: false,
        },
        other => return Err(SimError::UnknownScenario(other.to_string())),
    })
}

fn build_mcu(
    kind: ControllerKind,
    plant: &Plant,
    cfg: &SimConfig,
) -> Result<Box<dyn Mcu>, SimError> {
    Ok(match kind {
        ControllerKind::Oracle => Box::new(Oracle::new(plant.clone(), cfg.limits)),
        ControllerKind::OpenLoop => Box::new(OpenLoop::new(plant, cfg.ol_knows_load, cfg.limits)?),
        ControllerKind::HostPid => Box::new(HostPid::new(
            OpenLoop::new(plant, cfg.ol_knows_load, cfg.limits)?,
            cfg.hall,
            cfg.gains,
            cfg.plant.dt_s,
        )),
    })
}

/// Runs scenario `name` (one of [`SCENARIOS`]) with every controller of
/// `cfg.controllers`.
pub fn run_scenario(name: &str, cfg: &SimConfig) -> Result<ScenarioReport, SimError> {
    cfg.validate()?;
    if name == "rom" {
        return rom(cfg);
    }
    let plant = Plant::new(cfg.plant, cfg.seed)?;
    let mut runs = Vec::new();
    for &kind in &cfg.controllers {
        let mut mcu = build_mcu(kind, &plant, cfg)?;
        let mut run = simulate(name, &plant, cfg, mcu.as_mut())?;
        run.controller = kind.label().to_string();
        runs.push(run);
    }
    let pick = |k: ControllerKind| {
        runs.iter()
            .find(|r| r.controller == k.label())
            .map(|r| r.rmse_mm)
    };
    let sim: f64 = runs.iter().map(|r| r.sim_s).sum();
    let wall: f64 = runs
        .iter()
        .map(|r| r.sim_s / r.realtime_factor.max(1e-12))
        .sum();
    Ok(ScenarioReport {
        name: name.to_string(),
        seed: cfg.seed,
        ol_rmse_mm: pick(ControllerKind::OpenLoop),
        cl_rmse_mm: pick(ControllerKind::HostPid),
        oracle_rmse_mm: pick(ControllerKind::Oracle),
        realtime_factor: if wall > 0.0 { sim / wall } else { 0.0 },
        figures: BTreeMap::new(),
        runs,
        cloud: Vec::new(),
    })
}

/// Runs the time-domain scenario `name` with an external controller (the
/// firmware in-process, or a serial link).
pub fn run_with_mcu(name: &str, cfg: &SimConfig, mcu: &mut dyn Mcu) -> Result<RunReport, SimError> {
    cfg.validate()?;
    let plant = Plant::new(cfg.plant, cfg.seed)?;
    simulate(name, &plant, cfg, mcu)
}

fn simulate(
    name: &str,
    plant: &Plant,
    cfg: &SimConfig,
    mcu: &mut dyn Mcu,
) -> Result<RunReport, SimError> {
    let su = setup(name, cfg)?;
    let dt = cfg.plant.dt_s;
    let load0 = su.load_at(0.0, cfg);
    let q_start = su.path.config_at(0.0);
    // Every controller starts from the same rest state at the start point.
    let p0 = plant
        .pressures_for(&q_start, &load0, [0.0; 3])?
        .map(|p| p.clamp(cfg.limits.min_pa, cfg.limits.max_pa));
    let q0 = plant.static_equilibrium(p0, &load0, q_start)?;
    let mut state = plant.state_at(q0, p0, load0);
    let mut sensors = Sensors::new(
        cfg.hall,
        cfg.imu,
        cfg.plant.manipulator.column_radius_m,
        f64::from(cfg.plant.manipulator.ocms_per_column),
        ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(0x5e05)),
    );
    let duration = cfg
        .duration_cap_s
        .map_or(su.duration_s, |c| c.min(su.duration_s));
    let steps = (duration / dt).round() as usize;
    let mut log = Vec::new();
    let mut errs = Vec::new();
    let mut err_t = Vec::new();
    let mut q_errs = Vec::new();
    let (mut p_hi, mut p_lo) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut cmd_hi, mut cmd_lo) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut violations = 0usize;
    let start = Instant::now();
    let expected = PlateLoad::default();
    let preview = cfg.preview();
    for k in 0..steps {
        let t = k as f64 * dt;
        state.load = su.load_at(t, cfg);
        if let Some((ch, a, b)) = su.cut {
            state.connected[ch] = !(t >= a && t < b);
        }
        let sample = sensors.sample(&state.q, state.pressures_pa());
        // Announced loads reach the controller with the target updates.
        let announced = if cfg.ol_knows_load || su.announced {
            su.load_at(target_time(t, cfg.target_period_s), cfg)
        } else {
            expected
        };
        let input = McuInput {
            time_s: t,
            sensors: &sample,
            reference: &su.path,
            target: su
                .path
                .config_at(target_time(t, cfg.target_period_s) + preview),
            expected_load: announced,
            true_load: state.load,
            true_hysteresis_n: plant.hysteresis_n(&state),
        };
        let cmd = mcu.tick(&input).map_err(|e| SimError::Mcu {
            name: mcu.name().to_string(),
            message: format!("at t = {t:.3} s: {e}"),
        })?;
        plant.step(&mut state, cmd);
        let p = state.pressures_pa();
        for i in 0..3 {
            p_hi = p_hi.max(p[i]);
            p_lo = p_lo.min(p[i]);
            cmd_hi = cmd_hi.max(cmd[i]);
            cmd_lo = cmd_lo.min(cmd[i]);
            let lim = &cfg.plant.regulator;
            // The firmware holds its limits in f32 and commands in Q24.8.
            let tol = 1e-6 * cfg.limits.max_pa.abs().max(cfg.limits.min_pa.abs()) + 1.0 / 128.0;
            if p[i] > lim.max_pa + 1e-9
                || p[i] < lim.min_pa - 1e-9
                || cmd[i] > cfg.limits.max_pa + tol
                || cmd[i] < cfg.limits.min_pa - tol
            {
                violations += 1;
            }
        }
        let tn = state.time_s;
        let tip = state.q.position();
        let rf = su.path.tip_at(tn);
        let err = distance(tip, rf);
        let logged = k % cfg.log_every.max(1) == 0;
        let scored = tn >= su.score_from_s;
        // The orientation error costs a configuration solve: only where used.
        let q_err = if logged || (scored && name == "orientation") {
            quaternion_error_rad(state.q.quaternion(), su.path.config_at(tn).quaternion())
        } else {
            0.0
        };
        if scored {
            errs.push(err);
            err_t.push(tn);
            q_errs.push(q_err);
        }
        if logged {
            log.push(LogRow {
                t_s: tn,
                ref_x_mm: rf[0] * 1e3,
                ref_y_mm: rf[1] * 1e3,
                ref_z_mm: rf[2] * 1e3,
                x_mm: tip[0] * 1e3,
                y_mm: tip[1] * 1e3,
                z_mm: tip[2] * 1e3,
                err_mm: err * 1e3,
                q_err_rad: q_err,
                cmd1_pa: cmd[0],
                cmd2_pa: cmd[1],
                cmd3_pa: cmd[2],
                p1_pa: p[0],
                p2_pa: p[1],
                p3_pa: p[2],
                hall1: sample.hall_codes[0],
                hall2: sample.hall_codes[1],
                hall3: sample.hall_codes[2],
                load_z_n: state.load.force_n[2],
            });
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let sim_s = steps as f64 * dt;
    let mut figures = BTreeMap::new();
    figures.insert("max_chamber_pa".into(), p_hi);
    figures.insert("min_chamber_pa".into(), p_lo);
    figures.insert("max_command_pa".into(), cmd_hi);
    figures.insert("min_command_pa".into(), cmd_lo);
    figures.insert("limit_violations".into(), violations as f64);
    match name {
        "orientation" => {
            figures.insert("q_rmse_rad".into(), rms(&q_errs));
            figures.insert(
                "q_max_rad".into(),
                q_errs.iter().cloned().fold(0.0, f64::max),
            );
        }
        "points" => points_figures(&su, &err_t, &errs, &mut figures),
        "disconnect" => {
            if let Some((_, a, b)) = su.cut {
                disconnect_figures(a, b, &err_t, &errs, &mut figures);
            }
        }
        "step_load" => {
            let samples: Vec<(f64, f64)> =
                err_t.iter().copied().zip(errs.iter().copied()).collect();
            let peak = errs.iter().cloned().fold(0.0, f64::max);
            // Back within 1 mm for good (the 5 % band of a step response
            // makes no sense when the reference does not move).
            let (_, settle) = step_times(&samples, 0.0, 1e-3);
            figures.insert("max_deviation_mm".into(), peak * 1e3);
            figures.insert(
                "final_error_mm".into(),
                errs.last().copied().unwrap_or(0.0) * 1e3,
            );
            // Never back: the whole observed window, flagged.
            let window = err_t.last().copied().unwrap_or(0.0) - su.score_from_s;
            figures.insert("recovery_s".into(), settle.unwrap_or(window));
            figures.insert("recovered".into(), if settle.is_some() { 1.0 } else { 0.0 });
        }
        _ => {}
    }
    Ok(RunReport {
        controller: mcu.name().to_string(),
        rmse_mm: rms(&errs) * 1e3,
        max_err_mm: errs.iter().cloned().fold(0.0, f64::max) * 1e3,
        figures,
        sim_s,
        realtime_factor: if wall > 0.0 {
            sim_s / wall
        } else {
            f64::INFINITY
        },
        log,
    })
}

/// The time of the last target update at or before `t`.
fn target_time(t: f64, period_s: f64) -> f64 {
    if period_s > 0.0 {
        // The small bias keeps t = k * period on update k despite rounding.
        (t / period_s + 1e-9).floor() * period_s
    } else {
        t
    }
}

fn points_figures(su: &Setup, t: &[f64], e: &[f64], out: &mut BTreeMap<String, f64>) {
    let Path::Points { targets_m, dwell_s } = &su.path else {
        return;
    };
    let (mut finals, mut rises, mut settles) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..targets_m.len() {
        let (a, b) = (k as f64 * dwell_s, (k + 1) as f64 * dwell_s);
        let window: Vec<(f64, f64)> = t
            .iter()
            .zip(e)
            .filter(|(ti, _)| **ti > a && **ti <= b)
            .map(|(ti, ei)| (*ti, *ei))
            .collect();
        let last: Vec<f64> = window
            .iter()
            .filter(|(ti, _)| *ti > b - 1.0)
            .map(|w| w.1)
            .collect();
        finals.push(mean(&last));
        if k > 0 {
            let (r, s) = step_times(&window, 0.05, 1e-3);
            rises.push(r.unwrap_or(*dwell_s));
            settles.push(s.unwrap_or(*dwell_s));
        }
    }
    out.insert("mean_final_error_mm".into(), mean(&finals) * 1e3);
    out.insert("rise_s".into(), mean(&rises));
    out.insert("settling_s".into(), mean(&settles));
}

fn disconnect_figures(a: f64, b: f64, t: &[f64], e: &[f64], out: &mut BTreeMap<String, f64>) {
    let before: Vec<f64> = t
        .iter()
        .zip(e)
        .filter(|(ti, _)| **ti < a)
        .map(|x| *x.1)
        .collect();
    let base = before.iter().cloned().fold(0.0, f64::max);
    let max_dev = t
        .iter()
        .zip(e)
        .filter(|(ti, _)| **ti >= a)
        .map(|x| *x.1)
        .fold(0.0, f64::max);
    let band = base + 2e-3;
    // Recovered when the error last leaves the band after the reconnect.
    let last_out = t
        .iter()
        .zip(e)
        .filter(|(ti, ei)| **ti >= b && **ei > band)
        .map(|x| *x.0)
        .fold(b, f64::max);
    out.insert("baseline_max_err_mm".into(), base * 1e3);
    out.insert("max_deviation_mm".into(), max_dev * 1e3);
    out.insert("recovery_s".into(), last_out - b);
    out.insert(
        "recovered".into(),
        if t.last().is_some_and(|&tl| last_out < tl - 1e-9) {
            1.0
        } else {
            0.0
        },
    );
}

/// The `rom` scenario: plant statics against the model's forward map for
/// every pressure combination.
fn rom(cfg: &SimConfig) -> Result<ScenarioReport, SimError> {
    let start = Instant::now();
    let plant = Plant::new(cfg.plant, cfg.seed)?;
    let model = plant.model();
    let load = PlateLoad::default();
    let tension = plant.external_force_n(&load)[2] / 3.0;
    let (p_lo, p_hi) = match cfg.rom_pressure_pa {
        Some(r) => r,
        None => {
            let p_of = |eps: f64| {
                let t = model.axial_terms(eps);
                (tension - t.bar_n - t.hinge_n) / t.pressure_n_per_pa
            };
            (p_of(-0.45), p_of(0.45))
        }
    };
    let n = cfg.rom_levels.max(2);
    let level = |k: usize| p_lo + (p_hi - p_lo) * k as f64 / (n - 1) as f64;
    let d = cfg.plant.manipulator.column_radius_m;
    let col = plant.column_rest_length_m();
    let (mut plant_pts, mut errs, mut q_errs, mut reduced) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut theta_max: f64 = 0.0;
    let mut failed = 0usize;
    let mut cloud = Vec::with_capacity(n * n * n);
    let lim = model.strain_limits();
    for a in 0..n {
        for b in 0..n {
            for c in 0..n {
                let p = [level(a), level(b), level(c)];
                // The model's forward map (eq 3.29, 3.33, 3.34 without moments, 3.26).
                let eps: Result<Vec<f64>, _> = p
                    .iter()
                    .map(|&pi| model.strain_for_force(tension, pi, (-0.95, 0.98 * lim.1)))
                    .collect();
                let Ok(eps) = eps else {
                    failed += 1;
                    continue;
                };
                let l = [0, 1, 2].map(|i| col * (1.0 + eps[i]));
                let predicted = Config::from_column_lengths(l, d);
                let Ok(actual) = plant.static_equilibrium(p, &load, predicted) else {
                    failed += 1;
                    continue;
                };
                let (x, xh) = (actual.position(), predicted.position());
                let e = distance(x, xh);
                errs.push(e);
                let qe = quaternion_error_rad(actual.quaternion(), predicted.quaternion());
                q_errs.push(qe);
                cloud.push(RomPoint {
                    p1_pa: p[0],
                    p2_pa: p[1],
                    p3_pa: p[2],
                    x_mm: x[0] * 1e3,
                    y_mm: x[1] * 1e3,
                    z_mm: x[2] * 1e3,
                    model_x_mm: xh[0] * 1e3,
                    model_y_mm: xh[1] * 1e3,
                    model_z_mm: xh[2] * 1e3,
                    err_mm: e * 1e3,
                    q_err_rad: qe,
                });
                theta_max = theta_max.max(actual.bend_rad());
                if x[0].abs() <= 0.05 && x[1].abs() <= 0.05 && (0.07..=0.14).contains(&x[2]) {
                    reduced.push(e);
                }
                plant_pts.push(x);
            }
        }
    }
    let l_max = workspace_diagonal(&plant_pts);
    let rmse = rms(&errs);
    let q_rmse = rms(&q_errs);
    let mut figures = BTreeMap::new();
    figures.insert("points".into(), errs.len() as f64);
    figures.insert("failed".into(), failed as f64);
    figures.insert("pressure_min_pa".into(), p_lo);
    figures.insert("pressure_max_pa".into(), p_hi);
    figures.insert("rmse_mm".into(), rmse * 1e3);
    figures.insert(
        "max_err_mm".into(),
        errs.iter().cloned().fold(0.0, f64::max) * 1e3,
    );
    figures.insert("l_max_mm".into(), l_max * 1e3);
    figures.insert(
        "rmse_pct_of_l_max".into(),
        if l_max > 0.0 {
            100.0 * rmse / l_max
        } else {
            0.0
        },
    );
    figures.insert("q_rmse_rad".into(), q_rmse);
    figures.insert("theta_max_rad".into(), theta_max);
    figures.insert(
        "q_rmse_pct_of_theta_max".into(),
        if theta_max > 0.0 {
            100.0 * q_rmse / theta_max
        } else {
            0.0
        },
    );
    figures.insert("reduced_points".into(), reduced.len() as f64);
    figures.insert("reduced_rmse_mm".into(), rms(&reduced) * 1e3);
    Ok(ScenarioReport {
        name: "rom".into(),
        seed: cfg.seed,
        ol_rmse_mm: None,
        cl_rmse_mm: None,
        oracle_rmse_mm: None,
        realtime_factor: 0.0,
        figures: {
            figures.insert("wall_s".into(), start.elapsed().as_secs_f64());
            figures
        },
        runs: Vec::new(),
        cloud,
    })
}
