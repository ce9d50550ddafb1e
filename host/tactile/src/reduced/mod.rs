//! The reduced tactile model (dissertation Ch.5.4.2, eq 5.1-5.5): a POD basis of the gel's
//! displacement fields over many FEM indentations and a reduced static solve with contact.
//!
//! Basis: the snapshots u (3N, whole gel, metres) of full-FEM indentations go through the
//! workspace's randomized SVD (`ocm_mor::pod::pod`); u ~ Phi q (eq 5.4) with r modes.
//! Stiffness: eq 5.5 with the nonlinear operator K(u) of eq 5.1 taken at rest, K_r = Phi^T K_0 Phi
//! (r x r, computed once from the fem tangent). [`ReducedIndentation::with_nonlinear`] replaces
//! K_r q by the gel's Neo-Hookean force hyper-reduced by ECSW ([`hyper`]); the figures in
//! the README say what the linearisation costs against the Neo-Hookean FEM.
//!
//! Contact (frictionless, as the data sets' FEM): the same node-to-surface law as [`crate::contact`],
//! p_i = max(0, lambda_i - k_i g_i) with k_i = eps_n A_i, on the gel's surface nodes. Each pass
//! queries the signed distances g_i and normals n_i (parry) at the current q and linearises
//! g_i(q') = g_i + a_i . (q' - q) with a_i = Phi_i^T n_i; the penalty problem is then solved
//! exactly by a semismooth Newton on the active set, (K_r + sum_A k_i a_i a_i^T) q' =
//! sum_A a_i (lambda_i - k_i g_i + k_i a_i . q). Passes repeat until q settles, then the
//! augmented-Lagrangian multipliers are updated until the penetration is within the tolerance
//! (or the update budget is spent: the frame reports its penetration).
//! A node is queried only when the 1-Lipschitz bound on its signed distance (last queried gap
//! minus how far it and the indenter moved since) could bring it within reach of contact.

pub(crate) mod basis;
mod enrich;
pub mod hyper;
mod score;
mod solve;
#[cfg(test)]
mod tests;

pub use basis::{ReducedInfo, ReducedModel};
pub use enrich::{
    DEFAULT_FOOTPRINT_LOADS, Enrichment, FOOTPRINT_LOADS, FOOTPRINT_RIM_M, NodalLoads,
    RestStiffness, check_footprint_loads, footprint_load_cases, placement_model, second_order_mode,
};
pub use score::{
    FemSequence, SequenceScore, WorstFrame, deepest_depth_within, score_sequence, worst_frame,
};
pub use solve::{ReducedFrame, ReducedIndentation, ReducedOptions};
