//! ocm-fem: a small, verified tetrahedral finite-element code for soft robots.
//!
//! Stages, as a pipeline: [`mesh`] (VTK/STL I/O, surfaces) -> [`model`] (material, mass,
//! constraints, cavities: immutable data) -> [`solve`] (static Newton, implicit dynamics,
//! acting on a [`model::State`]). [`bellows`] builds the three-chamber manipulator of
//! dissertation Ch.4.4 from the real mesh, [`calibrate`] fits hyperelastic laws to tensile data,
//! [`sweep`] runs pressure sweeps, [`scene`] reads TOML scenes for `ocm fem run`.
//!
//! Design notes:
//! - SI units throughout (m, N, Pa, kg); readers keep file units and [`mesh::Mesh::scale`] converts.
//! - Laws: corotational (SOFA `TetrahedronFEMForceField`, polar rotation, SOFA's tangent R K0 R^T),
//!   Neo-Hookean eq 2.1 and the mu/kappa form eq 5.6, both with exact tangents.
//! - Pressure is a follower load on triangle surfaces (node force p N / 3, N the area vector) with
//!   its exact tangent; on a closed cavity it is p dV/dx and the cavity volume is reported.
//! - Rigid parts are a stiff penalty: elements of the part get their stiffness scaled (default
//!   100x). It keeps the system symmetric and the sparsity unchanged; master-slave elimination would
//!   be exact but needs a nonlinear rotation parametrisation of each body.
//! - Newton uses a line search on the directional derivative (regula falsi), which copes with the
//!   strongly curved paths of rotating stiff parts; failed steps are cut, inverted elements reject a
//!   trial, and the solvers return [`FemError::NoConvergence`] or [`FemError::Inverted`], never NaN.

// Index loops mirror the tensor notation of the formulas; `!(a > b)` is deliberate so NaN fails the test.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub mod mesh;

pub use error::{FemError, Result};
pub mod bellows;
pub mod calibrate;
pub mod element;
pub mod material;
pub mod model;
pub mod npy;
pub mod scene;
pub mod solve;
pub mod sweep;
