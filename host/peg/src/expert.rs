//! The scripted expert: a privileged Cartesian velocity controller that knows the true pose of
//! the peg (it reads the peg's body, so it sees the in-hand error the policy must infer).

use serde::{Deserialize, Serialize};

use crate::error::{PegError, Result, positive};
use crate::scene::{N_ACTION, PegScene};

/// Gains and thresholds of the expert.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExpertConfig {
    /// Proportional gain from the tip's position error to the gripper velocity, 1/s.
    pub gain_per_s: f64,
    /// Proportional gain from the peg's roll to the roll rate, 1/s.
    pub roll_gain_per_s: f64,
    /// Height of the tip above the board while aligning, m.
    pub hover_m: f64,
    /// Lateral tip error below which descending starts (it ramps to full speed at zero), m.
    pub align_radius_m: f64,
    /// Peg roll below which descending starts, rad.
    pub align_roll_rad: f64,
    /// Descending speed when aligned, m/s.
    pub insert_speed_m_s: f64,
}

impl Default for ExpertConfig {
    fn default() -> Self {
        Self {
            gain_per_s: 4.0,
            roll_gain_per_s: 4.0,
            hover_m: 0.003,
            align_radius_m: 0.0004,
            align_roll_rad: 1.5f64.to_radians(),
            insert_speed_m_s: 0.01,
        }
    }
}

impl ExpertConfig {
    /// Checks the gains, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("gain_per_s", self.gain_per_s),
            ("roll_gain_per_s", self.roll_gain_per_s),
            ("align_radius_m", self.align_radius_m),
            ("align_roll_rad", self.align_roll_rad),
            ("insert_speed_m_s", self.insert_speed_m_s),
        ] {
            positive(&format!("expert {name}"), v)?;
        }
        if !self.hover_m.is_finite() {
            return Err(PegError::Invalid("expert hover_m is not finite".into()));
        }
        Ok(())
    }

    /// The expert's gripper velocity `[vx, vy, vz, roll rate]` for the scene's current state.
    ///
    /// It turns the peg upright and centres its tip over the hole at the hover height; the
    /// closer it is to aligned, the more the height target gives way to a steady descent
    /// (a smooth gate, so that the cloned policy has a smooth map to learn). Once the tip is
    /// inside the hole it keeps descending while centring.
    pub fn act(&self, scene: &PegScene) -> [f64; N_ACTION] {
        let (tip, roll) = scene.peg_tip();
        let lateral = tip[0].hypot(tip[1]);
        let gate = (1.0 - lateral / self.align_radius_m).clamp(0.0, 1.0)
            * (1.0 - roll.abs() / self.align_roll_rad).clamp(0.0, 1.0);
        let vz = if tip[2] < 0.0 {
            -self.insert_speed_m_s
        } else {
            let hold = self.gain_per_s * (self.hover_m - tip[2]);
            (1.0 - gate) * hold.min(self.insert_speed_m_s) - gate * self.insert_speed_m_s
        };
        [
            -self.gain_per_s * tip[0],
            -self.gain_per_s * tip[1],
            vz,
            -self.roll_gain_per_s * roll,
        ]
    }
}
