//! Sampled trajectories of the manipulator: inputs and the compact state X_S with its rate.

use crate::error::{DynamicsError, Result};

/// Chamber pressures per step.
pub const PRESSURE_DIM: usize = 3;
/// Components of the tip force per step.
pub const FORCE_DIM: usize = 3;

/// One trajectory on a uniform time grid, every array row-major with one row per step.
///
/// Step `t` holds the inputs applied from `t` to `t + 1` (zero-order hold) and the state at `t`.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Time step, s.
    pub dt_s: f64,
    /// Components of X_S.
    pub state_dim: usize,
    /// Chamber pressures, kPa (`n x 3`).
    pub pressure_kpa: Vec<f64>,
    /// Tip force in the base frame, N (`n x 3`).
    pub force_n: Vec<f64>,
    /// X_S (`n x state_dim`), SI units (the first three components are the TCP position, m).
    pub state: Vec<f64>,
    /// dX_S/dt (`n x state_dim`), SI units per second.
    pub velocity: Vec<f64>,
}

impl Trajectory {
    /// Number of steps.
    pub fn len(&self) -> usize {
        self.pressure_kpa.len() / PRESSURE_DIM
    }

    /// Whether the trajectory has no step.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Checks sizes, the time step and that every value is finite.
    pub fn validate(&self) -> Result<()> {
        let n = self.len();
        let bad = |m: String| Err(DynamicsError::Data(m));
        if !(self.dt_s.is_finite() && self.dt_s > 0.0) {
            return bad(format!("time step {} s must be positive", self.dt_s));
        }
        if self.state_dim == 0 {
            return bad("state dimension is zero".into());
        }
        let sizes = [
            ("pressure_kpa", self.pressure_kpa.len(), n * PRESSURE_DIM),
            ("force_n", self.force_n.len(), n * FORCE_DIM),
            ("state", self.state.len(), n * self.state_dim),
            ("velocity", self.velocity.len(), n * self.state_dim),
        ];
        for (name, got, want) in sizes {
            if got != want {
                return bad(format!(
                    "{name} has {got} values, expected {want} ({n} steps)"
                ));
            }
        }
        for (name, v) in [
            ("pressure_kpa", &self.pressure_kpa),
            ("force_n", &self.force_n),
            ("state", &self.state),
            ("velocity", &self.velocity),
        ] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                let cols = v.len() / n.max(1);
                return bad(format!(
                    "{name} step {} column {} is not finite",
                    i / cols.max(1),
                    i % cols.max(1)
                ));
            }
        }
        Ok(())
    }

    /// X_S at step `t`.
    pub fn x(&self, t: usize) -> &[f64] {
        &self.state[t * self.state_dim..(t + 1) * self.state_dim]
    }

    /// dX_S/dt at step `t`.
    pub fn v(&self, t: usize) -> &[f64] {
        &self.velocity[t * self.state_dim..(t + 1) * self.state_dim]
    }

    /// Pressures at step `t`, kPa.
    pub fn p(&self, t: usize) -> &[f64] {
        &self.pressure_kpa[t * PRESSURE_DIM..(t + 1) * PRESSURE_DIM]
    }

    /// Tip force at step `t`, N.
    pub fn f(&self, t: usize) -> &[f64] {
        &self.force_n[t * FORCE_DIM..(t + 1) * FORCE_DIM]
    }

    /// The steps `start..end` as a trajectory of their own.
    pub fn slice(&self, start: usize, end: usize) -> Self {
        let d = self.state_dim;
        Self {
            dt_s: self.dt_s,
            state_dim: d,
            pressure_kpa: self.pressure_kpa[start * PRESSURE_DIM..end * PRESSURE_DIM].to_vec(),
            force_n: self.force_n[start * FORCE_DIM..end * FORCE_DIM].to_vec(),
            state: self.state[start * d..end * d].to_vec(),
            velocity: self.velocity[start * d..end * d].to_vec(),
        }
    }
}

/// Checks that all trajectories are valid and share the time step and state dimension.
pub fn check_set(trajs: &[Trajectory]) -> Result<(f64, usize)> {
    let first = trajs
        .first()
        .ok_or_else(|| DynamicsError::Data("no trajectory".into()))?;
    for (i, t) in trajs.iter().enumerate() {
        t.validate()
            .map_err(|e| DynamicsError::Data(format!("trajectory {i}: {e}")))?;
        if t.state_dim != first.state_dim || (t.dt_s - first.dt_s).abs() > 1e-12 * first.dt_s {
            return Err(DynamicsError::Data(format!(
                "trajectory {i} has dt {} s and {} state components, trajectory 0 has {} s and {}",
                t.dt_s, t.state_dim, first.dt_s, first.state_dim
            )));
        }
    }
    Ok((first.dt_s, first.state_dim))
}
