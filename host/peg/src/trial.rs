//! Randomised trials: the gripper's start pose and the peg's in-hand error, drawn from a seed.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{PegError, Result, non_negative};
use crate::scene::{GripperPose, InHandError, PegScene, SceneConfig};

/// Ranges of the randomisation (uniform, symmetric about zero unless a range is given).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Randomisation {
    /// Largest in-hand offset along the pads' horizontal direction, m.
    pub offset_y_m: f64,
    /// Largest in-hand offset along the fingers, m.
    pub offset_z_m: f64,
    /// Largest in-hand tilt, rad.
    pub tilt_rad: f64,
    /// Largest start offset of the gripper from the hole's axis in x and in y, m.
    pub start_xy_m: f64,
    /// Range of the nominal start height of the tip above the board, m.
    pub start_height_m: [f64; 2],
    /// Largest start roll of the gripper, rad.
    pub start_roll_rad: f64,
    /// Largest offset of the hole from where the robot believes it, in x and in y, m (0: the
    /// hole is where the proprioception's frame says; absent in settings written before).
    #[serde(default)]
    pub hole_xy_m: f64,
}

impl Default for Randomisation {
    fn default() -> Self {
        Self {
            offset_y_m: 0.0025,
            offset_z_m: 0.003,
            tilt_rad: 6f64.to_radians(),
            start_xy_m: 0.005,
            start_height_m: [0.012, 0.025],
            start_roll_rad: 3f64.to_radians(),
            hole_xy_m: 0.0,
        }
    }
}

/// One trial's initial condition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Trial {
    /// Seed of the stream the trial was drawn from (its sensors' errors are drawn from it too).
    #[serde(default)]
    pub seed: u64,
    /// Index of the trial in its stream.
    pub index: u64,
    /// Gripper pose at the start.
    pub start: GripperPose,
    /// The peg's in-hand error.
    pub error: InHandError,
    /// Where the hole's axis really is in the frame the robot believes is the hole's, x and
    /// y, m (privileged: no policy sees it).
    #[serde(default)]
    pub hole_m: [f64; 2],
}

impl Randomisation {
    /// Checks the ranges, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("offset_y_m", self.offset_y_m),
            ("offset_z_m", self.offset_z_m),
            ("tilt_rad", self.tilt_rad),
            ("start_xy_m", self.start_xy_m),
            ("start_roll_rad", self.start_roll_rad),
            ("hole_xy_m", self.hole_xy_m),
            ("start_height_m[0]", self.start_height_m[0]),
            ("start_height_m[1]", self.start_height_m[1]),
        ] {
            non_negative(&format!("randomisation {name}"), v)?;
        }
        if self.start_height_m[0] > self.start_height_m[1] {
            return Err(PegError::Invalid(format!(
                "randomisation start_height_m {:?} is not an increasing range",
                self.start_height_m
            )));
        }
        Ok(())
    }

    /// Trial `index` of the stream `seed` (each trial has its own ChaCha8 stream, so a trial
    /// does not depend on how many others are drawn).
    pub fn trial(&self, config: &SceneConfig, seed: u64, index: u64) -> Trial {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(index);
        let mut sym = |r: f64| {
            if r > 0.0 {
                rng.random_range(-r..=r)
            } else {
                0.0
            }
        };
        let error = InHandError {
            offset_y_m: sym(self.offset_y_m),
            offset_z_m: sym(self.offset_z_m),
            tilt_rad: sym(self.tilt_rad),
        };
        let x = sym(self.start_xy_m);
        let y = sym(self.start_xy_m);
        let roll = sym(self.start_roll_rad);
        let [h0, h1] = self.start_height_m;
        let h = if h1 > h0 {
            rng.random_range(h0..=h1)
        } else {
            h0
        };
        // The tip hangs peg_length - peg_top below the gripper's origin at the nominal grasp.
        let z = h + config.peg_length_m - config.peg_top_m;
        // Drawn after the rest, so that a trial keeps its pose and in-hand error whatever the
        // hole's error.
        let r = self.hole_xy_m;
        let hole_m = if r > 0.0 {
            [rng.random_range(-r..=r), rng.random_range(-r..=r)]
        } else {
            [0.0; 2]
        };
        Trial {
            seed,
            index,
            start: GripperPose {
                x_m: x,
                y_m: y,
                z_m: z,
                roll_rad: roll,
            },
            error,
            hole_m,
        }
    }
}

impl Trial {
    /// The scene of this trial in `config`: its start, in-hand error and hole.
    pub fn scene(&self, config: &SceneConfig) -> Result<PegScene> {
        PegScene::with_hole(config, self.start, self.error, self.hole_m)
    }
}
