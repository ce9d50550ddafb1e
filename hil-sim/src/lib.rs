//! The virtual lab: a simulated OCM manipulator segment, its sensors, the
//! controller under test and the dissertation's experiments as scenarios
//! (Ch. 3.3.6-3.4.2, Table 3.2; Ch. 4.10.4 for the chamber disconnect).
//!
//! Pipeline of one control tick: the [`plant`] integrates the plate
//! dynamics under the chamber pressures its [`pneumatics`] deliver; the
//! [`sensors`] sample Hall codes and the IMU; an [`mcu::Mcu`] turns them
//! into commanded pressures. [`scenario`] runs the experiments and
//! [`metrics`] scores them.
//!
//! The MCU under test is the firmware ([`firmware::FirmwareMcu`]) over a
//! [`firmware::Link`]: linked in process, or a board binary behind a byte
//! link, under QEMU ([`qemu`], PIL) or on a serial port ([`serial`]). The
//! command stream is the same in every mode, so the commanded pressures
//! are too, bit for bit.
//!
//! The plant's physics is the OCM energy model of `ocm-lutgen` (through
//! [`potential`]), never the firmware's LUT, so model error between the two
//! is real and measurable.

// The mechanics works on fixed 3-vectors (three columns, three
// coordinates); indexed loops mirror the equations more plainly than zips.
#![allow(clippy::needless_range_loop)]

pub mod effects;
#[cfg(feature = "firmware")]
pub mod firmware;
pub mod mcu;
pub mod metrics;
/// The segment's PCC kinematics: the one implementation, in `ocm-lutgen`.
pub use ocm_lutgen::pcc;
pub mod plant;
pub mod pneumatics;
pub mod potential;
#[cfg(feature = "serial")]
pub mod qemu;
pub mod reference;
pub mod scenario;
pub mod sensors;
#[cfg(feature = "serial")]
pub mod serial;

pub use scenario::{
    ControllerKind, LogRow, RomPoint, RunReport, SCENARIOS, ScenarioReport, SimConfig,
    run_scenario, run_with_mcu, working_limits,
};

/// Errors of the simulator.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A parameter is out of range.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// No scenario of this name; the message lists the known ones.
    #[error(
        "unknown scenario {0:?}; known: rom, triangle, circle, points, orientation, disconnect, step_load"
    )]
    UnknownScenario(String),
    /// A static solve found no equilibrium or inverse.
    #[error("no equilibrium: {0}")]
    NoEquilibrium(String),
    /// The controller under test failed.
    #[error("controller {name}: {message}")]
    Mcu {
        /// Controller name.
        name: String,
        /// What went wrong.
        message: String,
    },
    /// A file, device or process failed (a log, a serial port, QEMU).
    #[error("{path}: {message}")]
    Io {
        /// The file or device.
        path: String,
        /// The cause.
        message: String,
    },
}
