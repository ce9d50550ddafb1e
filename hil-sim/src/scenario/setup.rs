//! The experiments: each scenario's reference path, duration, loads and
//! faults.
//!
//! The paths sit around the middle of the workspace the command limits
//! reach, [`mid_backbone_m`]: the dissertation's z = -100 mm plane is a
//! place on its rig, and the plant reaches other lengths under other
//! parameter sets (calibrated: about 155 mm; Table 3.1 with vacuum: about
//! 120 mm, where the lab's paths were first laid out 20 mm lower).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use ocm_lutgen::OcmModel;

use crate::SimError;
use crate::pcc::Config;
use crate::plant::PlateLoad;
use crate::reference::Path;

use super::SimConfig;

/// A time-varying experiment.
#[derive(Debug, Clone)]
pub(super) struct Setup {
    pub(super) path: Path,
    pub(super) duration_s: f64,
    pub(super) score_from_s: f64,
    pub(super) payload_kg: f64,
    /// Tip force along gravity: from `(t0, f0)` to `(t1, f1)` linearly.
    pub(super) force_ramp: Option<(f64, f64, f64, f64)>,
    /// Chamber cut: `(chamber, from, to)`.
    pub(super) cut: Option<(usize, f64, f64)>,
    /// Payload added at this time, kilograms: `(time, mass)`.
    pub(super) payload_step: Option<(f64, f64)>,
    /// Whether the operator announces the load to the controller (the
    /// experiment's own payload and force, as in the dissertation); an
    /// unannounced load is a disturbance the feedback must reject.
    pub(super) announced: bool,
}

impl Setup {
    pub(super) fn load_at(&self, t: f64, cfg: &SimConfig) -> PlateLoad {
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

pub(super) fn setup(name: &str, cfg: &SimConfig) -> Result<Setup, SimError> {
    let laps = if cfg.short { 1.0 } else { 2.0 };
    let settle = 3.0;
    let mid = mid_backbone_m(cfg)?;
    // The circle's columns swing +-26 mm about the plane: around the middle
    // they stay inside the reachable lengths.
    let z = mid;
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
                        rng.random_range(mid - 0.012..mid + 0.012),
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
                path: Path::Hold(Config::from_polar(mid + 0.010, 0.30, 0.0)),
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
            path: Path::Hold(Config::from_polar(mid + 0.010, 0.20, 0.5)),
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

/// Backbone length of the straight, unloaded segment halfway between the
/// strains the command limits hold it at (each within the characterised
/// -0.6..0.6), metres: the middle of the reachable workspace.
pub(crate) fn mid_backbone_m(cfg: &SimConfig) -> Result<f64, SimError> {
    const EDGE: f64 = 0.6;
    let plant = &cfg.plant;
    let model = OcmModel::new(plant.ocm).map_err(|e| SimError::Config(e.to_string()))?;
    let tension = plant.external_force_n(&PlateLoad::default())[2] / 3.0;
    let strain_at = |p: f64| {
        if tension <= model.axial_force_n(-EDGE, p) {
            Ok(-EDGE)
        } else if tension >= model.axial_force_n(EDGE, p) {
            Ok(EDGE)
        } else {
            model
                .strain_for_force(tension, p, (-EDGE, EDGE))
                .map_err(|e| SimError::Config(format!("no column strain at {p} Pa: {e}")))
        }
    };
    let e = 0.5 * (strain_at(cfg.limits.min_pa)? + strain_at(cfg.limits.max_pa)?);
    let column = f64::from(plant.manipulator.ocms_per_column) * plant.ocm.rest_length_m;
    Ok(column * (1.0 + e))
}
