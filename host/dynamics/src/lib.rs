//! Learned dynamics of the bellows manipulator (dissertation Ch.4.5): the Transformer-PINN
//! forward model f_S with a lumped physics residual, and the inverse model f_S-dagger with a
//! cycle loss through the frozen forward model; the mapping MLPs of App. D (f_SP, its inverse,
//! f_RS). Built on `ocm-learn`.

pub mod dataset;
pub mod error;
pub mod eval;
pub mod forward;
pub mod inverse;
pub mod lumped;
pub mod mapping;
pub mod pipeline;
pub mod pressure_match;
pub mod samples;
pub mod synth;
pub mod trajectory;

pub use error::{DynamicsError, Result};
pub use forward::{ForwardConfig, ForwardModel};
pub use inverse::{InverseConfig, InverseModel};
pub use lumped::LumpedModel;
pub use mapping::{MapConfig, MapRole, SurrogateMlp, TrainedMap};
pub use pipeline::{
    TrainedForward, TrainedInverse, continue_forward, train_forward, train_inverse,
};
pub use samples::{Samples, Scalers};
pub use trajectory::Trajectory;
