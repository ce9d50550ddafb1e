//! ocm-npe: the neural physics engine of the DIGIT gel (dissertation Ch.6.4-6.5).
//!
//! Contact points of a rigid body in the sensor frame (as `ocm_tactile::dataset::ContactGrid`
//! defines them), its resultant normal force and depth go in; the displacement and contact
//! force of every node of the gel's top surface come out.
//!
//! - [`model`]: DeepSets encoder, fusion, residual GCN, readout (eq 6.10-6.15).
//! - [`data`]: samples of an `ocm-tactile` dataset and the split by set-up.
//! - [`fit`]: training with the shared loop of `ocm-learn` (loss eq 6.17).
//! - [`engine`]: [`Npe`], the trained engine: `load`, `predict`, `latent`.
//! - [`kernel`]: the engine's forward pass on plain values (one call, no tensors).
//! - [`eval`]: Table 6.1 against the FEM. [`bench`]: latency per call.
//! - [`stiffness`]: the total force read from a displacement field.
//! - [`symmetry`]: turned and mirrored indentations to augment the training set.

pub mod bench;
pub mod data;
pub mod engine;
pub mod error;
pub mod eval;
pub mod figure;
pub mod fit;
pub mod kernel;
pub mod model;
pub mod stiffness;
pub mod symmetry;

pub use engine::{Fields, Npe, Surface};
pub use error::{NpeError, Result};
