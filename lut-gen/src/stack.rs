//! The uniform-deformation assumption, measured: a full N-layer
//! bar-and-hinge equilibrium solver with every node free (dissertation
//! Ch. 3.3.2 states the assumption, Ch. 3.3.3 eq 3.15 and Fig. 3.5-C the
//! constant neutral-axis length).
//!
//! [`Stack`] describes the structure (an immutable description),
//! [`Stack::solve`] and [`Stack::continue_to`] turn a [`Load`] into an
//! [`Equilibrium`] (the state), and [`measure_assumptions`] sweeps pressure,
//! axial strain and bending to compare the full solve with the uniform model
//! of [`crate::model::OcmModel`].
//!
//! The uniform model is a kinematic restriction of this structure (its
//! nodes follow the layer map of [`crate::geometry`]), so by the minimum
//! principle the free structure is never stiffer in energy; with the fitted
//! `k_b`, `k_h` it is much softer, and its facets cannot carry more than a
//! few hundred pascals without losing stability. Both are findings of the
//! sweeps, not failures of the solver.

mod assumptions;
mod solver;
mod structure;

pub use assumptions::{
    AssumptionConfig, AssumptionReport, AxialPoint, BendPoint, DeviationSummary, PressureStability,
    SweepFailure, measure_assumptions,
};
pub use solver::{Equilibrium, Load, PlateTranslation, SolverConfig};
pub use structure::{Assembly, BEND_AXIS, BEND_DIRECTION, NeutralAxis, Stack};

/// Errors of the stack solver.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StackError {
    /// An input is malformed.
    #[error("invalid {what}: {reason}")]
    InvalidInput {
        /// The input.
        what: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// Newton ran out of iterations.
    #[error(
        "Newton did not converge in {iterations} iterations at {load} (residual {residual_n:.3e} N)"
    )]
    NotConverged {
        /// The load case.
        load: String,
        /// Iterations spent.
        iterations: usize,
        /// Last residual, newtons.
        residual_n: f64,
    },
    /// The line search found no decrease of the potential.
    #[error("line search failed at {load} (residual {residual_n:.3e} N)")]
    LineSearch {
        /// The load case.
        load: String,
        /// Residual when it failed, newtons.
        residual_n: f64,
    },
    /// The energy or its gradient became NaN or infinite.
    #[error("non-finite energy gradient at {load}")]
    NonFinite {
        /// The load case.
        load: String,
    },
    /// A node moved farther than the divergence limit: the structure
    /// balloons or collapses without bound.
    #[error("diverged at {load}: a node moved {displacement_m:.3e} m")]
    Diverged {
        /// The load case.
        load: String,
        /// Largest nodal displacement, metres.
        displacement_m: f64,
    },
    /// Load stepping could not follow the equilibrium path.
    #[error(
        "equilibrium path from [{from}] to [{to}] broken at fraction {reached_fraction:.4}: {cause}"
    )]
    PathBroken {
        /// Start load.
        from: String,
        /// Target load.
        to: String,
        /// Fraction of the path reached.
        reached_fraction: f64,
        /// The last step's failure.
        cause: Box<StackError>,
    },
    /// The uniform model rejected a query.
    #[error("uniform model: {0}")]
    Model(#[from] crate::model::ModelError),
}
