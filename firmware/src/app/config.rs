//! Static settings of an app instance and what the firmware reports about
//! itself.

use ocm_shared::params::{ManipulatorParams, ParamPreset};
use ocm_shared::protocol::{Geometry, Mount};

/// Static settings of an app instance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AppConfig {
    /// Control period the PD law assumes, microseconds.
    pub control_period_us: u32,
    /// Send telemetry every this many board-sampled ticks (0: never).
    pub telemetry_every: u16,
    /// Share of the IMU in the bend estimate, Q1.15.
    pub imu_weight_q15: i32,
}

impl Default for AppConfig {
    fn default() -> Self {
        Self {
            control_period_us: 1_000,
            telemetry_every: 50,
            imu_weight_q15: 1 << 14,
        }
    }
}

/// The geometry an app boots with: the manipulator of Table 3.1 on an
/// upright base, built from OCMs of the default parameter set
/// (`ParamPreset::default()`, the calibrated one), so that the default LUT
/// image is accepted without a `SetGeometry` first.
pub const DEFAULT_GEOMETRY: Geometry = Geometry {
    manipulator: ManipulatorParams::TABLE_3_1,
    ocm: ParamPreset::Calibrated.ocm(),
    mount: Mount::Upright,
};

const fn parse_version(s: &str) -> u8 {
    let b = s.as_bytes();
    let mut v: u32 = 0;
    let mut i = 0;
    while i < b.len() {
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    if v > 255 { 255 } else { v as u8 }
}

pub(super) const FIRMWARE_VERSION: [u8; 3] = [
    parse_version(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_version(env!("CARGO_PKG_VERSION_MINOR")),
    parse_version(env!("CARGO_PKG_VERSION_PATCH")),
];
