//! The OCM's potential energy as the plant uses it: the lut-gen energy
//! model `Pi(eps, phi, P) = E0(eps, phi) - P V(eps, phi)` (eq 3.3, 3.8,
//! 3.19) through the toolkit's one fast evaluator of it,
//! `ocm_lutgen::surface::EnergySurface`, over a fixed bend range, so that
//! the three columns of a segment, which share one bend, contract the bend
//! direction of the expansion once.
//!
//! The fit costs a few hundred evaluations of the model (about 2 % of a
//! 13 s closed-loop run), and every run of a session builds a plant of the
//! same design: each scenario, each controller, each of the bench's
//! iterations. So the fits are kept per design for the life of the process
//! ([`OcmPotential::new`]), and plants share one expansion.

use std::sync::{Arc, Mutex};

use ocm_lutgen::surface::{BendDomain, EnergySurface, elastic_and_volume};
use ocm_lutgen::{OcmModel, OcmParams};

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
    surface: Arc<EnergySurface<NX, NY, 2>>,
}

/// The expansion as fitted.
type Surface = EnergySurface<NX, NY, 2>;

/// Designs whose fits the process keeps; the oldest goes first.
const KEPT_FITS: usize = 8;

/// Fits made so far, newest last.
static FITS: Mutex<Vec<(OcmParams, Arc<Surface>)>> = Mutex::new(Vec::new());

impl OcmPotential {
    /// Strain range covered by the expansion.
    pub const STRAIN_RANGE: (f64, f64) = (-0.7, 1.2);
    /// Largest per-OCM bending angle covered, radians.
    pub const MAX_BEND_RAD: f64 = 0.5;

    /// The expansion of `model`: fitted on the first call for its
    /// parameters, shared afterwards (the fit is deterministic, so a kept
    /// one is the one a new fit would give).
    pub fn new(model: &OcmModel) -> Result<Self, SimError> {
        let key = *model.params();
        // A poisoned lock only means another thread panicked mid-fit: the
        // list itself is always whole.
        let kept = |fits: &Vec<(OcmParams, Arc<Surface>)>| {
            fits.iter()
                .find(|(p, _)| *p == key)
                .map(|(_, s)| Arc::clone(s))
        };
        if let Some(surface) = kept(&FITS.lock().unwrap_or_else(|e| e.into_inner())) {
            return Ok(Self { surface });
        }
        let surface = Arc::new(Self::fit(model)?);
        let mut fits = FITS.lock().unwrap_or_else(|e| e.into_inner());
        if kept(&fits).is_none() {
            if fits.len() >= KEPT_FITS {
                fits.remove(0);
            }
            fits.push((key, Arc::clone(&surface)));
        }
        Ok(Self { surface })
    }

    /// Fits the expansion to `model`.
    fn fit(model: &OcmModel) -> Result<Surface, SimError> {
        let (lo, _) = Self::STRAIN_RANGE;
        let phi_cap = model.max_bend_angle_rad(lo);
        if phi_cap <= Self::MAX_BEND_RAD {
            return Err(SimError::Config(format!(
                "OCM design bends at most {phi_cap:.3} rad at strain {lo}; the plant needs {}",
                Self::MAX_BEND_RAD
            )));
        }
        EnergySurface::new(
            model,
            Self::STRAIN_RANGE,
            BendDomain::Absolute {
                max_rad: Self::MAX_BEND_RAD,
            },
            elastic_and_volume,
        )
        .map_err(|e| SimError::Config(e.to_string()))
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
