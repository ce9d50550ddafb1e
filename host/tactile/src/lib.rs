//! ocm-tactile: the DIGIT gel pressed by rigid indenters (dissertation Ch.5.3-5.5, 5.7-5.8).
//!
//! Stages: [`indenter`] (closed STL surfaces placed by the set-up files, signed distances from
//! parry) and [`gel`] (the gel mesh, its fixed base and contact surface) -> [`contact`] (nodal
//! augmented-Lagrangian normal contact with regularised Coulomb friction) -> [`indent`] (the
//! stepwise indentation with Newton and its per-step outputs) -> [`mask`] (contact masks on the
//! top surface, Ch.6.5.1) and [`metrics`] (Ch.5.5) -> [`real`] (comparison against the real
//! frames) -> [`reduced`] (POD and a reduced contact solve) -> [`dataset`] (sharded samples).

// Index loops mirror the tensor notation; `!(a > b)` is deliberate so NaN fails the test.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod contact;
pub mod dataset;
pub mod error;
pub mod gel;
pub mod image_io;
pub mod indent;
pub mod indenter;
pub mod mask;
pub mod metrics;
pub mod nets;
pub mod optics;
pub mod output;
pub mod real;
pub mod reduced;
pub mod setup;
pub mod shapes;

pub use error::{Result, TactileError};
