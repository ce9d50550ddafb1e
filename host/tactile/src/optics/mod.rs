//! Physically based DIGIT frames from the FEM surface (issue 17, item 1): the deformed top face
//! resampled onto the camera image ([`camera`]), its slopes mapped to colour changes by a real
//! DIGIT's polynomial calibration ([`calib`]) and added to a real background ([`render`]).

pub mod bench;
pub mod calib;
pub mod camera;
pub mod render;
pub mod resample;

pub use calib::PolyCalib;
pub use camera::{CameraMap, SurfaceSampler};
pub use render::{RenderScratch, Renderer, RgbImage};
pub use resample::GridToMesh;
