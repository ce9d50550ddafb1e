//! ocm-fem: a small, verified tetrahedral finite-element code for soft robots.
//!
//! Stages, as a pipeline: [`mesh`] (VTK/STL I/O, surfaces) -> [`model`] (material, mass,
//! constraints, rigid bodies, cavities: immutable data; [`pattern`] the reduced sparse system) ->
//! [`solve`] (static Newton, implicit dynamics, acting on a [`model::State`]). [`bellows`] builds the three-chamber manipulator of
//! dissertation Ch.4.4 from the real mesh, [`calibrate`] fits hyperelastic laws to tensile data,
//! [`sweep`] runs pressure sweeps, [`scene`] reads TOML scenes for `ocm fem run`.
//!
//! Design notes:
//! - SI units throughout (m, N, Pa, kg); readers keep file units and [`mesh::Mesh::scale`] converts.
//! - Laws: corotational (SOFA `TetrahedronFEMForceField`, polar rotation, SOFA's tangent R K0 R^T),
//!   Neo-Hookean eq 2.1 and the mu/kappa form eq 5.6, both with exact tangents.
//! - Pressure is a follower load on triangle surfaces (node force p N / 3, N the area vector) with
//!   its exact tangent; on a closed cavity it is p dV/dx and the cavity volume is reported.
//! - Rigid parts are true rigid bodies ([`model::Model::add_rigid_body`], [`rigid`]): master-slave
//!   elimination with six DOFs per body, x_i = c + R (X_i - C0), R updated as exp(dtheta) R. The
//!   reduced residual T^T r is exact, the tangent is T^T K T plus the symmetric part of the rotation
//!   term (exact at equilibrium), and dynamics run a Lie-group Newmark on (c, R) with the reduced
//!   mass T^T M T. Elements inside a body are skipped (no strain); a body touching a clamp is
//!   clamped whole. The stiff penalty ([`model::Model::make_rigid`], elements scaled 100x) remains
//!   as an option; it leaves the parts about 1 % strained on the bellows and needs more Newton
//!   iterations, and with the corotational law's approximate tangent a 1e6 penalty stalls Newton.
//! - Newton uses a line search on the directional derivative (regula falsi), which copes with the
//!   strongly curved paths of rotating stiff parts; failed steps are cut (also after a run of tiny
//!   line-search steps: an indefinite tangent far from equilibrium), inverted elements reject a
//!   trial, and the solvers return [`FemError::NoConvergence`] or [`FemError::Inverted`], never NaN.

// Index loops mirror the tensor notation of the formulas; `!(a > b)` is deliberate so NaN fails the test.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub mod mesh;

pub use error::{FemError, Result};
pub mod bellows;
pub mod calibrate;
pub mod calibration;
pub mod element;
pub mod material;
pub mod model;
pub mod npy;
pub mod rigid;
pub mod scene;
pub mod solve;
pub mod sweep;
