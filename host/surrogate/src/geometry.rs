//! Surrogate geometry from the FEM samples (Ch.4.6.1, Fig 4.8-4.9): per-layer regression planes,
//! contact radii and R_min, link lengths from the backbone arc length.

use crate::chain::ChainGeometry;
use crate::fem_samples::FemSamples;
use crate::plane::{fit_plane, projected_radius};
use crate::{Result, SurrogateError};
use serde::{Deserialize, Serialize};

/// Mass of the real manipulator, kg (Ch.4.6.2: about 820 g).
pub const ROBOT_MASS_KG: f64 = 0.820;

/// Mass given to each dummy link between the x and y rotations, kg. The dissertation's dummies
/// are massless; rigid-body engines (MuJoCo, rapier) need a positive mass on every moving body.
pub const DUMMY_MASS_KG: f64 = 1e-5;

/// Contact-boundary statistics of one bellows layer over all samples.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct LayerStats {
    /// Ridge height at rest, m (middle of the ridge band).
    pub rest_height_m: f64,
    /// Mean contact radius over the samples (R_i), m.
    pub radius_mean_m: f64,
    /// Smallest and largest per-sample radius, m.
    pub radius_range_m: [f64; 2],
    /// Root-mean-square distance of the boundary nodes from their regression plane, m.
    pub plane_rms_m: f64,
}

/// Everything the geometry step measures, and the chain built from it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Geometry {
    /// Per layer, base first.
    pub layers: Vec<LayerStats>,
    /// Smallest mean layer radius (R_min), m.
    pub r_min_m: f64,
    /// Shortest and longest backbone arc length over the samples, m.
    pub arc_length_range_m: [f64; 2],
    /// Samples used.
    pub samples: usize,
    /// The chain dimensions and masses.
    pub chain: ChainGeometry,
}

/// Measures the layers over the training samples and sizes the chain.
///
/// Chain sizing (the dissertation gives the quantities, not the formulas): the flexible length
/// at zero extension is the shortest backbone arc of the samples less the rigid base and top
/// plate, so that the prismatic joints (d >= 0) only ever lengthen it. It is cut into four equal
/// parts with a bending pair at the middle of each (so equal joint angles trace the chord of a
/// constant-curvature arc); the three prismatic joints sit halfway between neighbouring pairs.
/// The TCP is the last eighth of the flexible length, the top plate and the FEM's TCP offset above
/// the last pair.
/// 820 g is split equally over the six body links and the top plate.
pub fn measure(s: &FemSamples) -> Result<Geometry> {
    if s.samples.is_empty() {
        return Err(SurrogateError::Invalid("no FEM samples to measure".into()));
    }
    let nl = s.layers.nodes.len();
    let mut layers = Vec::with_capacity(nl);
    for k in 0..nl {
        let (mut sum, mut lo, mut hi, mut sq, mut n) =
            (0.0, f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
        for smp in &s.samples {
            let pts = smp.layer(k);
            let plane = fit_plane(&pts)?;
            let r = projected_radius(&plane, &pts);
            sum += r;
            lo = lo.min(r);
            hi = hi.max(r);
            for p in &pts {
                sq += plane.distance(p).powi(2);
                n += 1;
            }
        }
        let z = s.layers.ridge_z_m[k];
        layers.push(LayerStats {
            rest_height_m: 0.5 * (z[0] + z[1]),
            radius_mean_m: sum / s.samples.len() as f64,
            radius_range_m: [lo, hi],
            plane_rms_m: (sq / n as f64).sqrt(),
        });
    }
    let r_min = layers
        .iter()
        .map(|l| l.radius_mean_m)
        .fold(f64::INFINITY, f64::min);
    let (amin, amax) = s
        .samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, x| {
            (a.0.min(x.arc_length_m), a.1.max(x.arc_length_m))
        });
    let top_thickness = s.top_face_m - s.rigid_top_bottom_m;
    let flex = amin - s.rigid_base_top_m - top_thickness;
    if !(flex > 0.0) {
        return Err(SurrogateError::Invalid(format!(
            "shortest arc {amin} m leaves no flexible length between base and top plate"
        )));
    }
    // The four pairs sit at the midpoints of four equal parts of the flexible length (the
    // midpoint rule for a constant-curvature arc); the outer eighths are rigid.
    let chain = ChainGeometry {
        base_height_m: s.rigid_base_top_m + flex / 8.0,
        segment_length_m: flex / 4.0,
        tcp_offset_m: flex / 8.0 + top_thickness + s.tcp_offset_m,
        link_radius_m: r_min,
        base_radius_m: s.base_radius_m,
        top_radius_m: s.top_radius_m,
        top_thickness_m: top_thickness,
        link_mass_kg: ROBOT_MASS_KG / 7.0,
        dummy_mass_kg: DUMMY_MASS_KG,
    };
    Ok(Geometry {
        layers,
        r_min_m: r_min,
        arc_length_range_m: [amin, amax],
        samples: s.samples.len(),
        chain,
    })
}
