//! Potential energy of one Yoshimura layer (dissertation eq 3.3-3.8 and
//! 3.16-3.19): bar strain energy, hinge rotation energy weighted by crease
//! length, and pressure work.
//!
//! The energy is evaluated on the layer's kinematic configuration
//! `(h, beta)`; the reference state (bar rest lengths, rest dihedral angles,
//! rest volume) is the unloaded straight layer at the design height
//! `l0 / N`. Using one reference for both modes makes the axial force and
//! the bending moment partial derivatives of one potential, so they satisfy
//! the Maxwell relation `dF/dphi = dM/dl` (checked in the tests).

use crate::geometry::{
    BARS, HINGES, LayerGeometry, NODES, Topology, dihedral, enclosed_volume, norm, sub,
};
use crate::scalar::Scalar;

/// The three parts of the layer energy, each per unit of its coefficient so
/// that callers can weight them (k_b, k_h, pressure) without re-evaluating
/// the geometry.
#[derive(Debug, Clone, Copy)]
pub struct EnergyParts<D> {
    /// `sum 1/2 (L_i - L_i0)^2`, square metres (multiply by `k_b`).
    pub bar: D,
    /// `sum 1/2 L_i (theta_i - theta_i0)^2`, metre-radian^2 (multiply by `k_h`).
    pub hinge: D,
    /// `V - V0`, cubic metres (multiply by `-P`).
    pub volume: D,
}

/// The reference (unloaded) state of a layer.
#[derive(Debug, Clone)]
pub struct RestState {
    /// Bar rest lengths, metres.
    pub bar_length_m: [f64; BARS],
    /// Rest dihedral angles, radians.
    pub dihedral_rad: [f64; HINGES],
    /// Rest enclosed volume, cubic metres.
    pub volume_m3: f64,
}

/// An immutable single-layer energy model: geometry, topology and rest state.
#[derive(Debug, Clone)]
pub struct LayerEnergy {
    /// Layer geometry constants.
    pub geometry: LayerGeometry,
    /// Bars, hinges and facets.
    pub topology: Topology,
    /// The unloaded reference.
    pub rest: RestState,
}

impl LayerEnergy {
    /// Builds the model with the straight layer at `geometry.rest_height_m`
    /// as reference.
    pub fn new(geometry: LayerGeometry) -> Self {
        let topology = Topology::new(&geometry);
        let x = geometry.positions::<f64>(geometry.rest_height_m, 0.0);
        let rest = rest_state(&x, &topology);
        Self {
            geometry,
            topology,
            rest,
        }
    }

    /// The energy parts at layer height `h` and layer bending angle `beta`.
    pub fn parts<D: Scalar>(&self, h: D, beta: D) -> EnergyParts<D> {
        let x = self.geometry.positions(h, beta);
        parts_at(&x, &self.topology, &self.rest)
    }
}

/// Rest lengths, angles and volume of a configuration.
pub fn rest_state(x: &[[f64; 3]; NODES], topology: &Topology) -> RestState {
    let mut bar_length_m = [0.0; BARS];
    for (l, [p, q]) in bar_length_m.iter_mut().zip(topology.bars) {
        *l = norm(sub(x[q], x[p]));
    }
    let mut dihedral_rad = [0.0; HINGES];
    for (a, h) in dihedral_rad.iter_mut().zip(&topology.hinges) {
        *a = dihedral(x, h);
    }
    RestState {
        bar_length_m,
        dihedral_rad,
        volume_m3: enclosed_volume(x, &topology.facets),
    }
}

/// Energy parts of arbitrary nodal positions against a rest state.
pub fn parts_at<D: Scalar>(x: &[[D; 3]], topology: &Topology, rest: &RestState) -> EnergyParts<D> {
    let mut bar = D::from(0.0);
    for ([p, q], l0) in topology.bars.iter().zip(rest.bar_length_m) {
        let dl = norm(sub(x[*q], x[*p])) - l0;
        bar += dl * dl * 0.5;
    }
    let mut hinge = D::from(0.0);
    for (h, a0) in topology.hinges.iter().zip(rest.dihedral_rad) {
        let len = norm(sub(x[h.j], x[h.i]));
        let da = dihedral(x, h) - a0;
        hinge += len * da * da * 0.5;
    }
    let volume = enclosed_volume(x, &topology.facets) - rest.volume_m3;
    EnergyParts { bar, hinge, volume }
}
