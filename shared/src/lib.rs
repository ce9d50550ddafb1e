//! The contract between the ocm host tools and the OCM firmware.
//!
//! Everything here is `no_std` and allocation-free so that the microcontroller
//! and the host read the same bytes with the same code.
#![no_std]

pub mod lut;
pub mod params;
pub mod protocol;
