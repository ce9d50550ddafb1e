//! Origami physics of the Yoshimura origami cylinder module (OCM).
//!
//! The bar-and-hinge energy model of one layer (dissertation Ch. 3.3.3,
//! eq 3.3-3.21), the axial force and bending moment as exact energy
//! derivatives, a full multi-layer bar-and-hinge solver that measures the
//! model's assumptions, and the forward/inverse tables compressed into LUT
//! images for the firmware.

pub mod config;
pub mod energy;
pub mod geometry;
pub mod hysteresis;
pub mod model;
pub mod pcc;
pub mod scalar;
pub mod stack;
pub mod surface;
pub mod tables;

pub use model::{AxialTerms, BendConfig, BendingTerms, ModelError, OcmModel};
pub use ocm_shared::params::OcmParams;
