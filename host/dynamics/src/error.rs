//! Errors of the learned dynamics.

/// What can go wrong with data, models or checkpoints of the dynamics.
#[derive(Debug, thiserror::Error)]
pub enum DynamicsError {
    /// Trajectories are inconsistent or too short.
    #[error("bad trajectory data: {0}")]
    Data(String),
    /// The lumped model cannot be identified from the data.
    #[error("identification failed: {0}")]
    Identification(String),
    /// A reduced-FEM data set could not be read.
    #[error(transparent)]
    Mor(#[from] ocm_mor::MorError),
    /// Training, checkpoint or scaling failed.
    #[error(transparent)]
    Learn(#[from] ocm_learn::LearnError),
}

/// Result with [`DynamicsError`].
pub type Result<T> = std::result::Result<T, DynamicsError>;
