//! The FE model: the immutable description ([`Model`]), its evolving [`State`], the sparse
//! structure of the reduced system ([`Pattern`]) and the assembly of forces and tangents on it
//! ([`Model::evaluate`]). A model is data, a state is data, and the solvers are functions of both.

mod assembly;
mod description;
pub mod pattern;
mod state;

pub use crate::rigid::{BodyState, RigidBody, skew};
pub use assembly::{Evaluation, Loads};
pub use description::{Cavity, MassKind, Model};
pub use pattern::{BodyDofs, Pattern};
pub use state::State;
