//! Hidden-effect records of every kind: the scalar kinds' generator ([`crate::generator`]) and
//! the pose generator ([`crate::pose_generator`]) behind one entry point. The dispatch lives
//! here so that the pose generator can build on the shared protocol pieces of the scalar one
//! without the two modules importing each other.

use crate::data::Kind;
pub use crate::generator::{Generated, Spec, hideable};

/// Generates a record for `spec`. Effects not in [`hideable`] for the kind are ignored.
pub fn generate(spec: &Spec) -> Generated {
    match spec.kind {
        Kind::Pose => crate::pose_generator::generate_pose(spec),
        _ => crate::generator::generate_scalar(spec),
    }
}
