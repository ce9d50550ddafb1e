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
//!
//! The room plan: [`config`] holds the run settings, [`setup`] the
//! experiments' paths and loads, [`simulate`] the time-domain loop,
//! [`figures`] the scenario-specific scores, [`rom`] the static sweep and
//! [`report`] what comes back.

mod config;
mod figures;
mod report;
mod rom;
mod setup;
mod simulate;

pub use config::{ControllerKind, LAB_GAINS, SimConfig, working_limits};
pub use report::{LogRow, RomPoint, RunReport, ScenarioReport};
pub use simulate::run_with_mcu;

use std::collections::BTreeMap;

use crate::SimError;
use crate::mcu::{HostPid, Mcu, OpenLoop, Oracle};
use crate::plant::Plant;

use rom::rom;
use simulate::simulate;

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
