//! Host-side companions of the OCM firmware, for tests, benches and board
//! builds; none of it is flashed.
//!
//! - [`physics`]: the default LUT image from the `ocm-lutgen` energy model,
//!   the image users flash and the one every firmware figure is measured on.
//! - [`reference`]: the `f64` twin of `ocm_firmware::kinematics`, the
//!   yardstick of the fixed-point path, over any [`maps_f64::OcmMapsF64`].
//! - [`linear`]: a linear-spring OCM with closed-form maps in both
//!   arithmetics, to test the kinematics without a table.
//! - [`bringup`]: a closed-form monotone LUT image (not the physics) whose
//!   maps are known exactly, to test the LUT path against a formula.

pub mod bringup;
pub mod linear;
pub mod maps_f64;
pub mod physics;
pub mod reference;
