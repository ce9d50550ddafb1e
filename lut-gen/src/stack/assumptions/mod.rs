//! Sweeps that compare the full N-layer solve with the uniform model.
//!
//! Pressure: the pressure is ramped with the plate free (no force) and with
//! the plate held at `l0`, and the first pressure without a stable
//! equilibrium (no convergence, divergence or an indefinite Hessian) is
//! located by bisection.
//!
//! Axial: at each pressure the level plate is held at strain `eps`
//! (displacement control passes the limit points that force control cannot),
//! walking outward from `eps = 0`. The plate reaction `F` is the full
//! structure's force; `F - F_A(eps, P)` is the force error at equal strain
//! and `eps - F_A^-1(F, P)` the strain error at equal force.
//!
//! Bending: at each initial strain `eps0` the straight stack is first held
//! at `l0 (1 + eps0)` (plate centre prescribed), which gives the axial force
//! `F0` that sets that strain in the full structure. Then the plate is
//! rotated by `phi` two ways:
//! - on the uniform model's arc: the plate centre prescribed where the
//!   uniform map puts it, so the generalised force `dPi/dphi` along that
//!   path is the same quantity as the model's `M(phi, eps0)`;
//! - under the constant axial force `F0` along the plate normal with the
//!   plate centre free, so the neutral-axis length is free to change: the
//!   test of the claim that it does not depend on the bending angle.

mod config;
mod pressure;
mod report;
mod sweep;

pub use config::AssumptionConfig;
pub use report::{
    AssumptionReport, AxialPoint, BendPoint, DeviationSummary, PressureStability, SweepFailure,
};
pub use sweep::measure_assumptions;
