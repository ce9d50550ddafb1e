//! ocm-rl: reinforcement learning on the rigid-link surrogate of the bellows manipulator
//! (dissertation Ch.4.8-4.10).
//!
//! - [`robot`]: the surrogate under grouped commands with a TCP load, its static equilibrium and
//!   the expert inverse.
//! - [`tasks`], [`reward`], [`env`], [`vec_env`]: the Gymnasium-style environments.
//! - [`policy`], [`bc`], [`ppo`], [`sac`]: policies and their training; [`eval`]: 100-point evaluation;
//!   [`bench`]: throughput.
//! - [`transfer`]: deployment on the reduced FEM (or the surrogate in pressure space) through
//!   the inverse actuation map, with the chamber-disconnect test.

pub mod error;
pub use error::{Result, RlError};
pub mod bc;
pub mod bench;
pub mod env;
pub mod eval;
pub mod policy;
pub mod ppo;
pub mod reward;
pub mod robot;
pub mod sac;
pub mod tasks;
pub mod transfer;
pub mod vec_env;
