//! The OCM model: axial force `F_A(eps, P)` (eq 3.9) and bending moment
//! `F_B(phi, s)` (eq 3.20-3.21) of a whole N-layer cylinder under the
//! uniform-deformation assumption, as exact derivatives of the layer energy.
//!
//! Conventions (SI): `strain` is `eps = (l - l0)/l0` (eq 3.1); the axial
//! force is `dPi/dl` in newtons, positive in tension, i.e. the external
//! force that holds the cylinder at `eps` under pressure `P` (eq 3.9 divided
//! by `l0` so that it is a force); the bending angle `phi` is the whole
//! cylinder's (each layer turns by `phi/N`) and the moment is `dPi/dphi` in
//! newton-metres at fixed neutral-axis length `s = l0 (1 + eps0)`.

use num_dual::{Dual2_64, Dual64};
use ocm_shared::params::OcmParams;

use crate::energy::{EnergyParts, LayerEnergy};
use crate::geometry::LayerGeometry;

/// Errors of the OCM model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A design parameter is outside the range where the layer exists.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name as in the TOML configuration.
        name: &'static str,
        /// The offending value.
        value: f64,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// A query lies outside the model's domain.
    #[error("{what} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        /// The quantity, with its unit.
        what: &'static str,
        /// The offending value.
        value: f64,
        /// Lower bound of the domain.
        min: f64,
        /// Upper bound of the domain.
        max: f64,
    },
    /// The requested load cannot be reached on the searched interval.
    #[error("{what} = {value} is not reached on [{lo}, {hi}] (range {at_lo} .. {at_hi})")]
    Unreachable {
        /// The load searched for, with its unit.
        what: &'static str,
        /// The requested value.
        value: f64,
        /// Lower end of the searched configuration interval.
        lo: f64,
        /// Upper end of the searched configuration interval.
        hi: f64,
        /// Load at the lower end.
        at_lo: f64,
        /// Load at the upper end.
        at_hi: f64,
    },
}

/// Axial force split by its origin: `F = bar_n + hinge_n + P * pressure_n_per_pa`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxialTerms {
    /// Bar contribution, newtons (proportional to `k_b`).
    pub bar_n: f64,
    /// Hinge contribution, newtons (proportional to `k_h`).
    pub hinge_n: f64,
    /// Pressure contribution per pascal, newtons per pascal (`-dV/dl`).
    pub pressure_n_per_pa: f64,
}

impl AxialTerms {
    /// Total force at pressure `pressure_pa`.
    pub fn force_n(&self, pressure_pa: f64) -> f64 {
        self.bar_n + self.hinge_n + pressure_pa * self.pressure_n_per_pa
    }
}

/// Bending moment split by its origin: `M = bar_nm + hinge_nm + P * pressure_nm_per_pa`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BendingTerms {
    /// Bar contribution, newton-metres (proportional to `k_b`).
    pub bar_nm: f64,
    /// Hinge contribution, newton-metres (proportional to `k_h`).
    pub hinge_nm: f64,
    /// Pressure contribution per pascal (`-dV/dphi`), newton-metres per pascal.
    pub pressure_nm_per_pa: f64,
}

impl BendingTerms {
    /// Total moment at pressure `pressure_pa`.
    pub fn moment_nm(&self, pressure_pa: f64) -> f64 {
        self.bar_nm + self.hinge_nm + pressure_pa * self.pressure_nm_per_pa
    }
}

/// Bending configuration of the cylinder (the quantities of eq 3.11-3.15).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BendConfig {
    /// Half the height difference of the two middle-ring vertices in the
    /// bending plane, `delta_l`, metres.
    pub delta_l_m: f64,
    /// Whole-cylinder bending angle `phi`, radians.
    pub bend_angle_rad: f64,
    /// Radius of the neutral axis `R`, metres (infinite when straight).
    pub radius_m: f64,
    /// Curvature `kappa = 1/R`, per metre.
    pub curvature_per_m: f64,
    /// Neutral-axis length `s = R phi`, metres.
    pub arc_length_m: f64,
}

/// The uniform-deformation model of one OCM.
#[derive(Debug, Clone)]
pub struct OcmModel {
    params: OcmParams,
    layer: LayerEnergy,
}

impl OcmModel {
    /// Builds the model, validating the parameters.
    pub fn new(params: OcmParams) -> Result<Self, ModelError> {
        let positive = |name, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(ModelError::InvalidParameter {
                    name,
                    value,
                    reason: "must be finite and positive",
                })
            }
        };
        positive("base_side_m", params.base_side_m)?;
        positive("rest_length_m", params.rest_length_m)?;
        positive("side_angle_rad", params.side_angle_rad)?;
        positive("bar_stiffness_n_per_m", params.bar_stiffness_n_per_m)?;
        positive("hinge_stiffness_n_per_m", params.hinge_stiffness_n_per_m)?;
        if !(params.mass_kg.is_finite() && params.mass_kg >= 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "mass_kg",
                value: params.mass_kg,
                reason: "must be finite and non-negative",
            });
        }
        if params.layers == 0 || params.layers > 1000 {
            return Err(ModelError::InvalidParameter {
                name: "layers",
                value: params.layers as f64,
                reason: "must be between 1 and 1000",
            });
        }
        if params.side_angle_rad >= core::f64::consts::FRAC_PI_2 {
            return Err(ModelError::InvalidParameter {
                name: "side_angle_rad",
                value: params.side_angle_rad,
                reason: "must be below pi/2",
            });
        }
        let rest_height = params.rest_length_m / params.layers as f64;
        let geometry = LayerGeometry::new(params.base_side_m, params.side_angle_rad, rest_height)
            .ok_or(ModelError::InvalidParameter {
            name: "rest_length_m",
            value: params.rest_length_m,
            reason: "a layer taller than L*tan(theta_d) cannot be folded from the pattern",
        })?;
        Ok(Self {
            params,
            layer: LayerEnergy::new(geometry),
        })
    }

    /// The parameters the model was built from.
    pub fn params(&self) -> &OcmParams {
        &self.params
    }

    /// The single-layer energy model underneath.
    pub fn layer(&self) -> &LayerEnergy {
        &self.layer
    }

    /// Layer height for a cylinder strain, metres.
    pub fn layer_height_m(&self, strain: f64) -> f64 {
        self.params.rest_length_m * (1.0 + strain) / self.params.layers as f64
    }

    /// Geometric range of the axial strain, `[-1, eps*]` (eq 3.5).
    pub fn strain_limits(&self) -> (f64, f64) {
        let n = self.params.layers as f64;
        (
            -1.0,
            n * self.layer.geometry.max_height_m / self.params.rest_length_m - 1.0,
        )
    }

    fn check_strain(&self, strain: f64) -> Result<(), ModelError> {
        let (lo, hi) = self.strain_limits();
        if strain.is_finite() && strain > lo && strain < hi {
            Ok(())
        } else {
            Err(ModelError::OutOfRange {
                what: "strain",
                value: strain,
                min: lo,
                max: hi,
            })
        }
    }

    /// Total potential energy `Pi = Pi_bar + Pi_hinge - P dV` of the
    /// cylinder (eq 3.3), joules.
    pub fn energy_j(&self, strain: f64, bend_angle_rad: f64, pressure_pa: f64) -> f64 {
        let n = self.params.layers as f64;
        let parts = self.layer.parts(
            self.layer_height_m(strain),
            bend_angle_rad / self.params.layers as f64,
        );
        n * self.weigh(parts, pressure_pa)
    }

    fn weigh<D: crate::scalar::Scalar>(&self, parts: EnergyParts<D>, pressure_pa: f64) -> D {
        parts.bar * self.params.bar_stiffness_n_per_m
            + parts.hinge * self.params.hinge_stiffness_n_per_m
            - parts.volume * pressure_pa
    }

    /// Axial force terms at `strain` (straight cylinder).
    ///
    /// `Pi = N * Pi_layer(h)` with `l = N h`, so `dPi/dl = dPi_layer/dh`.
    pub fn axial_terms(&self, strain: f64) -> AxialTerms {
        let h = Dual64::from_re(self.layer_height_m(strain)).derivative();
        let p = self.layer.parts(h, Dual64::from_re(0.0));
        AxialTerms {
            bar_n: self.params.bar_stiffness_n_per_m * p.bar.eps,
            hinge_n: self.params.hinge_stiffness_n_per_m * p.hinge.eps,
            pressure_n_per_pa: -p.volume.eps,
        }
    }

    /// Axial force `F_A(eps, P)` (eq 3.9), newtons, tension positive.
    pub fn axial_force_n(&self, strain: f64, pressure_pa: f64) -> f64 {
        self.axial_terms(strain).force_n(pressure_pa)
    }

    /// Axial stiffness `dF_A/dl`, newtons per metre.
    pub fn axial_stiffness_n_per_m(&self, strain: f64, pressure_pa: f64) -> f64 {
        let h = Dual2_64::from_re(self.layer_height_m(strain)).derivative();
        let parts = self.layer.parts(h, Dual2_64::from_re(0.0));
        // d2(Pi)/dl2 = (1/N) d2(Pi_layer)/dh2.
        self.weigh(parts, pressure_pa).v2 / self.params.layers as f64
    }

    /// Largest feasible whole-cylinder bending angle at initial strain
    /// `strain0`: the inner edge of each layer closes completely.
    pub fn max_bend_angle_rad(&self, strain0: f64) -> f64 {
        let h = self.layer_height_m(strain0);
        let r2 = self.layer.geometry.middle_radius(h);
        self.params.layers as f64 * h / r2
    }

    /// Largest feasible bend angle at `strain0` and its derivative with
    /// respect to the strain (radians, radians per unit strain).
    pub fn max_bend_angle_and_slope(&self, strain0: f64) -> (f64, f64) {
        let n = f64::from(self.params().layers);
        let h = Dual64::from_re(self.layer_height_m(strain0)).derivative();
        let r2 = self.layer().geometry.middle_radius(h);
        let phi = h * n / r2;
        // dh/dstrain = l0 / N
        (phi.re, phi.eps * self.params().rest_length_m / n)
    }

    /// Bending moment terms at bending angle `phi` and initial strain `strain0`.
    ///
    /// `Pi = N * Pi_layer(beta)` with `phi = N beta`, so `dPi/dphi = dPi_layer/dbeta`.
    pub fn bending_terms(&self, bend_angle_rad: f64, strain0: f64) -> BendingTerms {
        let n = self.params.layers as f64;
        let h = Dual64::from_re(self.layer_height_m(strain0));
        let beta = Dual64::from_re(bend_angle_rad / n).derivative();
        let p = self.layer.parts(h, beta);
        BendingTerms {
            bar_nm: self.params.bar_stiffness_n_per_m * p.bar.eps,
            hinge_nm: self.params.hinge_stiffness_n_per_m * p.hinge.eps,
            pressure_nm_per_pa: -p.volume.eps,
        }
    }

    /// Bending moment `F_B(phi, s)` at pressure `P` (eq 3.20-3.21), newton-metres.
    pub fn bending_moment_nm(&self, bend_angle_rad: f64, strain0: f64, pressure_pa: f64) -> f64 {
        self.bending_terms(bend_angle_rad, strain0)
            .moment_nm(pressure_pa)
    }

    /// Bending stiffness `dM/dphi`, newton-metres per radian.
    pub fn bending_stiffness_nm_per_rad(
        &self,
        bend_angle_rad: f64,
        strain0: f64,
        pressure_pa: f64,
    ) -> f64 {
        let n = self.params.layers as f64;
        let h = Dual2_64::from_re(self.layer_height_m(strain0));
        let beta = Dual2_64::from_re(bend_angle_rad / n).derivative();
        let parts = self.layer.parts(h, beta);
        self.weigh(parts, pressure_pa).v2 / n
    }

    /// Neutral-axis length of the whole cylinder at initial strain `strain0`, metres.
    pub fn arc_length_m(&self, strain0: f64) -> f64 {
        self.params.rest_length_m * (1.0 + strain0)
    }

    /// Initial strain of a cylinder whose neutral axis is `arc_length_m` long.
    pub fn strain_of_arc_length(&self, arc_length_m: f64) -> f64 {
        arc_length_m / self.params.rest_length_m - 1.0
    }

    /// Bending configuration from `(delta_l, eps0)` (eq 3.11-3.15): the
    /// middle ring turns rigidly by `beta/2`, so `delta_l = r2 sin(beta/2)`.
    pub fn bend_config(&self, delta_l_m: f64, strain0: f64) -> Result<BendConfig, ModelError> {
        self.check_strain(strain0)?;
        let n = self.params.layers as f64;
        let h = self.layer_height_m(strain0);
        let r2 = self.layer.geometry.middle_radius(h);
        let beta_max = h / r2;
        let delta_max = r2 * (0.5 * beta_max).sin();
        if !(delta_l_m.is_finite() && (0.0..=delta_max).contains(&delta_l_m)) {
            return Err(ModelError::OutOfRange {
                what: "delta_l_m",
                value: delta_l_m,
                min: 0.0,
                max: delta_max,
            });
        }
        let beta = 2.0 * (delta_l_m / r2).asin();
        let radius_m = if beta > 0.0 { h / beta } else { f64::INFINITY };
        Ok(BendConfig {
            delta_l_m,
            bend_angle_rad: n * beta,
            radius_m,
            curvature_per_m: beta / h,
            arc_length_m: n * h,
        })
    }

    /// Inverse axial map `eps = F_A^-1(F, P)` on `[lo, hi]` (eq 3.24), by
    /// safeguarded Newton on the exact force; requires `F_A` to be
    /// increasing on the interval.
    pub fn strain_for_force(
        &self,
        force_n: f64,
        pressure_pa: f64,
        (lo, hi): (f64, f64),
    ) -> Result<f64, ModelError> {
        self.check_strain(lo)?;
        self.check_strain(hi)?;
        solve_increasing(
            |e| self.axial_force_n(e, pressure_pa),
            |e| self.axial_stiffness_n_per_m(e, pressure_pa) * self.params.rest_length_m,
            force_n,
            (lo, hi),
            "force_n",
        )
    }

    /// Inverse bending map `phi = F_B^-1(M, s)` at pressure `P` (eq 3.25), on
    /// the feasible range; odd in the moment.
    pub fn bend_angle_for_moment(
        &self,
        moment_nm: f64,
        strain0: f64,
        pressure_pa: f64,
    ) -> Result<f64, ModelError> {
        self.check_strain(strain0)?;
        let phi_max = self.max_bend_angle_rad(strain0);
        let sign = moment_nm.signum();
        let phi = solve_increasing(
            |phi| self.bending_moment_nm(phi, strain0, pressure_pa),
            |phi| self.bending_stiffness_nm_per_rad(phi, strain0, pressure_pa),
            moment_nm.abs(),
            (0.0, phi_max),
            "moment_nm",
        )?;
        Ok(sign * phi)
    }
}

/// Finds `x` in `[lo, hi]` with `f(x) = target` for increasing `f`, by Newton
/// steps kept inside a shrinking bracket (bisection when Newton leaves it).
fn solve_increasing(
    f: impl Fn(f64) -> f64,
    df: impl Fn(f64) -> f64,
    target: f64,
    (mut lo, mut hi): (f64, f64),
    what: &'static str,
) -> Result<f64, ModelError> {
    let (f_lo, f_hi) = (f(lo) - target, f(hi) - target);
    if !target.is_finite() || f_lo > 0.0 || f_hi < 0.0 {
        return Err(ModelError::Unreachable {
            what,
            value: target,
            lo,
            hi,
            at_lo: f_lo + target,
            at_hi: f_hi + target,
        });
    }
    let mut x = 0.5 * (lo + hi);
    for _ in 0..200 {
        let r = f(x) - target;
        if r == 0.0 {
            return Ok(x);
        }
        if r < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let slope = df(x);
        let newton = x - r / slope;
        x = if slope > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo < 1e-14 * (1.0 + x.abs()) || (r / slope).abs() < 1e-15 {
            break;
        }
    }
    Ok(x)
}
