//! The manipulator segment as a dynamic system.
//!
//! Model (immutable, [`Plant`]) and state ([`PlantState`]) are kept apart.
//! Generalized coordinates are the PCC configuration in Cartesian form
//! `q = (S, bx, by)` (see [`crate::pcc`]). Three columns of `n` OCMs in
//! series (identical strain along a column, the PCC assumption of
//! Ch. 3.3.5) hold the top plate. The potential is the sum of the OCM
//! energies `n (s_i E0(eps_i, w) - P_i V(eps_i, w))` with `eps_i = l_i /
//! (n l0) - 1` and the per-OCM bending angle `theta / n`, `w = (theta/n)^2`;
//! its gradient is the generalized elastic force, which couples axial and
//! bending stiffness exactly as the energy model does. At rest the
//! gradient balances gravity and the tip load: the virtual-work form of
//! eq 3.27-3.29 (which it reduces to when the OCMs' own bending stiffness
//! is neglected).
//!
//! Kinetic energy: the plate, the payload and the lumped column masses move
//! with the plate centre; the mass matrix is `m J_p^T J_p + I J_w^T J_w`
//! with the rotation Jacobian of the straight pose (the tilt rate equals the
//! bending-vector rate there); its configuration dependence is kept but the
//! Coriolis terms it would bring are dropped, which is harmless at the slow
//! motions of a pneumatic arm and keeps the step cheap. Damping is viscous
//! along each column. Integration is semi-implicit Euler at `dt`.
//!
//! Gravity acts along the backbone: `Hanging` (the default, the base above
//! as in the dissertation's experiments, Fig 3.9 and App. B) stretches the
//! columns; `Upright` compresses them. Upright, a segment of Table 3.1's
//! own stiffness is close to buckling: its tilt stiffness (about 0.14 N
//! m/rad at S = 110 mm) barely exceeds the destabilizing `m g S / 3` of its
//! own weight, and a 250 g payload tips it over; the calibrated set
//! (`docs/model.md`) is about 19 times stiffer.

use ocm_lutgen::{OcmModel, OcmParams};
use ocm_shared::params::{ManipulatorParams, ParamPreset};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::effects::{BoucWen, COLUMN_LOOP, Effects};
use crate::pcc::{COS_BETA, Config, SIN_BETA, Turn, sinc_from_sin};
use crate::pneumatics::{Regulator, RegulatorParams};
use crate::potential::OcmPotential;

/// Standard gravity, m/s^2.
pub const GRAVITY: f64 = 9.806_65;

/// How the base is mounted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Mounting {
    /// Base below: weights compress the columns.
    Upright,
    /// Base above: weights stretch the columns.
    Hanging,
}

impl Mounting {
    /// Gravity along the backbone axis z, m/s^2.
    pub fn gravity_z(self) -> f64 {
        match self {
            Self::Upright => -GRAVITY,
            Self::Hanging => GRAVITY,
        }
    }
}

/// Everything that describes the plant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantParams {
    /// OCM design: [`ParamPreset::Calibrated`] by default; a `[plant.ocm]`
    /// table starts from its `preset` key (`"calibrated"` or `"table-3.1"`).
    #[serde(deserialize_with = "ocm_lutgen::config::deserialize_ocm")]
    pub ocm: OcmParams,
    /// Manipulator layout (one segment is simulated).
    pub manipulator: ManipulatorParams,
    /// Mounting of the base.
    pub mounting: Mounting,
    /// Tilt inertia of the plate about a diameter, kg m^2 (thin disc of
    /// radius `d + 10 mm` by default).
    pub plate_inertia_kg_m2: f64,
    /// Viscous damping of each column, N s/m.
    pub column_damping_n_s_per_m: f64,
    /// Stiffness of the end stop outside the modelled strain range, N/m.
    pub end_stop_n_per_m: f64,
    /// Regulators.
    pub regulator: RegulatorParams,
    /// Non-ideal effects.
    pub effects: Effects,
    /// Integration step, seconds.
    pub dt_s: f64,
}

impl PlantParams {
    /// Moving mass: plate, lumped OCMs and payload, kilograms.
    pub fn moving_mass_kg(&self, load: &PlateLoad) -> f64 {
        self.manipulator.plate_mass_kg
            + 3.0 * f64::from(self.manipulator.ocms_per_column) * self.ocm.mass_kg
            + load.payload_kg
    }

    /// Total external force on the plate (gravity of the moving mass plus
    /// the tip force), base frame, newtons.
    pub fn external_force_n(&self, load: &PlateLoad) -> [f64; 3] {
        let w = self.moving_mass_kg(load) * self.mounting.gravity_z();
        [load.force_n[0], load.force_n[1], load.force_n[2] + w]
    }
}

impl Default for PlantParams {
    fn default() -> Self {
        let manipulator = ManipulatorParams::TABLE_3_1;
        let r = manipulator.column_radius_m + 0.010;
        Self {
            ocm: ParamPreset::default().ocm(),
            manipulator,
            mounting: Mounting::Hanging,
            plate_inertia_kg_m2: 0.25 * manipulator.plate_mass_kg * r * r,
            // Damping ratio about 0.3 on the axial mode, as the Table 3.1
            // plant had with 1 N s/m: the calibrated columns are 19.45
            // times stiffer, so sqrt(19.45) times the damping.
            column_damping_n_s_per_m: 4.5,
            end_stop_n_per_m: 2_000.0,
            regulator: RegulatorParams::default(),
            effects: Effects::NONE,
            dt_s: 1e-3,
        }
    }
}

/// External load on the plate, base frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PlateLoad {
    /// Payload mass at the plate centre, kilograms.
    pub payload_kg: f64,
    /// Extra force at the plate centre, newtons.
    pub force_n: [f64; 3],
}

/// The immutable plant model: design, potential and the seeded draws of the
/// effects (stiffness spread, regulator offsets).
#[derive(Debug, Clone)]
pub struct Plant {
    params: PlantParams,
    model: OcmModel,
    potential: OcmPotential,
    stiffness: [f64; 3],
    offsets_pa: [f64; 3],
    ocms: f64,
    l0: f64,
    d: f64,
}

/// Generalized forces and column quantities at one configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Forces {
    /// Gradient of the potential, `[N, N m, N m]`.
    pub elastic_grad: [f64; 3],
    /// Column tensions `dPi/dl_i` (eq 3.9 for a column), newtons.
    pub column_tension_n: [f64; 3],
    /// Whether a column is beyond the modelled range (on its end stop).
    pub on_end_stop: bool,
}

/// Elastic forces as `x0 + sum_i P_i dx/dP_i`: the energy is affine in
/// the pressures (eq 3.7), which makes the static inverse one linear solve.
#[derive(Debug, Clone, Copy, Default)]
struct Affine {
    grad0: [f64; 3],
    dgrad_dp: [[f64; 3]; 3],
    tension0: [f64; 3],
    dtension_dp: [f64; 3],
    on_stop: bool,
}

impl Affine {
    fn at(&self, p: [f64; 3]) -> Forces {
        let mut grad = self.grad0;
        for i in 0..3 {
            for k in 0..3 {
                grad[k] += p[i] * self.dgrad_dp[i][k];
            }
        }
        Forces {
            elastic_grad: grad,
            column_tension_n: std::array::from_fn(|i| {
                self.tension0[i] + p[i] * self.dtension_dp[i]
            }),
            on_end_stop: self.on_stop,
        }
    }
}

/// Evolving state of the plant.
#[derive(Debug, Clone)]
pub struct PlantState {
    /// Time, seconds.
    pub time_s: f64,
    /// Configuration.
    pub q: Config,
    /// Rate of the configuration `[m/s, rad/s, rad/s]`.
    pub qdot: [f64; 3],
    /// Regulators, one per chamber.
    pub regulators: [Regulator; 3],
    /// Hysteresis states, one per column.
    pub hysteresis: [BoucWen; 3],
    /// Chamber connected to its regulator (false during a supply cut).
    pub connected: [bool; 3],
    /// Load on the plate.
    pub load: PlateLoad,
    /// The configuration a step last left and its [`Turn`]: the tip, the
    /// IMU and the next step's Jacobian all need that trigonometry.
    turn: (Config, Turn),
}

fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if !d.is_finite() || d.abs() < 1e-300 {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *xk = det(m) / d;
    }
    Some(x)
}

/// `(x cos x - sin x) / x^3`, i.e. `sinc'(x) / x`, exact through zero,
/// from `sin x` and `cos x`.
fn dsinc_over_x(x: f64, sin: f64, cos: f64) -> f64 {
    if x.abs() < 1e-3 {
        -1.0 / 3.0 + x * x / 30.0
    } else {
        (x * cos - sin) / (x * x * x)
    }
}

/// Closed-form Jacobian of [`Config::position`]: with `f = sinc^2(th/2)/2`,
/// `p_xy = S f b` and `p_z = S sinc(th)`.
pub fn position_jacobian(q: &Config) -> [[f64; 3]; 3] {
    position_jacobian_with(q, &q.turn())
}

/// [`position_jacobian`] from the configuration's [`Turn`].
pub fn position_jacobian_with(q: &Config, turn: &Turn) -> [[f64; 3]; 3] {
    let (s, b) = (q.backbone_m, [q.bend_x_rad, q.bend_y_rad]);
    let (th, half) = (turn.theta_rad, turn.half_rad);
    // One sine and cosine of the half angle give those of the whole.
    let (s_half, c_half) = (turn.sin_half, turn.cos_half);
    let (s_th, c_th) = (2.0 * s_half * c_half, 1.0 - 2.0 * s_half * s_half);
    let sh = sinc_from_sin(half, s_half);
    let f = 0.5 * sh * sh;
    // f'(th)/th and sinc'(th)/th, both regular at th = 0.
    let df_over = 0.25 * sh * dsinc_over_x(half, s_half, c_half);
    let dz_over = dsinc_over_x(th, s_th, c_th);
    let mut j = [[0.0; 3]; 3];
    for r in 0..2 {
        j[r][0] = f * b[r];
        for c in 0..2 {
            let delta = if r == c { 1.0 } else { 0.0 };
            j[r][c + 1] = s * (f * delta + df_over * b[r] * b[c]);
        }
    }
    j[2][0] = sinc_from_sin(th, s_th);
    j[2][1] = s * dz_over * b[0];
    j[2][2] = s * dz_over * b[1];
    j
}

/// Solves the 3x3 system `a x = b` (Cramer), `None` when singular.
pub fn solve_3x3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    solve3(a, b)
}

impl Plant {
    /// Builds the plant; `seed` draws the manufacturing spread and the
    /// regulator offsets.
    pub fn new(params: PlantParams, seed: u64) -> Result<Self, SimError> {
        let model = OcmModel::new(params.ocm).map_err(|e| SimError::Config(e.to_string()))?;
        let m = &params.manipulator;
        let fx = &params.effects;
        let reg = &params.regulator;
        let at_least = |v: f64, lo: f64| v.is_finite() && v >= lo;
        let above = |v: f64, lo: f64| v.is_finite() && v > lo;
        // each check names its setting, its value and the range (NaN fails every one)
        let checks: [(&str, f64, bool, &str); 15] = [
            (
                "manipulator.column_radius_m",
                m.column_radius_m,
                above(m.column_radius_m, 0.0),
                "> 0",
            ),
            (
                "manipulator.plate_mass_kg",
                m.plate_mass_kg,
                at_least(m.plate_mass_kg, 0.0),
                ">= 0",
            ),
            (
                "manipulator.ocms_per_column",
                f64::from(m.ocms_per_column),
                (1..=8).contains(&m.ocms_per_column),
                "1 to 8",
            ),
            (
                "dt_s",
                params.dt_s,
                above(params.dt_s, 0.0) && params.dt_s <= 0.01,
                "in (0, 0.01]",
            ),
            (
                "plate_inertia_kg_m2",
                params.plate_inertia_kg_m2,
                above(params.plate_inertia_kg_m2, 0.0),
                "> 0",
            ),
            (
                "column_damping_n_s_per_m",
                params.column_damping_n_s_per_m,
                at_least(params.column_damping_n_s_per_m, 0.0),
                ">= 0",
            ),
            (
                "regulator.max_pa",
                reg.max_pa,
                reg.min_pa.is_finite() && reg.max_pa.is_finite() && reg.min_pa < reg.max_pa,
                "finite and above regulator.min_pa",
            ),
            (
                "regulator.time_constant_s",
                reg.time_constant_s,
                above(reg.time_constant_s, 0.0),
                "> 0",
            ),
            (
                "regulator.dead_time_s",
                reg.dead_time_s,
                at_least(reg.dead_time_s, 0.0),
                ">= 0",
            ),
            (
                "end_stop_n_per_m",
                params.end_stop_n_per_m,
                above(params.end_stop_n_per_m, 0.0),
                "> 0",
            ),
            (
                "effects.hysteresis_fraction",
                fx.hysteresis_fraction,
                at_least(fx.hysteresis_fraction, 0.0),
                ">= 0",
            ),
            (
                "effects.hysteresis_reference_n",
                fx.hysteresis_reference_n,
                at_least(fx.hysteresis_reference_n, 0.0),
                ">= 0",
            ),
            (
                "effects.stiffness_spread",
                fx.stiffness_spread,
                at_least(fx.stiffness_spread, 0.0),
                ">= 0",
            ),
            (
                "effects.regulator_offset_pa",
                fx.regulator_offset_pa,
                at_least(fx.regulator_offset_pa, 0.0),
                ">= 0",
            ),
            (
                "effects.hysteresis_yield_m",
                fx.hysteresis_yield_m,
                above(fx.hysteresis_yield_m, 0.0),
                "> 0",
            ),
        ];
        if let Some((name, v, _, range)) = checks.iter().find(|c| !c.2) {
            return Err(SimError::Config(format!(
                "plant parameter {name} = {v} is out of range (must be {range})"
            )));
        }
        let potential = OcmPotential::new(&model)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
        let stiffness = params.effects.column_stiffness(m.ocms_per_column, &mut rng);
        let offsets_pa = params.effects.offsets(&mut rng);
        Ok(Self {
            ocms: f64::from(m.ocms_per_column),
            l0: params.ocm.rest_length_m,
            d: m.column_radius_m,
            params,
            model,
            potential,
            stiffness,
            offsets_pa,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    /// The OCM energy model underneath.
    pub fn model(&self) -> &OcmModel {
        &self.model
    }

    /// Per-column stiffness scales drawn for the manufacturing spread.
    pub fn stiffness_scales(&self) -> [f64; 3] {
        self.stiffness
    }

    /// Per-chamber regulator offsets, pascals.
    pub fn regulator_offsets_pa(&self) -> [f64; 3] {
        self.offsets_pa
    }

    /// Column rest length `n l0`, metres.
    pub fn column_rest_length_m(&self) -> f64 {
        self.ocms * self.l0
    }

    /// Moving mass: plate, lumped OCMs and payload, kilograms.
    pub fn moving_mass_kg(&self, load: &PlateLoad) -> f64 {
        self.params.moving_mass_kg(load)
    }

    /// Total external force on the plate (gravity of the moving mass plus
    /// the tip force), base frame, newtons.
    pub fn external_force_n(&self, load: &PlateLoad) -> [f64; 3] {
        self.params.external_force_n(load)
    }

    /// Plate-position Jacobian `dp/dq` (rows x, y, z; columns S, bx, by),
    /// in closed form from [`Config::position`].
    pub fn position_jacobian(&self, q: &Config) -> [[f64; 3]; 3] {
        position_jacobian(q)
    }

    /// Generalized external force `J_p^T F` of a plate force.
    pub fn generalized_load(&self, q: &Config, force_n: [f64; 3]) -> [f64; 3] {
        let j = self.position_jacobian(q);
        std::array::from_fn(|k| (0..3).map(|r| j[r][k] * force_n[r]).sum())
    }

    /// Strains and per-OCM bend of a configuration.
    fn column_strains(&self, q: &Config) -> ([f64; 3], f64) {
        let l = q.column_lengths(self.d);
        let eps = l.map(|li| li / (self.ocms * self.l0) - 1.0);
        let w = (q.bend_x_rad.powi(2) + q.bend_y_rad.powi(2)) / (self.ocms * self.ocms);
        (eps, w)
    }

    /// Elastic forces split by their affine dependence on the pressures.
    fn affine(&self, q: &Config) -> Affine {
        let (eps, w) = self.column_strains(q);
        let (lo, hi) = OcmPotential::STRAIN_RANGE;
        let w_max = OcmPotential::MAX_BEND_RAD.powi(2);
        let wc = w.min(w_max);
        let mut a = Affine {
            on_stop: w > w_max,
            ..Affine::default()
        };
        let col = self.ocms * self.l0;
        let kw = 2.0 / (self.ocms * self.ocms);
        // dl_i/dq = (1, -d cos b_i, -d sin b_i); dw/db = 2 b / n^2.
        let dl = |i: usize| [1.0, -self.d * COS_BETA[i], -self.d * SIN_BETA[i]];
        let dw = [0.0, kw * q.bend_x_rad, kw * q.bend_y_rad];
        let ecs = eps.map(|e| e.clamp(lo, hi));
        let gs = self.potential.grad3(ecs, wc);
        for i in 0..3 {
            let (ec, g) = (ecs[i], gs[i]);
            let s = self.stiffness[i];
            // Column energy is n times the OCM energy; dl_i = n l0 d eps.
            let mut t0 = self.ocms * s * g.elastic.d_strain / col;
            if ec != eps[i] {
                a.on_stop = true;
                t0 += self.params.end_stop_n_per_m * (eps[i] - ec) * col;
            }
            let tp = -self.ocms * g.volume.d_strain / col;
            let w0 = self.ocms * s * g.elastic.d_w;
            let wp = -self.ocms * g.volume.d_w;
            a.tension0[i] = t0;
            a.dtension_dp[i] = tp;
            let li = dl(i);
            for k in 0..3 {
                a.grad0[k] += t0 * li[k] + w0 * dw[k];
                a.dgrad_dp[i][k] = tp * li[k] + wp * dw[k];
            }
        }
        if w > w_max {
            let k = self.params.end_stop_n_per_m * self.d * self.d;
            let th = w.sqrt() * self.ocms;
            let excess = th - OcmPotential::MAX_BEND_RAD * self.ocms;
            a.grad0[1] += k * excess * q.bend_x_rad / th;
            a.grad0[2] += k * excess * q.bend_y_rad / th;
        }
        a
    }

    /// Elastic forces at `q` under chamber pressures `p_pa`.
    pub fn forces(&self, q: &Config, p_pa: [f64; 3]) -> Forces {
        self.affine(q).at(p_pa)
    }

    /// Elastic potential energy of the columns at `q` (end stops excluded),
    /// joules.
    pub fn elastic_energy_j(&self, q: &Config, p_pa: [f64; 3]) -> f64 {
        let (eps, w) = self.column_strains(q);
        (0..3)
            .map(|i| {
                let g = self.potential.eval(eps[i], w);
                self.ocms * (self.stiffness[i] * g.elastic.value - p_pa[i] * g.volume.value)
            })
            .sum()
    }

    /// Mechanical energy: kinetic + elastic + potential of the external
    /// force field (constant force), joules.
    pub fn mechanical_energy_j(&self, s: &PlantState) -> f64 {
        let m = self.mass_matrix(&s.q, &s.load);
        let v = s.qdot;
        let kin: f64 = 0.5
            * (0..3)
                .map(|r| (0..3).map(|c| v[r] * m[r][c] * v[c]).sum::<f64>())
                .sum::<f64>();
        let p = s.q.position();
        let f = self.external_force_n(&s.load);
        let pot_ext = -(0..3).map(|k| f[k] * p[k]).sum::<f64>();
        kin + self.elastic_energy_j(&s.q, s.pressures_pa()) + pot_ext
    }

    /// Mass matrix at `q`.
    pub fn mass_matrix(&self, q: &Config, load: &PlateLoad) -> [[f64; 3]; 3] {
        self.mass_matrix_with(&self.position_jacobian(q), load)
    }

    fn mass_matrix_with(&self, j: &[[f64; 3]; 3], load: &PlateLoad) -> [[f64; 3]; 3] {
        let m = self.moving_mass_kg(load);
        let mut out = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                out[r][c] = m * (0..3).map(|k| j[k][r] * j[k][c]).sum::<f64>();
            }
        }
        out[1][1] += self.params.plate_inertia_kg_m2;
        out[2][2] += self.params.plate_inertia_kg_m2;
        out
    }

    /// Residual of the static balance at `q`: elastic gradient minus the
    /// generalized load (hysteresis forces `f_h` added to the tensions).
    pub fn static_residual(
        &self,
        q: &Config,
        p_pa: [f64; 3],
        load: &PlateLoad,
        hyst_n: [f64; 3],
    ) -> [f64; 3] {
        let f = self.forces(q, p_pa);
        let g = self.generalized_load(q, self.external_force_n(load));
        let h = self.column_generalized(hyst_n);
        std::array::from_fn(|k| f.elastic_grad[k] + h[k] - g[k])
    }

    /// Generalized force of column tensions `t` (`sum t_i dl_i/dq`).
    fn column_generalized(&self, t: [f64; 3]) -> [f64; 3] {
        let mut g = [0.0; 3];
        for i in 0..3 {
            g[0] += t[i];
            g[1] -= t[i] * self.d * COS_BETA[i];
            g[2] -= t[i] * self.d * SIN_BETA[i];
        }
        g
    }

    /// Static equilibrium under pressures `p_pa` and `load` by damped
    /// Newton iteration from `start` (finite-difference Jacobian).
    pub fn static_equilibrium(
        &self,
        p_pa: [f64; 3],
        load: &PlateLoad,
        start: Config,
    ) -> Result<Config, SimError> {
        let mut q = start.to_array();
        let res = |a: [f64; 3]| self.static_residual(&Config::from_array(a), p_pa, load, [0.0; 3]);
        let norm =
            |r: [f64; 3]| (r[0] * r[0] + (r[1] / self.d).powi(2) + (r[2] / self.d).powi(2)).sqrt();
        let mut r = res(q);
        for _ in 0..100 {
            if norm(r) < 1e-10 {
                return Ok(Config::from_array(q));
            }
            let mut jac = [[0.0; 3]; 3];
            for k in 0..3 {
                let h = if k == 0 { 1e-7 } else { 1e-6 };
                let (mut ap, mut am) = (q, q);
                ap[k] += h;
                am[k] -= h;
                let (rp, rm) = (res(ap), res(am));
                for row in 0..3 {
                    jac[row][k] = (rp[row] - rm[row]) / (2.0 * h);
                }
            }
            let Some(dx) = solve3(jac, r) else { break };
            let mut step = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                let cand: [f64; 3] = std::array::from_fn(|k| q[k] - step * dx[k]);
                let rc = res(cand);
                if norm(rc) < norm(r) {
                    q = cand;
                    r = rc;
                    accepted = true;
                    break;
                }
                step *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        if norm(r) < 1e-7 {
            Ok(Config::from_array(q))
        } else {
            Err(SimError::NoEquilibrium(format!(
                "pressures {p_pa:?} Pa, load {load:?}: residual {:.3e}",
                norm(r)
            )))
        }
    }

    /// Pressures that hold `q` at rest under `load` with hysteresis forces
    /// `hyst_n` (the exact static inverse, linear in the pressures because
    /// the energy is affine in them). Unclamped.
    pub fn pressures_for(
        &self,
        q: &Config,
        load: &PlateLoad,
        hyst_n: [f64; 3],
    ) -> Result<[f64; 3], SimError> {
        let a = self.affine(q);
        let g = self.generalized_load(q, self.external_force_n(load));
        let h = self.column_generalized(hyst_n);
        let m: [[f64; 3]; 3] = std::array::from_fn(|k| std::array::from_fn(|i| a.dgrad_dp[i][k]));
        let rhs: [f64; 3] = std::array::from_fn(|k| g[k] - h[k] - a.grad0[k]);
        solve3(m, rhs)
            .ok_or_else(|| SimError::NoEquilibrium(format!("configuration {q:?} cannot be held")))
    }

    /// A state at rest at `q` with the chambers at `p_pa`.
    pub fn state_at(&self, q: Config, p_pa: [f64; 3], load: PlateLoad) -> PlantState {
        let dt = self.params.dt_s;
        PlantState {
            time_s: 0.0,
            q,
            qdot: [0.0; 3],
            regulators: std::array::from_fn(|i| {
                Regulator::new(
                    self.params.regulator,
                    dt,
                    p_pa[i] - self.offsets_pa[i],
                    self.offsets_pa[i],
                )
            }),
            hysteresis: [BoucWen::default(); 3],
            connected: [true; 3],
            load,
            turn: (q, q.turn()),
        }
    }

    /// Elongations of the three columns from their rest length in state `s`, metres.
    pub fn column_elongations_m(&self, s: &PlantState) -> [f64; 3] {
        let rest = self.column_rest_length_m();
        s.q.column_lengths(self.d).map(|l| l - rest)
    }

    /// Sensitivity of the plate position to each column's elongation in state `s`,
    /// `d p_r / d e_j` (rows x, y, z; columns 1-3; metres per metre): the position Jacobian
    /// times the configuration's linear map from column lengths (eq 3.26). Logged beside the
    /// elongations so an identification can take the kinematics as exact.
    pub fn tip_sensitivity_to_elongations(&self, s: &PlantState) -> [[f64; 3]; 3] {
        let jp = position_jacobian(&s.q);
        // the map from lengths to (S, bx, by) is linear: its columns are unit lengths' images
        let dq: [[f64; 3]; 3] = std::array::from_fn(|j| {
            let mut l = [0.0; 3];
            l[j] = 1.0;
            Config::from_column_lengths(l, self.d).to_array()
        });
        std::array::from_fn(|r| std::array::from_fn(|j| (0..3).map(|k| jp[r][k] * dq[j][k]).sum()))
    }

    /// Hysteresis force amplitude `F_h` (half the loop width), newtons.
    fn hysteresis_amplitude_n(&self) -> f64 {
        let e = &self.params.effects;
        0.5 * e.hysteresis_fraction * e.hysteresis_reference_n
    }

    /// Current hysteresis tensions of the columns, newtons.
    pub fn hysteresis_n(&self, s: &PlantState) -> [f64; 3] {
        let a = self.hysteresis_amplitude_n();
        std::array::from_fn(|i| a * s.hysteresis[i].z)
    }

    /// Advances the state by one step with regulator commands `command_pa`.
    pub fn step(&self, s: &mut PlantState, command_pa: [f64; 3]) {
        let dt = self.params.dt_s;
        for i in 0..3 {
            s.regulators[i].step(command_pa[i], s.connected[i], dt);
        }
        let p = s.pressures_pa();
        let f = self.forces(&s.q, p);
        let jac = position_jacobian_with(&s.q, &s.turn());
        let fe = self.external_force_n(&s.load);
        let ext: [f64; 3] = std::array::from_fn(|k| (0..3).map(|r| jac[r][k] * fe[r]).sum());
        let d = self.d;
        let ldot: [f64; 3] = std::array::from_fn(|i| {
            s.qdot[0] - d * (COS_BETA[i] * s.qdot[1] + SIN_BETA[i] * s.qdot[2])
        });
        let hyst = self.hysteresis_n(s);
        let c = self.params.column_damping_n_s_per_m;
        let resist = self.column_generalized(std::array::from_fn(|i| hyst[i] + c * ldot[i]));
        let q_total: [f64; 3] = std::array::from_fn(|k| ext[k] - f.elastic_grad[k] - resist[k]);
        let m = self.mass_matrix_with(&jac, &s.load);
        let acc = solve3(m, q_total).unwrap_or([0.0; 3]);
        for k in 0..3 {
            s.qdot[k] += dt * acc[k];
        }
        let before = s.q.column_lengths(d);
        let mut a = s.q.to_array();
        for k in 0..3 {
            a[k] += dt * s.qdot[k];
        }
        s.q = Config::from_array(a);
        s.turn = (s.q, s.q.turn());
        let after = s.q.column_lengths(d);
        if self.params.effects.hysteresis_fraction > 0.0 {
            let y = self.params.effects.hysteresis_yield_m;
            for i in 0..3 {
                s.hysteresis[i].step((after[i] - before[i]) / y, COLUMN_LOOP);
            }
        }
        s.time_s += dt;
    }
}

impl PlantState {
    /// Chamber gauge pressures, pascals.
    pub fn pressures_pa(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.regulators[i].pressure_pa())
    }

    /// The [`Turn`] of the configuration `q`: kept from the last step unless
    /// `q` was set since.
    pub fn turn(&self) -> Turn {
        match self.turn {
            (q, t) if q == self.q => t,
            _ => self.q.turn(),
        }
    }

    /// Plate-centre position, metres ([`Config::position`] of `q`).
    pub fn position(&self) -> [f64; 3] {
        self.q.position_with(&self.turn())
    }
}
