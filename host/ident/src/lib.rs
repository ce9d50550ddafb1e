//! Discrepancy discovery for the ocm models: from measured data to what the model gets wrong,
//! the named cause, an extended model and the measured held-out gain.
//!
//! The pipeline: read a record ([`data`], [`softarm`]) -> split it by time blocks ([`split`])
//! -> fit the physics baseline on the training rows ([`baseline`], [`physics`],
//! [`manipulator`]) -> compute per-cause residual diagnostics ([`diagnostics`]) -> fit one
//! model extension per cause and score it on held-out rows ([`extension`]) -> select causes by
//! held-out gain and an information criterion with a false-discovery guard ([`select`]) ->
//! report ([`ident`], [`report`]). [`synth`] makes measured-like data with hidden effects
//! ([`generator`] for the scalar kinds, [`pose_generator`] for `pose`).

// Numeric kernels index several parallel arrays by row; iterator chains over four zipped
// slices read worse than the index.
#![allow(clippy::needless_range_loop)]

pub mod baseline;
pub mod cause;
pub mod conventions;
pub mod cylinder;
pub mod data;
pub mod diagnostics;
pub mod direction;
pub mod dynamic_generator;
pub mod error;
pub mod extension;
pub mod generator;
pub mod ident;
mod lm;
pub mod lsq;
pub mod manipulator;
pub mod matv5;
pub mod physics;
pub mod pose_generator;
pub mod preisach;
pub mod report;
pub mod select;
pub mod signal;
pub mod softarm;
pub mod split;
pub mod statespace;
mod structure;
pub mod synth;

pub use cause::Cause;
pub use data::{Channel, Kind, Record};
pub use error::IdentError;
pub use ident::{Identification, Report, identify};
pub use select::Config;
