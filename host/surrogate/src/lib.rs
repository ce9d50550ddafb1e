//! ocm-surrogate: the rigid-link surrogate of the bellows manipulator (dissertation Ch.4.6-4.7,
//! App. D and F).
//!
//! Stages: [`fem_samples`] (FEM boundary nodes over actuation samples) -> [`geometry`] (regression
//! planes [`plane`], contact radii, link dimensions) -> [`chain`] (the joint chain, forward
//! kinematics) with [`constraints`] (limits and grouped constraints) -> [`urdf`] (the robot file)
//! -> [`mapping`] (Algorithm 1, f_SP and its inverse, with the interpolant [`rbf`]) -> [`model`]
//! (the stored surrogate); [`sim`] (articulated simulation with contact on rapier), [`batch`] (a
//! reduced-coordinate stepper for many environments) and [`bench`] (their throughput).

// Index loops follow the joint numbering of the formulas; `!(a > b)` is deliberate so NaN fails.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub use error::{Result, SurrogateError};
pub mod batch;
pub mod bench;
pub mod chain;
pub mod constraints;
pub mod fem_samples;
pub mod force;
pub mod geometry;
mod json;
pub mod mapping;
pub mod model;
pub mod plane;
pub mod rbf;
pub mod sim;
pub mod urdf;
