//! The stored surrogate: geometry, limits, the actuation map and its fit report, built from FEM
//! samples in one call and saved as JSON beside the URDF.

use crate::chain::{JointKind, KINDS, N_JOINTS, Posture};
use crate::constraints::Limits;
use crate::fem_samples::{FemSample, FemSamples};
use crate::force::ForceCalibration;
use crate::geometry::{Geometry, measure};
use crate::mapping::{ActuationMap, Match, MatchConfig, match_samples};
use crate::{Result, SurrogateError};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Format tag of the model file.
pub const FORMAT: &str = "ocm-surrogate-model/1";

/// Jig forces of both models per calibration pressure.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceSamples {
    /// Chamber pressures, kPa: the fit set, then the held-out set.
    pub pressures_kpa: Vec<[f64; 3]>,
    /// Force of the surrogate on the jig, N.
    pub surrogate_n: Vec<[f64; 3]>,
    /// Force of the FEM on the jig, N.
    pub fem_n: Vec<[f64; 3]>,
    /// How many leading entries form the fit set.
    pub fit: usize,
}

/// Errors of the mapping over a set of samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct MapErrors {
    /// Samples.
    pub samples: usize,
    /// RMSE of the surrogate TCP (Algorithm 1 postures) against the FEM TCP, m.
    pub optimised_tcp_rmse_m: f64,
    /// RMSE of the surrogate TCP at f_SP(P) against the FEM TCP, m.
    pub mapped_tcp_rmse_m: f64,
    /// Largest TCP error at f_SP(P), m.
    pub mapped_tcp_max_m: f64,
    /// Mean absolute error of f_SP's rotations against the optimised ones, rad.
    pub rotation_mae_rad: f64,
    /// Mean absolute error of f_SP's extensions against the optimised ones, m.
    pub extension_mae_m: f64,
    /// RMSE of inverse(f_SP(P)) against P, kPa.
    pub inverse_rmse_kpa: f64,
}

/// The surrogate model.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SurrogateModel {
    /// [`FORMAT`].
    pub format: String,
    /// Geometry measured on the FEM samples (with the chain).
    pub geometry: Geometry,
    /// Joint limits and grouped constraints.
    pub limits: Limits,
    /// Algorithm 1 settings used.
    pub match_config: MatchConfig,
    /// f_SP and its inverse.
    pub map: ActuationMap,
    /// Optimised postures of the training samples.
    pub training_postures: Vec<Posture>,
    /// Errors on the training samples.
    pub training: MapErrors,
    /// Errors on the held-out samples.
    pub held_out: MapErrors,
    /// Force calibration (surrogate TCP force to FEM TCP force on the jig), once measured.
    #[serde(default)]
    pub force_calibration: Option<ForceCalibration>,
}

/// Evaluates the map on samples, given their Algorithm 1 postures.
pub fn map_errors(
    model_geometry: &Geometry,
    map: &ActuationMap,
    samples: &[FemSample],
    optimised: &[Match],
) -> Result<MapErrors> {
    let chain = &model_geometry.chain;
    let (mut so, mut sm, mut mx, mut rot, mut ext, mut inv) = (0.0, 0.0, 0.0f64, 0.0, 0.0, 0.0);
    let (mut nr, mut ne) = (0usize, 0usize);
    for (s, m) in samples.iter().zip(optimised) {
        let target = Vector3::from(s.tcp_m);
        so += m.error_m.powi(2);
        let q = map.posture(&s.pressures_kpa)?;
        let e = (chain.tcp(&q) - target).norm();
        sm += e * e;
        mx = mx.max(e);
        for j in 0..N_JOINTS {
            let d = (q[j] - m.posture[j]).abs();
            if KINDS[j] == JointKind::Prismatic {
                ext += d;
                ne += 1;
            } else {
                rot += d;
                nr += 1;
            }
        }
        let p = map.pressures(&q)?;
        inv += (0..3)
            .map(|k| (p[k] - s.pressures_kpa[k]).powi(2))
            .sum::<f64>()
            / 3.0;
    }
    let n = samples.len().max(1) as f64;
    Ok(MapErrors {
        samples: samples.len(),
        optimised_tcp_rmse_m: (so / n).sqrt(),
        mapped_tcp_rmse_m: (sm / n).sqrt(),
        mapped_tcp_max_m: mx,
        rotation_mae_rad: rot / nr.max(1) as f64,
        extension_mae_m: ext / ne.max(1) as f64,
        inverse_rmse_kpa: (inv / n).sqrt(),
    })
}

impl SurrogateModel {
    /// Measures the geometry, runs Algorithm 1 on every training and held-out sample, fits f_SP
    /// and its inverse on the training samples and scores both sets. `on_sample` counts
    /// optimised samples (progress bars).
    pub fn build(
        samples: &FemSamples,
        limits: Limits,
        cfg: MatchConfig,
        mut on_sample: impl FnMut(usize),
    ) -> Result<Self> {
        limits.validate()?;
        let geometry = measure(samples)?;
        let chain = geometry.chain;
        let mut count = 0;
        let train = match_samples(&chain, &limits, &samples.samples, &cfg, |_| {
            count += 1;
            on_sample(count)
        })?;
        let held = match_samples(&chain, &limits, &samples.held_out, &cfg, |_| {
            count += 1;
            on_sample(count)
        })?;
        let map = ActuationMap::fit(&samples.samples, &train, &limits)?;
        let training = map_errors(&geometry, &map, &samples.samples, &train)?;
        let held_out = map_errors(&geometry, &map, &samples.held_out, &held)?;
        Ok(SurrogateModel {
            format: FORMAT.into(),
            geometry,
            limits,
            match_config: cfg,
            map,
            training_postures: train.iter().map(|m| m.posture).collect(),
            training,
            held_out,
            force_calibration: None,
        })
    }

    /// Calibration pressures over the whole actuation range -20..35 kPa: the eight corners of
    /// the pressure box followed by `n` seeded uniformly random triples.
    pub fn calibration_pressures(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let [lo, hi] = crate::fem_samples::PRESSURE_RANGE_KPA;
        let corners =
            (0..8).map(|c: usize| [0, 1, 2].map(|k| if c >> k & 1 == 1 { hi } else { lo }));
        corners
            .chain(crate::fem_samples::random_pressures(n, seed))
            .collect()
    }

    /// Measures both models on the jig (top plate clamped at the FEM's rest pose) at the fit and
    /// held-out pressure triples (kPa), stores the component-wise linear fit over the fit set
    /// with its RMSE and R^2 there, its RMSE on the held-out set and, over both sets, its RMSE
    /// inside each of [`crate::force::REPORT_RANGES_KPA`]. The surrogate uses the motor
    /// stiffness of `scene`, the posture f_SP(P) and is held as `hold` says
    /// ([`crate::force::JigHold::TcpPinned`] is the calibration's choice, see the README);
    /// `on_sample` counts finished pressures.
    pub fn calibrate_force(
        &mut self,
        b: &ocm_fem::bellows::Bellows,
        fit_kpa: &[[f64; 3]],
        held_out_kpa: &[[f64; 3]],
        scene: &crate::sim::SceneConfig,
        hold: crate::force::JigHold,
        mut on_sample: impl FnMut(usize),
    ) -> Result<ForceSamples> {
        let rest = ocm_fem::model::State::at_rest(&b.model);
        // One jig in space for both: the FEM's TCP at rest (the chain shares the mesh frame).
        let x0 = Vector3::from(b.state_of(&rest).tcp_m);
        let chain = self.geometry.chain;
        let k: Posture = std::array::from_fn(|j| match KINDS[j] {
            JointKind::Prismatic => scene.prismatic_stiffness,
            _ => scene.revolute_stiffness,
        });
        let all: Vec<[f64; 3]> = fit_kpa.iter().chain(held_out_kpa).copied().collect();
        let mut sur = Vec::with_capacity(all.len());
        for p in &all {
            let q = self.map.posture(p)?;
            let (_, fs) = crate::force::surrogate_jig_held(&chain, &k, &q, &x0, hold)?;
            sur.push([fs.x, fs.y, fs.z]);
        }
        let fem: Vec<[f64; 3]> = crate::force::fem_clamped_jig_forces(b, &all, &mut on_sample)?
            .iter()
            .map(|f| [f.x, f.y, f.z])
            .collect();
        let nf = fit_kpa.len();
        let mut cal = ForceCalibration::fit(&sur[..nf], &fem[..nf])?;
        cal.set_held_out(&sur[nf..], &fem[nf..]);
        cal.set_range_errors(&all, &sur, &fem, nf, &crate::force::REPORT_RANGES_KPA);
        cal.surrogate_hold = hold;
        self.force_calibration = Some(cal);
        Ok(ForceSamples {
            pressures_kpa: all,
            surrogate_n: sur,
            fem_n: fem,
            fit: nf,
        })
    }

    /// Writes the model as JSON.
    pub fn write(&self, path: &std::path::Path) -> Result<()> {
        crate::json::write(path, self, "model")
    }

    /// Reads a model file and checks its format tag and limits.
    pub fn read(path: &std::path::Path) -> Result<Self> {
        let name = path.display().to_string();
        let m: SurrogateModel = crate::json::read(path)?;
        if m.format != FORMAT {
            return Err(SurrogateError::parse(
                &name,
                "format",
                format!("expected {FORMAT}, found {}", m.format),
            ));
        }
        m.limits.validate()?;
        m.geometry
            .chain
            .validate()
            .map_err(|e| SurrogateError::parse(&name, "geometry.chain", e.to_string()))?;
        Ok(m)
    }
}
