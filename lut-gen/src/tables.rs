//! Forward tables of the OCM model and their compression into a LUT image
//! (dissertation Ch. 3.3.4 and App. A).
//!
//! * Axial: `F_A(eps, P)` on a uniform `(P, eps)` grid, by default
//!   `eps` in -0.6..0.6 (129 points) and the 16 pressure levels 0, 2, ..., 30 kPa.
//! * Bending: `M(phi, s, P) = M0(phi, s) + P * M1(phi, s)` on uniform
//!   neutral-axis lengths `s = l0 (1 + eps0)`, `eps0` in -0.6..0.6 (17 levels),
//!   and a normalized angle `u = phi / phi_max(s)` in 0..1 (129 points).
//!
//! # Non-monotone regions
//! The inverse maps need each row to increase. A row that decreases (a
//! snap-through, where the force drops while the strain grows) has no
//! single-valued inverse; we replace it by its monotone envelope, the
//! running maximum from the low end, so the inverse returns the strain at
//! which the force is *first* reached on loading. Every raised sample is
//! counted in [`Tables::raised_samples`] and reported by `ocm lut build`, so a
//! user sees when a design has a snap-through in the table's range. The Table
//! 3.1 design has none.

use ocm_shared::lut::{
    AxialTableSpec, BendingTableSpec, EncodeError, LutImage, encode, encoded_len, length_grid_m,
    pressure_grid_pa, strain_grid,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::model::{ModelError, OcmModel};

/// Grids of the tables.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TableConfig {
    /// Lowest axial strain.
    pub eps_min: f64,
    /// Highest axial strain.
    pub eps_max: f64,
    /// Axial strain points.
    pub n_eps: u16,
    /// Lowest pressure level, kPa.
    pub p_min_kpa: f64,
    /// Highest pressure level, kPa.
    pub p_max_kpa: f64,
    /// Pressure levels.
    pub n_p: u16,
    /// Lowest initial strain of the bending table.
    pub eps0_min: f64,
    /// Highest initial strain of the bending table.
    pub eps0_max: f64,
    /// Neutral-axis length levels of the bending table.
    pub n_s: u16,
    /// Normalized bending-angle points.
    pub n_u: u16,
}

impl Default for TableConfig {
    fn default() -> Self {
        Self {
            eps_min: -0.6,
            eps_max: 0.6,
            n_eps: 129,
            p_min_kpa: 0.0,
            p_max_kpa: 30.0,
            n_p: 16,
            eps0_min: -0.6,
            eps0_max: 0.6,
            n_s: 17,
            n_u: 129,
        }
    }
}

/// Errors while building tables.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// A grid is malformed.
    #[error("table grid {what}: {reason}")]
    Grid {
        /// The grid field.
        what: &'static str,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The model could not be evaluated.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The image writer rejected the tables.
    #[error("writing the LUT image: {0:?}")]
    Encode(EncodeError),
}

/// Sampled forward tables.
#[derive(Debug, Clone)]
pub struct Tables {
    /// The grids.
    pub config: TableConfig,
    /// Axial force, N, row-major `[p][eps]`.
    pub axial_force_n: Vec<f64>,
    /// Largest bending angle per length level, rad.
    pub phi_max_rad: Vec<f64>,
    /// Moment at zero pressure, N*m, row-major `[s][u]`.
    pub m0_nm: Vec<f64>,
    /// Moment per pascal, N*m/Pa, row-major `[s][u]`.
    pub m1_nm_per_pa: Vec<f64>,
    /// Samples raised to make rows monotone (see the module docs).
    pub raised_samples: usize,
}

impl TableConfig {
    fn validate(&self, model: &OcmModel) -> Result<(), TableError> {
        let (lo, hi) = model.strain_limits();
        let grid = |what, ok: bool, reason| {
            if ok {
                Ok(())
            } else {
                Err(TableError::Grid { what, reason })
            }
        };
        grid(
            "n_eps",
            (2..=1024).contains(&self.n_eps),
            "must be 2..=1024",
        )?;
        grid("n_p", (2..=1024).contains(&self.n_p), "must be 2..=1024")?;
        grid("n_s", (2..=1024).contains(&self.n_s), "must be 2..=1024")?;
        grid("n_u", (2..=1024).contains(&self.n_u), "must be 2..=1024")?;
        let inside = |a: f64, b: f64| a.is_finite() && b.is_finite() && lo < a && a < b && b < hi;
        grid(
            "eps_min/eps_max",
            inside(self.eps_min, self.eps_max),
            "need -1 < eps_min < eps_max < eps*",
        )?;
        grid(
            "eps0_min/eps0_max",
            inside(self.eps0_min, self.eps0_max),
            "need -1 < eps0_min < eps0_max < eps*",
        )?;
        grid(
            "p_min_kpa/p_max_kpa",
            self.p_min_kpa.is_finite()
                && self.p_max_kpa.is_finite()
                && self.p_min_kpa < self.p_max_kpa,
            "need finite p_min_kpa < p_max_kpa",
        )
    }

    /// Strain of axial grid point `i`, exactly as the image places it.
    pub fn strain(&self, i: u16) -> f64 {
        strain_grid(self.eps_min, self.eps_max, self.n_eps, i)
    }

    /// Pressure of level `j`, Pa, exactly as the image places it.
    pub fn pressure_pa(&self, j: u16) -> f64 {
        pressure_grid_pa(self.p_min_kpa * 1e3, self.p_max_kpa * 1e3, self.n_p, j)
    }

    /// Neutral-axis length bounds, m.
    pub fn length_bounds_m(&self, model: &OcmModel) -> (f64, f64) {
        (
            model.arc_length_m(self.eps0_min),
            model.arc_length_m(self.eps0_max),
        )
    }

    /// Neutral-axis length of bending level `k`, m, exactly as the image places it.
    pub fn length_m(&self, model: &OcmModel, k: u16) -> f64 {
        let (lo, hi) = self.length_bounds_m(model);
        length_grid_m(lo, hi, self.n_s, k)
    }
}

/// Samples the model on the grids. `progress(done, total)` is called once per
/// finished table row.
pub fn build_tables(
    model: &OcmModel,
    config: &TableConfig,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Tables, TableError> {
    config.validate(model)?;
    let (n_eps, n_p, n_s, n_u) = (
        usize::from(config.n_eps),
        usize::from(config.n_p),
        usize::from(config.n_s),
        usize::from(config.n_u),
    );
    let total = n_p + n_s;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let tick = || {
        progress(
            done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
            total,
        )
    };

    // The force is affine in P, so two evaluations of the terms per strain
    // give every pressure row exactly.
    let terms: Vec<_> = (0..config.n_eps)
        .into_par_iter()
        .map(|i| model.axial_terms(config.strain(i)))
        .collect();
    let mut axial_force_n = vec![0.0; n_p * n_eps];
    for (j, row) in axial_force_n.chunks_exact_mut(n_eps).enumerate() {
        let p = config.pressure_pa(j as u16);
        for (f, t) in row.iter_mut().zip(&terms) {
            *f = t.force_n(p);
        }
        tick();
    }

    let rows: Vec<(f64, Vec<f64>, Vec<f64>)> = (0..config.n_s)
        .into_par_iter()
        .map(|k| {
            let eps0 = model.strain_of_arc_length(config.length_m(model, k));
            let phi_max = model.max_bend_angle_rad(eps0);
            let (m0, m1) = (0..config.n_u)
                .map(|i| {
                    let u = f64::from(i) / f64::from(config.n_u - 1);
                    let t = model.bending_terms(u * phi_max, eps0);
                    (t.bar_nm + t.hinge_nm, t.pressure_nm_per_pa)
                })
                .unzip();
            tick();
            (phi_max, m0, m1)
        })
        .collect();
    let mut phi_max_rad = Vec::with_capacity(n_s);
    let mut m0_nm = Vec::with_capacity(n_s * n_u);
    let mut m1_nm_per_pa = Vec::with_capacity(n_s * n_u);
    for (phi_max, m0, m1) in rows {
        phi_max_rad.push(phi_max);
        m0_nm.extend(m0);
        m1_nm_per_pa.extend(m1);
    }

    let mut raised_samples = 0;
    for row in axial_force_n.chunks_exact_mut(n_eps) {
        raised_samples += monotone_envelope(row);
    }
    // A bending row is monotone at every pressure of the axial grid if it is
    // at both ends (affinity in P); raise M0 where M0 + P M1 dips at either.
    let p_ends = [config.pressure_pa(0), config.pressure_pa(config.n_p - 1)];
    for (m0, m1) in m0_nm
        .chunks_exact_mut(n_u)
        .zip(m1_nm_per_pa.chunks_exact(n_u))
    {
        for p in p_ends {
            let mut row: Vec<f64> = m0.iter().zip(m1).map(|(a, b)| a + p * b).collect();
            let raised = monotone_envelope(&mut row);
            if raised > 0 {
                raised_samples += raised;
                for ((a, b), r) in m0.iter_mut().zip(m1).zip(&row) {
                    *a = r - p * b;
                }
            }
        }
    }

    Ok(Tables {
        config: *config,
        axial_force_n,
        phi_max_rad,
        m0_nm,
        m1_nm_per_pa,
        raised_samples,
    })
}

/// Raises samples to the running maximum; returns how many were raised.
fn monotone_envelope(row: &mut [f64]) -> usize {
    let mut raised = 0;
    for i in 1..row.len() {
        if row[i] < row[i - 1] {
            row[i] = row[i - 1];
            raised += 1;
        }
    }
    raised
}

impl Tables {
    fn specs<'a>(&'a self, model: &OcmModel) -> (AxialTableSpec<'a>, BendingTableSpec<'a>) {
        let c = &self.config;
        let (s_min_m, s_max_m) = c.length_bounds_m(model);
        (
            AxialTableSpec {
                eps_min: c.eps_min,
                eps_max: c.eps_max,
                n_eps: c.n_eps,
                p_min_pa: c.p_min_kpa * 1e3,
                p_max_pa: c.p_max_kpa * 1e3,
                n_p: c.n_p,
                force_n: &self.axial_force_n,
            },
            BendingTableSpec {
                s_min_m,
                s_max_m,
                n_s: c.n_s,
                n_u: c.n_u,
                phi_max_rad: &self.phi_max_rad,
                m0_nm: &self.m0_nm,
                m1_nm_per_pa: &self.m1_nm_per_pa,
            },
        )
    }

    /// The LUT image bytes, stamped with the model's parameter hash.
    pub fn encode(&self, model: &OcmModel) -> Result<Vec<u8>, TableError> {
        let (axial, bending) = self.specs(model);
        let mut out = vec![0u8; encoded_len(&axial, &bending)];
        let n = encode(model.params().hash(), &axial, &bending, &mut out)
            .map_err(TableError::Encode)?;
        out.truncate(n);
        Ok(out)
    }
}

/// How well a LUT image reproduces the f64 model's inverse maps, in percent
/// of each table's full scale (strain span for the axial inverse, the
/// largest feasible bending angle for the bending inverse).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Accuracy {
    /// Image size, bytes.
    pub size_bytes: usize,
    /// Whether the image's CRC (and header) validated.
    pub crc_ok: bool,
    /// Mean absolute error of `eps = F_A^-1(F, P)`, % of full scale.
    pub axial_err_mean_pct_fs: f64,
    /// Largest absolute error of `eps = F_A^-1(F, P)`, % of full scale.
    pub axial_err_max_pct_fs: f64,
    /// Mean absolute error of `phi = F_B^-1(M, s, P)`, % of full scale.
    pub bending_err_mean_pct_fs: f64,
    /// Largest absolute error of `phi = F_B^-1(M, s, P)`, % of full scale.
    pub bending_err_max_pct_fs: f64,
    /// Number of off-grid points checked per table.
    pub points: usize,
}

/// Halton low-discrepancy sequence: deterministic points that avoid the grid.
fn halton(mut i: usize, base: usize) -> f64 {
    let (mut f, mut r) = (1.0, 0.0);
    i += 1;
    while i > 0 {
        f /= base as f64;
        r += f * (i % base) as f64;
        i /= base;
    }
    r
}

/// Errors while checking an image.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The image failed validation.
    #[error("LUT image rejected: {0:?}")]
    Image(ocm_shared::lut::LutError),
    /// The image was built for other parameters.
    #[error(
        "LUT image parameter hash {image:#018x} does not match the model's {model:#018x}; pass the --config the image was built with"
    )]
    HashMismatch {
        /// Hash in the image.
        image: u64,
        /// Hash of the model's parameters.
        model: u64,
    },
    /// A lookup failed where the model says it must succeed.
    #[error("lookup failed at {what}: {error:?}")]
    Lookup {
        /// The query.
        what: String,
        /// The reader's error.
        error: ocm_shared::lut::LookupError,
    },
}

/// Compares inverse lookups through the fixed-point image with the f64
/// model on `points` off-grid points per table (Halton sequence over the
/// tables' domains; pressures anywhere in the pressure span).
pub fn check_accuracy(
    model: &OcmModel,
    bytes: &[u8],
    points: usize,
) -> Result<Accuracy, CheckError> {
    let image = LutImage::parse(bytes).map_err(CheckError::Image)?;
    if image.param_hash() != model.params().hash() {
        return Err(CheckError::HashMismatch {
            image: image.param_hash(),
            model: model.params().hash(),
        });
    }
    let ag = image.axial_grid();
    let (eps_min, eps_max): (f64, f64) = (ag.eps_min.to_num(), ag.eps_max.to_num());
    let (p_min, p_max): (f64, f64) = (ag.p_min.to_num(), ag.p_max.to_num());
    let bg = image.bending_grid();
    let (s_min, s_max): (f64, f64) = (bg.s_min.to_num(), bg.s_max.to_num());
    let (eps0_min, eps0_max) = (
        model.strain_of_arc_length(s_min),
        model.strain_of_arc_length(s_max),
    );
    let phi_fs = (0..bg.n_s)
        .filter_map(|k| image.phi_max_at(k))
        .map(|p| p.to_num::<f64>())
        .fold(0.0, f64::max);

    let axial: Result<Vec<f64>, CheckError> = (0..points)
        .into_par_iter()
        .map(|i| {
            let eps = eps_min + (eps_max - eps_min) * halton(i, 2);
            let p = p_min + (p_max - p_min) * halton(i, 3);
            let f = model.axial_force_n(eps, p);
            let got = image
                .axial_strain_f64(f, p)
                .map_err(|error| CheckError::Lookup {
                    what: format!("F_A^-1({f} N, {p} Pa)"),
                    error,
                })?;
            Ok((got.value - eps).abs() / (eps_max - eps_min) * 100.0)
        })
        .collect();
    let bending: Result<Vec<f64>, CheckError> = (0..points)
        .into_par_iter()
        .map(|i| {
            let eps0 = eps0_min + (eps0_max - eps0_min) * halton(i, 2);
            let p = p_min + (p_max - p_min) * halton(i, 3);
            // Stay inside the feasible range at this length.
            let phi = model.max_bend_angle_rad(eps0) * 0.999 * halton(i, 5);
            let m = model.bending_moment_nm(phi, eps0, p);
            let s = model.arc_length_m(eps0);
            let got = image
                .bending_angle_f64(m, s, p)
                .map_err(|error| CheckError::Lookup {
                    what: format!("F_B^-1({m} N*m, {s} m, {p} Pa)"),
                    error,
                })?;
            Ok((got.value - phi).abs() / phi_fs * 100.0)
        })
        .collect();
    let (axial, bending) = (axial?, bending?);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    Ok(Accuracy {
        size_bytes: image.size_bytes(),
        crc_ok: true,
        axial_err_mean_pct_fs: mean(&axial),
        axial_err_max_pct_fs: max(&axial),
        bending_err_mean_pct_fs: mean(&bending),
        bending_err_max_pct_fs: max(&bending),
        points,
    })
}
