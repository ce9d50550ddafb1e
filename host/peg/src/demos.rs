//! Expert demonstrations (eq 6.18): per control step the proprioception s_t, the tactile
//! latents z_t and the expert's action a*_t, over M successful trials.

use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::encoder::TactileEncoder;
use crate::error::{PegError, Result};
use crate::expert::ExpertConfig;
use crate::rollout::{Outcome, obs_dim, run_trial};
use crate::scene::{N_ACTION, N_PROPRIO, SceneConfig};
use crate::trial::Randomisation;

/// Standard deviations of the noise added to the executed expert action (the recorded label
/// stays clean, so the data covers states just off the expert's path).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActionNoise {
    /// Noise on each velocity component, m/s.
    pub speed_m_s: f64,
    /// Noise on the roll rate, rad/s.
    pub rate_rad_s: f64,
}

impl Default for ActionNoise {
    fn default() -> Self {
        Self {
            speed_m_s: 0.003,
            rate_rad_s: 0.03,
        }
    }
}

/// How demonstrations were made (stored in the manifest).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DemoSettings {
    /// Successful demonstrations wanted.
    pub count: usize,
    /// Seed of the trials (the noise uses the same seed on another stream).
    pub seed: u64,
    /// The scene.
    pub scene: SceneConfig,
    /// The randomisation of the trials.
    pub randomisation: Randomisation,
    /// The expert.
    pub expert: ExpertConfig,
    /// Execution noise.
    pub noise: ActionNoise,
}

/// A set of demonstrations: row-major observations and actions, one row per control step.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoSet {
    /// How they were made.
    pub settings: DemoSettings,
    /// Encoder of the latents.
    pub encoder: String,
    /// Latent values per sensor.
    pub latent_dim: usize,
    /// Observations `[s, z_left, z_right]`, rows of [`obs_dim`].
    pub obs: Vec<f64>,
    /// Expert actions, rows of 4.
    pub actions: Vec<f64>,
    /// Demonstration index of each row.
    pub episode: Vec<usize>,
    /// Every trial run (successful or not), in order.
    pub outcomes: Vec<Outcome>,
    /// Gripper path of each kept demonstration: rows `[time_s, x_m, y_m, z_m, roll_rad]`.
    pub paths: Vec<Vec<[f64; 5]>>,
}

#[derive(Serialize, Deserialize)]
struct Manifest {
    settings: DemoSettings,
    encoder: String,
    latent_dim: usize,
    rows: usize,
    obs_columns: Vec<String>,
    action_columns: Vec<String>,
    files: serde_json::Value,
    outcomes: Vec<Outcome>,
}

fn obs_columns(latent_dim: usize) -> Vec<String> {
    let mut c: Vec<String> = ["x_m", "y_m", "z_m", "roll_rad"].map(String::from).to_vec();
    for side in ["left", "right"] {
        for i in 0..latent_dim {
            c.push(format!("z_{side}_{i}"));
        }
    }
    c
}

impl DemoSet {
    /// Runs the expert on trials `0, 1, ...` of `settings.seed` until `settings.count` have
    /// succeeded (at most twice as many trials); only successful ones are kept.
    /// `progress(kept)` is called after each trial.
    pub fn collect(
        settings: &DemoSettings,
        encoder: &dyn TactileEncoder,
        progress: &mut dyn FnMut(usize),
    ) -> Result<Self> {
        settings.scene.validate()?;
        settings.randomisation.validate()?;
        settings.expert.validate()?;
        let n = settings.noise;
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        if !(ok(n.speed_m_s) && ok(n.rate_rad_s)) {
            return Err(PegError::Invalid(format!(
                "action noise {n:?} must be finite and not negative"
            )));
        }
        if settings.count == 0 {
            return Err(PegError::Invalid(
                "demonstration count must be positive".into(),
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
        rng.set_stream(u64::MAX);
        let sv = Normal::new(0.0, n.speed_m_s).map_err(|e| PegError::Invalid(e.to_string()))?;
        let sw = Normal::new(0.0, n.rate_rad_s).map_err(|e| PegError::Invalid(e.to_string()))?;
        let mut set = DemoSet {
            settings: settings.clone(),
            encoder: encoder.name().to_string(),
            latent_dim: encoder.dim(),
            obs: Vec::new(),
            actions: Vec::new(),
            episode: Vec::new(),
            outcomes: Vec::new(),
            paths: Vec::new(),
        };
        let mut kept = 0;
        for index in 0..(2 * settings.count) as u64 {
            if kept == settings.count {
                break;
            }
            let trial = settings
                .randomisation
                .trial(&settings.scene, settings.seed, index);
            let expert = &settings.expert;
            let (outcome, steps, path) = run_trial(
                &settings.scene,
                &trial,
                encoder,
                &mut |scene, _| Ok(expert.act(scene)),
                &mut || {
                    [
                        sv.sample(&mut rng),
                        sv.sample(&mut rng),
                        sv.sample(&mut rng),
                        sw.sample(&mut rng),
                    ]
                },
            )?;
            set.outcomes.push(outcome);
            if outcome.success {
                for s in steps {
                    set.obs.extend(&s.obs);
                    set.actions.extend(s.action);
                    set.episode.push(kept);
                }
                set.paths.push(path);
                kept += 1;
            }
            progress(kept);
        }
        Ok(set)
    }

    /// Rows (control steps).
    pub fn rows(&self) -> usize {
        self.episode.len()
    }

    /// Observation width.
    pub fn obs_dim(&self) -> usize {
        obs_dim(self.latent_dim)
    }

    /// Demonstrations kept.
    pub fn demos(&self) -> usize {
        self.paths.len()
    }

    /// Writes `obs.npy`, `actions.npy`, `episodes.npy`, `demos.json` and one
    /// `paths/demo_NNN.csv` per demonstration into `dir`.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let io = |p: &Path, e: &dyn std::fmt::Display| PegError::file(p, e);
        std::fs::create_dir_all(dir.join("paths")).map_err(|e| io(dir, &e))?;
        let rows = self.rows();
        let npy = |name: &str, data: &[f64], cols: usize| -> Result<()> {
            let p = dir.join(name);
            ocm_fem::npy::write_f64_2d_path(&p, data, rows, cols).map_err(|e| io(&p, &e))
        };
        npy("obs.npy", &self.obs, self.obs_dim())?;
        npy("actions.npy", &self.actions, N_ACTION)?;
        let ep: Vec<f64> = self.episode.iter().map(|&e| e as f64).collect();
        npy("episodes.npy", &ep, 1)?;
        for (i, path) in self.paths.iter().enumerate() {
            crate::replay::write_path(&dir.join(format!("paths/demo_{i:03}.csv")), path)?;
        }
        let manifest = Manifest {
            settings: self.settings.clone(),
            encoder: self.encoder.clone(),
            latent_dim: self.latent_dim,
            rows,
            obs_columns: obs_columns(self.latent_dim),
            action_columns: ["vx_m_s", "vy_m_s", "vz_m_s", "roll_rate_rad_s"]
                .map(String::from)
                .to_vec(),
            files: serde_json::json!({
                "obs.npy": "float64 (rows, obs_columns): proprioception (m, rad) in the hole frame, then the latents of the left and right sensor",
                "actions.npy": "float64 (rows, 4): the expert's gripper velocity (m/s, rad/s), without the execution noise",
                "episodes.npy": "float64 (rows, 1): demonstration index",
                "paths/demo_NNN.csv": "gripper path of each demonstration (replay input)",
            }),
            outcomes: self.outcomes.clone(),
        };
        let p = dir.join("demos.json");
        let text = serde_json::to_string_pretty(&manifest).map_err(|e| io(&p, &e))?;
        std::fs::write(&p, text).map_err(|e| io(&p, &e))
    }

    /// Reads a set written by [`DemoSet::save`]; shapes are checked against the manifest.
    pub fn load(dir: &Path) -> Result<Self> {
        let p = dir.join("demos.json");
        let text = std::fs::read_to_string(&p).map_err(|e| PegError::file(&p, e))?;
        let m: Manifest = serde_json::from_str(&text).map_err(|e| PegError::file(&p, e))?;
        let read = |name: &str, cols: usize| -> Result<Vec<f64>> {
            let path = dir.join(name);
            let a = ocm_fem::npy::read_f64_2d(&path).map_err(|e| PegError::file(&path, e))?;
            if a.rows != m.rows || a.cols != cols {
                return Err(PegError::file(
                    &path,
                    format!(
                        "shape ({}, {}) but the manifest says ({}, {cols})",
                        a.rows, a.cols, m.rows
                    ),
                ));
            }
            if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
                return Err(PegError::file(
                    &path,
                    format!(
                        "value at row {}, column {} is not finite",
                        i / cols,
                        i % cols
                    ),
                ));
            }
            Ok(a.data)
        };
        let obs = read("obs.npy", obs_dim(m.latent_dim))?;
        let actions = read("actions.npy", N_ACTION)?;
        // ids count the kept demonstrations, so each is an integer below the number of
        // demonstrations run (a stray id would size the set by itself)
        let ids = read("episodes.npy", 1)?;
        if let Some(i) = ids
            .iter()
            .position(|&v| v < 0.0 || v.fract() != 0.0 || v >= m.outcomes.len() as f64)
        {
            let path = dir.join("episodes.npy");
            return Err(PegError::file(
                &path,
                format!(
                    "row {i}: episode id {} is not an integer in [0, {}) (the demonstrations run)",
                    ids[i],
                    m.outcomes.len()
                ),
            ));
        }
        let episode: Vec<usize> = ids.into_iter().map(|v| v as usize).collect();
        let demos = episode.iter().max().map_or(0, |e| e + 1);
        Ok(DemoSet {
            settings: m.settings,
            encoder: m.encoder,
            latent_dim: m.latent_dim,
            obs,
            actions,
            episode,
            outcomes: m.outcomes,
            paths: vec![Vec::new(); demos],
        })
    }

    /// The observation columns a policy uses: all, or proprioception only.
    pub fn inputs(&self, touch: bool) -> (Vec<f64>, usize) {
        if touch {
            return (self.obs.clone(), self.obs_dim());
        }
        let d = self.obs_dim();
        let v = self
            .obs
            .chunks_exact(d)
            .flat_map(|r| r[..N_PROPRIO].iter().copied())
            .collect();
        (v, N_PROPRIO)
    }
}
