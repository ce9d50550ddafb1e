//! Python binding of `ocm-rl`: the native module `ocm_rl._native` under the pure-Python package
//! `ocm_rl` (python/ocm_rl), which wraps these classes as a `gymnasium.Env` and a
//! `gymnasium.vector.VectorEnv`.
//!
//! The classes speak plain lists of floats and dicts; the Python side turns them into NumPy
//! arrays and Gymnasium spaces. Every error of `ocm-rl` becomes a Python exception carrying the
//! Rust message: `ValueError` for bad input (NaN actions, unknown tasks, stepping a finished
//! episode, a malformed model file), `OSError` (`FileNotFoundError`, `PermissionError`) when a
//! file cannot be read. The physics runs with the interpreter released, so other
//! Python threads keep going while an environment steps.

use ocm_rl::RlError;
use ocm_rl::env::{Env, EnvConfig, PHYSICS_DT_S, StepInfo};
use ocm_rl::robot::Robot;
use ocm_rl::tasks::{POINTS, TaskKind};
use ocm_rl::vec_env::VecEnv;
use ocm_surrogate::SurrogateError;
use ocm_surrogate::chain::ChainGeometry;
use ocm_surrogate::constraints::Limits;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyPermissionError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Arc;

fn py_err(e: RlError) -> PyErr {
    let io_kind = match &e {
        RlError::Io { source, .. } | RlError::Surrogate(SurrogateError::Io { source, .. }) => {
            Some(source.kind())
        }
        _ => None,
    };
    let msg = e.to_string();
    match io_kind {
        Some(std::io::ErrorKind::NotFound) => PyFileNotFoundError::new_err(msg),
        Some(std::io::ErrorKind::PermissionDenied) => PyPermissionError::new_err(msg),
        Some(_) => PyOSError::new_err(msg),
        None => PyValueError::new_err(msg),
    }
}

/// The robot of a stored surrogate model, or of a chain given as JSON with the default limits.
fn robot_of(model: Option<PathBuf>, chain: Option<&str>) -> PyResult<Arc<Robot>> {
    let robot = match (model, chain) {
        (Some(path), None) => Robot::read(&path, PHYSICS_DT_S).map_err(py_err)?,
        (None, Some(json)) => {
            let chain = chain_of_json(json)?;
            Robot::new(&chain, &Limits::default(), PHYSICS_DT_S).map_err(py_err)?
        }
        _ => {
            return Err(PyValueError::new_err(
                "give exactly one of `model` (the surrogate.json of `ocm surrogate map`) or \
                 `chain` (the chain geometry as a dict or JSON)",
            ));
        }
    };
    Ok(Arc::new(robot))
}

/// Parses a chain geometry and refuses values that are not finite and positive (the dynamics
/// would go NaN far from the cause).
fn chain_of_json(json: &str) -> PyResult<ChainGeometry> {
    let chain: ChainGeometry = serde_json::from_str(json)
        .map_err(|e| PyValueError::new_err(format!("chain geometry: {e}")))?;
    let value = serde_json::to_value(chain)
        .map_err(|e| PyValueError::new_err(format!("chain geometry: {e}")))?;
    if let Some(fields) = value.as_object() {
        for (name, v) in fields {
            let x = v.as_f64().unwrap_or(f64::NAN);
            if !(x.is_finite() && x > 0.0) {
                return Err(PyValueError::new_err(format!(
                    "chain geometry: {name} = {v} must be finite and positive"
                )));
            }
        }
    }
    Ok(chain)
}

/// The defaults of `task`, with the given settings replaced (`Env::new` validates them).
fn config_of(
    task: &str,
    substeps: Option<usize>,
    init_noise: Option<f64>,
    lost_distance_m: Option<f64>,
) -> PyResult<EnvConfig> {
    let kind = TaskKind::from_name(task).ok_or_else(|| {
        let names: Vec<&str> = TaskKind::ALL.iter().map(|t| t.name()).collect();
        PyValueError::new_err(format!(
            "unknown task '{task}' (one of {})",
            names.join(", ")
        ))
    })?;
    let mut config = EnvConfig::new(kind);
    if let Some(s) = substeps {
        config.substeps = s;
    }
    if let Some(n) = init_noise {
        config.init_noise = n;
    }
    if let Some(d) = lost_distance_m {
        config.lost_distance_m = d;
    }
    Ok(config)
}

fn info_dict<'py>(py: Python<'py>, info: &StepInfo) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("point", info.point)?;
    d.set_item("tcp_m", info.tcp_m.to_vec())?;
    d.set_item("target_m", info.target_m.to_vec())?;
    d.set_item("position_error_m", info.position_error_m)?;
    d.set_item("force_n", info.force_n.to_vec())?;
    d.set_item("force_target_n", info.force_target_n.to_vec())?;
    d.set_item("force_error_n", info.force_error_n)?;
    d.set_item("clipped", info.clipped)?;
    Ok(d)
}

/// One environment of `ocm-rl` (observations and actions as lists of floats).
#[pyclass(name = "Env", module = "ocm_rl._native")]
struct PyEnv {
    inner: Env,
}

/// What `Env.step` returns: observation, reward, terminated, truncated, info.
type StepTuple<'py> = (Vec<f64>, f64, bool, bool, Bound<'py, PyDict>);

#[pymethods]
impl PyEnv {
    /// An environment of `task` on the robot of `model` (a surrogate.json) or `chain` (JSON).
    #[new]
    #[pyo3(signature = (task, model=None, chain=None, substeps=None, init_noise=None, lost_distance_m=None))]
    fn new(
        task: &str,
        model: Option<PathBuf>,
        chain: Option<&str>,
        substeps: Option<usize>,
        init_noise: Option<f64>,
        lost_distance_m: Option<f64>,
    ) -> PyResult<Self> {
        let config = config_of(task, substeps, init_noise, lost_distance_m)?;
        let robot = robot_of(model, chain)?;
        Ok(PyEnv {
            inner: Env::new(robot, config).map_err(py_err)?,
        })
    }

    /// Starts the episode of `seed`; returns the observation.
    fn reset(&mut self, py: Python<'_>, seed: u64) -> PyResult<Vec<f64>> {
        let env = &mut self.inner;
        py.detach(|| env.reset(seed)).map_err(py_err)
    }

    /// Applies an action for one control period.
    fn step<'py>(&mut self, py: Python<'py>, action: Vec<f64>) -> PyResult<StepTuple<'py>> {
        let env = &mut self.inner;
        let s = py.detach(|| env.step(&action)).map_err(py_err)?;
        let info = info_dict(py, &s.info)?;
        Ok((s.obs, s.reward, s.terminated, s.truncated, info))
    }

    /// The expert's action (eq 4.31) for the next target.
    fn expert_action(&mut self, py: Python<'_>) -> PyResult<[f64; 3]> {
        let env = &mut self.inner;
        py.detach(|| env.expert_action()).map_err(py_err)
    }

    /// The observation of the current state (zeros before the first reset).
    fn observation(&self) -> Vec<f64> {
        self.inner.observation()
    }

    /// Observation length.
    #[getter]
    fn observation_size(&self) -> usize {
        self.inner.observation_size()
    }

    /// Action length.
    #[getter]
    fn action_size(&self) -> usize {
        self.inner.action_size()
    }

    /// Bounds of every action value.
    #[getter]
    fn action_bounds(&self) -> (f64, f64) {
        self.inner.action_bounds()
    }

    /// Bounds of every observation value.
    #[getter]
    fn observation_bounds(&self) -> (f64, f64) {
        self.inner.observation_bounds()
    }

    /// Control period, s.
    #[getter]
    fn control_period_s(&self) -> f64 {
        self.inner.control_period_s()
    }

    /// Steps of a full episode (one per target point).
    #[getter]
    fn max_episode_steps(&self) -> usize {
        POINTS
    }

    /// The task's name.
    #[getter]
    fn task(&self) -> &'static str {
        self.inner.config().task.name()
    }

    /// Grouped joint command (rad, rad, m) of a normalised action.
    fn command_of_action(&self, action: [f64; 3]) -> [f64; 3] {
        self.inner.command_of_action(&action)
    }
}

/// What `VecEnv.step` returns: observations, rewards, terminated, truncated, final
/// observations, infos.
type VecStepTuple<'py> = (
    Vec<f64>,
    Vec<f64>,
    Vec<bool>,
    Vec<bool>,
    Vec<Option<Vec<f64>>>,
    Vec<Bound<'py, PyDict>>,
);

/// `n` environments stepped together on a thread pool with same-step autoreset (flat row-major
/// lists: `n x 3` actions, `n x 40` observations).
#[pyclass(name = "VecEnv", module = "ocm_rl._native")]
struct PyVecEnv {
    inner: VecEnv,
}

#[pymethods]
impl PyVecEnv {
    /// `n` environments of `task` on `threads` threads.
    #[new]
    #[pyo3(signature = (task, n, threads=1, model=None, chain=None, substeps=None, init_noise=None, lost_distance_m=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        task: &str,
        n: usize,
        threads: usize,
        model: Option<PathBuf>,
        chain: Option<&str>,
        substeps: Option<usize>,
        init_noise: Option<f64>,
        lost_distance_m: Option<f64>,
    ) -> PyResult<Self> {
        let config = config_of(task, substeps, init_noise, lost_distance_m)?;
        let robot = robot_of(model, chain)?;
        Ok(PyVecEnv {
            inner: VecEnv::new(robot, config, n, threads).map_err(py_err)?,
        })
    }

    /// Resets every environment (environment i gets `seed + i`); flat observations.
    fn reset(&mut self, py: Python<'_>, seed: u64) -> PyResult<Vec<f64>> {
        let env = &mut self.inner;
        py.detach(|| env.reset(seed)).map_err(py_err)
    }

    /// Steps every environment with its row of the flat `actions`.
    fn step<'py>(&mut self, py: Python<'py>, actions: Vec<f64>) -> PyResult<VecStepTuple<'py>> {
        let env = &mut self.inner;
        let s = py.detach(|| env.step(&actions)).map_err(py_err)?;
        let infos = s
            .infos
            .iter()
            .map(|i| info_dict(py, i))
            .collect::<PyResult<Vec<_>>>()?;
        Ok((
            s.obs,
            s.rewards,
            s.terminated,
            s.truncated,
            s.final_obs,
            infos,
        ))
    }

    /// The expert's actions for every environment, flat `n x 3`.
    fn expert_actions(&mut self, py: Python<'_>) -> PyResult<Vec<f64>> {
        let env = &mut self.inner;
        let actions = py
            .detach(|| {
                env.envs_mut()
                    .iter_mut()
                    .map(|e| e.expert_action())
                    .collect::<ocm_rl::Result<Vec<_>>>()
            })
            .map_err(py_err)?;
        Ok(actions.concat())
    }

    /// Number of environments.
    #[getter]
    fn num_envs(&self) -> usize {
        self.inner.len()
    }
}

/// The native module.
#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEnv>()?;
    m.add_class::<PyVecEnv>()?;
    let tasks: Vec<&str> = TaskKind::ALL.iter().map(|t| t.name()).collect();
    m.add("TASKS", tasks)?;
    m.add("OBS_DIM", ocm_rl::env::OBS_DIM)?;
    m.add("ACT_DIM", ocm_rl::env::ACT_DIM)?;
    Ok(())
}
