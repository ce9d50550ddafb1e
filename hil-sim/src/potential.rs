//! The OCM's potential energy as the plant uses it: the lut-gen energy
//! model `Pi(eps, phi, P) = E0(eps, phi) - P V(eps, phi)` (eq 3.3, 3.8,
//! 3.19) through the toolkit's one fast evaluator of it,
//! `ocm_lutgen::surface::EnergySurface`, over a fixed bend range, so that
//! the three columns of a segment, which share one bend, contract the bend
//! direction of the expansion once.

use ocm_lutgen::OcmModel;
use ocm_lutgen::surface::{BendDomain, EnergySurface, elastic_and_volume};

pub use ocm_lutgen::surface::PartGrad;

use crate::SimError;

/// Expansion orders in the strain and in `w = phi^2`.
const NX: usize = 20;
const NY: usize = 8;

/// Both energy parts of one OCM at one point.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EnergyGrad {
    /// Elastic part `E0` (bars and hinges), joules.
    pub elastic: PartGrad,
    /// Volume part `V - V0` of the whole OCM, cubic metres (energy is `-P V`).
    pub volume: PartGrad,
}

/// The plant's expansion of one OCM's energy.
#[derive(Debug, Clone)]
pub struct OcmPotential {
    surface: EnergySurface<NX, NY, 2>,
}

impl OcmPotential {
    /// Strain range covered by the expansion.
    pub const STRAIN_RANGE: (f64, f64) = (-0.7, 1.2);
    /// Largest per-OCM bending angle covered, radians.
    pub const MAX_BEND_RAD: f64 = 0.5;

    /// Fits the expansion to `model`.
    pub fn new(model: &OcmModel) -> Result<Self, SimError> {
        let (lo, _) = Self::STRAIN_RANGE;
        let phi_cap = model.max_bend_angle_rad(lo);
        if phi_cap <= Self::MAX_BEND_RAD {
            return Err(SimError::Config(format!(
                "OCM design bends at most {phi_cap:.3} rad at strain {lo}; the plant needs {}",
                Self::MAX_BEND_RAD
            )));
        }
        let surface = EnergySurface::new(
            model,
            Self::STRAIN_RANGE,
            BendDomain::Absolute {
                max_rad: Self::MAX_BEND_RAD,
            },
            elastic_and_volume,
        )
        .map_err(|e| SimError::Config(e.to_string()))?;
        Ok(Self { surface })
    }

    /// Rest length `l0` of one OCM, metres.
    pub fn rest_length_m(&self) -> f64 {
        self.surface.model().params().rest_length_m
    }

    /// Layer count of the OCM.
    pub fn layers(&self) -> u32 {
        self.surface.model().params().layers
    }

    /// Both parts and their gradients at `(strain, w = phi^2)`; the point
    /// must lie in the covered range (callers clamp).
    pub fn eval(&self, strain: f64, w: f64) -> EnergyGrad {
        self.eval3([strain; 3], w)[0]
    }

    /// [`Self::eval`] at three strains sharing one bend (the three columns
    /// of a segment).
    pub fn eval3(&self, strains: [f64; 3], w: f64) -> [EnergyGrad; 3] {
        self.surface.eval3(strains, w).map(pair)
    }

    /// [`Self::eval3`] without the values (left 0): the gradients are all
    /// the dynamics needs.
    pub fn grad3(&self, strains: [f64; 3], w: f64) -> [EnergyGrad; 3] {
        self.surface.grad3(strains, w).map(pair)
    }
}

fn pair([elastic, volume]: [PartGrad; 2]) -> EnergyGrad {
    EnergyGrad { elastic, volume }
}
