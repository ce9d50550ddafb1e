//! The evolving state of a model: positions, velocities, accelerations and rigid-body states.

use super::description::Model;
use crate::rigid::BodyState;
use crate::{FemError, Result};
use nalgebra::Vector3;

/// A configuration of the model (positions and velocities, flat DOF vectors).
#[derive(Debug, Clone)]
pub struct State {
    /// Current positions, m.
    pub x: Vec<f64>,
    /// Velocities, m/s.
    pub v: Vec<f64>,
    /// Accelerations, m/s^2 (used by Newmark).
    pub a: Vec<f64>,
    /// Time, s.
    pub t: f64,
    /// Rigid-body states, one per [`Model::rigid_bodies`] entry.
    pub bodies: Vec<BodyState>,
}

impl State {
    /// The undeformed state at rest.
    pub fn at_rest(model: &Model) -> Self {
        let x = model.rest_dofs();
        let n = x.len();
        State {
            x,
            v: vec![0.0; n],
            a: vec![0.0; n],
            t: 0.0,
            bodies: model.rigid_bodies.iter().map(BodyState::at_rest).collect(),
        }
    }

    /// Nodal displacements x - X.
    pub fn displacements(&self, model: &Model) -> Vec<[f64; 3]> {
        model
            .rest
            .iter()
            .enumerate()
            .map(|(i, p)| {
                [
                    self.x[3 * i] - p.x,
                    self.x[3 * i + 1] - p.y,
                    self.x[3 * i + 2] - p.z,
                ]
            })
            .collect()
    }

    /// Positions as vectors.
    pub fn positions(&self) -> Vec<Vector3<f64>> {
        self.x
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect()
    }
}

impl Model {
    /// Writes the slave positions, velocities and accelerations of every rigid body into `state`
    /// from its body states (x_i = c + R (X_i - C0), v_i = v_c + w x r_i,
    /// a_i = a_c + alpha x r_i + w x (w x r_i)).
    pub fn place_bodies(&self, state: &mut State) -> Result<()> {
        self.check_bodies(state)?;
        for (body, bs) in self.rigid_bodies.iter().zip(&state.bodies) {
            let rot = bs.rotation_matrix();
            let (w, al) = (bs.angular_velocity, bs.angular_acceleration);
            let home = bs.is_home(body);
            for (&i, off) in body.nodes.iter().zip(&body.offsets) {
                let r = rot * off;
                let x = if home { self.rest[i] } else { bs.center + r };
                let v = bs.velocity + w.cross(&r);
                let a = bs.acceleration + al.cross(&r) + w.cross(&w.cross(&r));
                for d in 0..3 {
                    state.x[3 * i + d] = x[d];
                    state.v[3 * i + d] = v[d];
                    state.a[3 * i + d] = a[d];
                }
            }
        }
        Ok(())
    }
    /// Errors unless `state` has one body state per rigid body.
    pub(crate) fn check_bodies(&self, state: &State) -> Result<()> {
        if state.bodies.len() != self.rigid_bodies.len() {
            return Err(FemError::Model(format!(
                "state has {} rigid-body states, model {} rigid bodies (build the state after adding bodies)",
                state.bodies.len(),
                self.rigid_bodies.len()
            )));
        }
        Ok(())
    }
}
