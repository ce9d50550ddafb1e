//! The OCM manipulator's control core, `no_std`, without heap and without
//! panics on any input.
//!
//! Pipeline of one control tick (Fig 3.7): raw Hall codes are mapped to
//! column lengths ([`calibration`]), fused with the IMU into a PCC
//! configuration estimate ([`estimate`]), the inverse model turns the target
//! configuration and load into feed-forward pressures ([`kinematics`], via
//! the LUT maps of [`maps`]), and the PD law ([`control`]) adds feedback,
//! limits the slew and saturates at the pressure limits. [`safety`] watches
//! the link and the sensors; [`app`] handles the protocol of
//! `ocm_shared::protocol` and is generic over a [`app::Board`].
//!
//! All arithmetic on the control path is fixed point ([`fx`] lists the
//! Q-formats). The `f64` twin of the kinematics, closed-form test maps and
//! the default physics LUT image for tests live in the host-side crate
//! `ocm-firmware-support`, outside this API.
#![no_std]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

#[cfg(test)]
extern crate std;

pub mod app;
pub mod calibration;
pub mod control;
pub mod estimate;
pub mod fx;
pub mod kinematics;
pub mod maps;
pub mod safety;
