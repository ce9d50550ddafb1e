//! ocm-mor: model-order reduction of the bellows FEM (dissertation Ch.4.4.5, App. E), the compact
//! state X_S of Fig 4.3, and the sharded datasets the learned models train on.
//!
//! Pipeline: [`drive`] (seeded pressure and tip-force sequences) -> [`full`] (the FEM, snapshots)
//! -> [`pod`] (randomized SVD basis) -> [`rom`] (Galerkin projection, ECSW hyper-reduction via
//! [`nnls`], reduced statics and implicit dynamics) -> [`xs`] (X_S of a full or reduced state) ->
//! [`dataset`] (NPY + JSON manifest, shards). [`store`] keeps bases and reduced models on disk with
//! their hashes. [`weighted`] is the stiffness-weighted POD, [`modes`] the full model's rest
//! modes, static load shapes and Petrov-Galerkin test bases, and [`lspg`] least-squares
//! Petrov-Galerkin steps on the full step residual (all measured, none better for the bellows:
//! see the README's error budget). [`opinf`] is the non-intrusive alternative: operator inference
//! on the POD coordinates (fitted maps, no element sweeps in a step).

#![allow(clippy::needless_range_loop)]

pub mod curve;
pub mod dataset;
pub mod drive;
pub mod error;
pub mod full;
pub mod lspg;
pub mod modes;
pub mod nnls;
pub mod opinf;
pub mod pod;
pub mod rom;
pub mod run;
pub mod store;
pub mod weighted;
pub mod xs;

pub use error::{MorError, Result, sha256_f64, sha256_hex};
