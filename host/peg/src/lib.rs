//! Peg-in-hole with two DIGIT pads (dissertation Ch.6.6.2-6.6.4): a rigid-body scene on rapier,
//! contact points in each sensor's frame, tactile encoders, a scripted expert, demonstrations,
//! behaviour cloning (eq 6.18-6.19), evaluation and trajectory replay.

pub mod bc;
pub mod contact;
pub mod dagger;
pub mod demos;
pub mod encoder;
pub mod error;
pub mod eval;
pub mod expert;
pub mod grasp;
pub mod images;
pub mod npe_encoder;
pub mod patch;
pub mod replay;
pub mod rollout;
pub mod scene;
pub mod sensor;
pub mod trial;

pub use bc::{BcConfig, BcPolicy, BcTraining, DaggerConfig, DaggerRecord, DaggerRound, train_bc};
pub use contact::{GelFoundation, SensorContact, SensorFrame, pad_contact};
pub use dagger::dagger;
pub use demos::{ActionNoise, DemoSet, DemoSettings};
pub use encoder::{ContactFeatures, TactileEncoder};
pub use error::{PegError, Result};
pub use eval::{
    Evaluation, Labelled, TrialSpec, evaluate_expert, evaluate_policy, label_policy_states,
};
pub use expert::{ExpertConfig, SpiralSearch};
pub use grasp::{GelGrip, Grasp, GraspCompliance};
pub use npe_encoder::NpeEncoder;
pub use scene::{GripperPose, InHandError, PegScene, SceneConfig};
pub use sensor::SensorNoise;
pub use trial::{Randomisation, Trial};
