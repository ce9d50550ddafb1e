//! The full bellows FEM driven by the random inputs: implicit dynamics (backward Euler, dt from
//! the drive, Rayleigh damping and density from the scene), the source of snapshots and the
//! reference the reduced model is measured against.

use crate::drive::Input;
use crate::{MorError, Result};
use nalgebra::Vector3;
use ocm_fem::bellows::{Bellows, check_pressures};
use ocm_fem::model::{Model, State};
use ocm_fem::solve::dynamics::{DynamicSolver, Integrator, StepReport};

/// Distributes a tip force over the top-face nodes in equal parts (a dead load on the top plate).
pub fn tip_point_forces(top_face: &[usize], force_n: [f64; 3]) -> Vec<(usize, Vector3<f64>)> {
    let f = Vector3::from(force_n) / top_face.len() as f64;
    top_face.iter().map(|&i| (i, f)).collect()
}

/// A running full-model simulation.
pub struct FullSim<'a> {
    bellows: &'a Bellows,
    model: Model,
    solver: DynamicSolver,
    /// Current state.
    pub state: State,
}

impl<'a> FullSim<'a> {
    /// Starts at rest.
    pub fn new(bellows: &'a Bellows) -> Result<Self> {
        let model = bellows.model.clone();
        let solver = DynamicSolver::new(&model, Integrator::ImplicitEuler)?;
        let state = State::at_rest(&model);
        Ok(FullSim {
            bellows,
            model,
            solver,
            state,
        })
    }

    /// Advances one step of `dt_s` under `input` (held over the step); returns the solver's
    /// report (Newton iterations, sub-steps when the step was cut).
    pub fn step(&mut self, input: &Input, dt_s: f64) -> Result<StepReport> {
        check_pressures(&input.pressure_kpa)?;
        self.model.point_forces = tip_point_forces(&self.bellows.top_face, input.tip_force_n);
        let loads = self.bellows.loads_kpa(&input.pressure_kpa);
        self.solver
            .step(&self.model, &mut self.state, &loads, dt_s)
            .map_err(|e| MorError::Solve(format!("full model at t = {:.3} s: {e}", self.state.t)))
    }

    /// Nodal displacements x - X, flat (3N), m.
    pub fn displacement(&self) -> Vec<f64> {
        self.state
            .x
            .iter()
            .zip(self.model.rest.iter().flat_map(|p| [p.x, p.y, p.z]))
            .map(|(x, r)| x - r)
            .collect()
    }
}

/// One simulated trajectory: displacement snapshots and X_S per step.
#[derive(Debug, Clone)]
pub struct Trajectory {
    /// Displacements after each step (3N each), m.
    pub displacements: Vec<Vec<f64>>,
    /// X_S and its rate after each step.
    pub xs: Vec<[f64; 2 * crate::xs::XS_DIM]>,
    /// Wall time of the steps, s.
    pub seconds: f64,
    /// Wall time of each step, s.
    pub step_seconds: Vec<f64>,
    /// Sub-steps of each step (1 unless the solver cut it).
    pub substeps: Vec<usize>,
}

/// Runs the full model over `inputs` from rest.
pub fn simulate(
    bellows: &Bellows,
    inputs: &[Input],
    dt_s: f64,
    keep_displacements: bool,
    mut on_step: impl FnMut(usize),
) -> Result<Trajectory> {
    let probe = crate::xs::XsProbe::of_bellows(bellows);
    let mut sim = FullSim::new(bellows)?;
    let mut out = Trajectory {
        displacements: vec![],
        xs: Vec::with_capacity(inputs.len()),
        seconds: 0.0,
        step_seconds: Vec::with_capacity(inputs.len()),
        substeps: Vec::with_capacity(inputs.len()),
    };
    for (k, inp) in inputs.iter().enumerate() {
        let t0 = std::time::Instant::now();
        let rep = sim.step(inp, dt_s)?;
        let dt = t0.elapsed().as_secs_f64();
        out.substeps.push(rep.substeps);
        out.seconds += dt;
        out.step_seconds.push(dt);
        if keep_displacements {
            out.displacements.push(sim.displacement());
        }
        out.xs.push(probe.of_full_state(&sim.state));
        on_step(k);
    }
    Ok(out)
}

/// Runs `sequences + held_out` seeded sequences of `steps` steps from rest and collects the
/// snapshots (rows of displacements, 3N each, and X_S rows) with their record; `on_step` gets the
/// number of steps done.
pub fn record_snapshots(
    bellows: &Bellows,
    drive: &crate::drive::DriveConfig,
    seed: u64,
    sequences: usize,
    held_out: usize,
    steps: usize,
    mut on_step: impl FnMut(usize),
) -> Result<(crate::store::SnapshotRecord, Vec<f64>, Vec<f64>)> {
    let total = sequences + held_out;
    let dofs = 3 * bellows.model.num_nodes();
    let (mut disp, mut xs, mut secs) = (
        Vec::with_capacity(total * steps * dofs),
        Vec::with_capacity(total * steps * 2 * crate::xs::XS_DIM),
        0.0,
    );
    for k in 0..total {
        let inputs = crate::drive::sequence(drive, seed, k as u64, steps);
        let tr = simulate(bellows, &inputs, drive.dt_s, true, |j| {
            on_step(k * steps + j + 1)
        })?;
        secs += tr.seconds;
        disp.extend(tr.displacements.into_iter().flatten());
        xs.extend(tr.xs.iter().flatten().copied());
    }
    let rec = crate::store::SnapshotRecord {
        model_hash: crate::store::model_hash(bellows),
        seed,
        sequences,
        held_out,
        steps,
        dt_s: drive.dt_s,
        dofs,
        seconds_per_step: secs / (total * steps).max(1) as f64,
    };
    Ok((rec, disp, xs))
}
