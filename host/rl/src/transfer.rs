//! Deployment of a trained policy on another plant, the analogue of Table 4.2's sim-to-real rows
//! (Ch.4.10): the policy's grouped joint command goes through the inverse actuation map
//! (theta to chamber pressures P_S), a moving-average filter over the last commands at the
//! command rate, and drives the plant in pressure space; the policy observes the plant through
//! the environment's scaling ([`crate::env::observation_of`]).
//!
//! Plants: the reduced FEM of `ocm-mor` ([`RomPlant`], a Galerkin/ECSW model stepped implicitly,
//! the load applied as a tip force each step) and the surrogate itself driven through f_SP
//! ([`SurrogatePlant`], which isolates the pressure chain and the filter from the model gap).
//! A plant knows no joints: the policy sees the posture f_SP assigns to the applied pressures
//! and its rate over the command period. On paths with a target force an optional admittance
//! layer ([`Admittance`]) closes the force loop on the measured force between the policy and the
//! inverse map: BC learned from an open-loop expert and does not correct a model gap itself.
//!
//! The chamber-disconnect test of Ch.4.10.4 vents one chamber (0 kPa gauge) for a while in the
//! middle of a run of several laps of the path and measures the time the TCP needs after the
//! reconnection to be back on the path ([`Disconnect`]).

use crate::env::{ObservedState, StepInfo, observation_of};
use crate::error::{Result, RlError};
use crate::eval::{EvalReport, MeanStd};
use crate::reward::combined_reward;
use crate::robot::{Load, Robot};
use crate::tasks::{Episode, POINTS};
use nalgebra::Vector3;
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_fem::solve::dynamics::Integrator;
use ocm_mor::drive::{Input, P_MAX_KPA, P_MIN_KPA};
use ocm_mor::rom::{ReducedModel, ReducedState, Stepper};
use ocm_mor::store::{self, ReducedProbe};
use ocm_mor::xs::XsProbe;
use ocm_surrogate::batch::EnvState;
use ocm_surrogate::chain::{N_JOINTS, Posture};
use ocm_surrogate::mapping::ActuationMap;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::path::Path;
use std::sync::Arc;

/// A plant driven by chamber pressures with a load on its TCP.
pub trait Plant {
    /// Short name for reports (`reduced`, `surrogate`).
    fn name(&self) -> &str;
    /// Back to rest at zero pressure.
    fn reset(&mut self) -> Result<()>;
    /// Advances `duration_s` with the pressures (kPa, held) and the load on the TCP.
    fn advance(&mut self, pressures_kpa: &[f64; 3], load: &Load, duration_s: f64) -> Result<()>;
    /// TCP (m) and its velocity (m/s).
    fn tcp(&self) -> (Vector3<f64>, Vector3<f64>);
}

/// The actuation map as deployment uses it: f_SP and its inverse.
pub trait CommandMap {
    /// Chamber pressures (kPa) for a feasible posture (the inverse of f_SP).
    fn pressures(&self, q: &Posture) -> Result<[f64; 3]>;
    /// The posture of chamber pressures (f_SP).
    fn posture(&self, pressures_kpa: &[f64; 3]) -> Result<Posture>;
}

impl CommandMap for ActuationMap {
    fn pressures(&self, q: &Posture) -> Result<[f64; 3]> {
        Ok(ActuationMap::pressures(self, q)?)
    }
    fn posture(&self, pressures_kpa: &[f64; 3]) -> Result<Posture> {
        Ok(ActuationMap::posture(self, pressures_kpa)?)
    }
}

/// The reduced FEM and its X_S reader, loaded from `ocm mor pod` + `ocm mor reduce` output.
#[derive(Debug, Clone)]
pub struct RomAssets {
    /// The hyper-reduced model.
    pub rom: ReducedModel,
    /// Reads the TCP from reduced coordinates.
    pub probe: ReducedProbe,
}

impl RomAssets {
    /// Loads the basis and ECSW weights in `dir` for the bellows mesh at `mesh` (the mesh
    /// checks the basis' model hash). `gravity_m_s2` > 0 adds the FEM body's own weight (its
    /// density, along -z) as a projected dead load; `ocm mor` builds and scores the model
    /// without gravity (0).
    pub fn load(dir: &Path, mesh: &Path, gravity_m_s2: f64) -> Result<Self> {
        let mor = |e: ocm_mor::MorError| RlError::Invalid(format!("{}: {e}", dir.display()));
        if !(gravity_m_s2 >= 0.0 && gravity_m_s2.is_finite()) {
            return Err(RlError::Invalid(format!(
                "gravity {gravity_m_s2} m/s^2 must be >= 0"
            )));
        }
        let mut b = Bellows::load(mesh, BellowsConfig::default())
            .map_err(|e| RlError::Invalid(format!("{}: {e}", mesh.display())))?;
        let hash = store::model_hash(&b);
        let (v, _) = store::load_basis(dir, &hash, 3 * b.model.num_nodes()).map_err(mor)?;
        let gal = ReducedModel::galerkin(&b.model, v.clone(), &b.top_face).map_err(mor)?;
        let (mut rom, _) = store::load_rom(dir, &gal).map_err(mor)?;
        if gravity_m_s2 > 0.0 {
            b.model.gravity = Vector3::new(0.0, 0.0, -gravity_m_s2);
            let heavy = ReducedModel::galerkin(&b.model, v, &b.top_face).map_err(mor)?;
            rom.gravity = heavy.gravity;
        }
        let probe = ReducedProbe::new(XsProbe::of_bellows(&b), &rom);
        Ok(RomAssets { rom, probe })
    }

    /// A plant on this model stepped with `dt_s` (at most; each command period is cut into
    /// equal steps no longer than it).
    pub fn plant(&self, dt_s: f64, gravity_m_s2: f64) -> Result<RomPlant<'_>> {
        RomPlant::new(&self.rom, &self.probe, dt_s, gravity_m_s2)
    }
}

/// The reduced FEM as a plant: implicit Euler steps of `ocm-mor`'s [`Stepper`] with the load's
/// force on the TCP, evaluated at each step start, applied as the dead tip load on the top face.
pub struct RomPlant<'a> {
    rom: &'a ReducedModel,
    probe: &'a ReducedProbe,
    stepper: Stepper<'a>,
    state: ReducedState,
    dt_s: f64,
    gravity_m_s2: f64,
}

impl<'a> RomPlant<'a> {
    /// A plant at rest.
    pub fn new(
        rom: &'a ReducedModel,
        probe: &'a ReducedProbe,
        dt_s: f64,
        gravity_m_s2: f64,
    ) -> Result<Self> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(RlError::Invalid(format!(
                "reduced-model time step {dt_s} s must be positive"
            )));
        }
        Ok(RomPlant {
            rom,
            probe,
            stepper: Stepper::new(rom, Integrator::ImplicitEuler),
            state: rom.rest_state(),
            dt_s,
            gravity_m_s2,
        })
    }

    /// The reduced state.
    pub fn state(&self) -> &ReducedState {
        &self.state
    }
}

impl Plant for RomPlant<'_> {
    fn name(&self) -> &str {
        "reduced"
    }

    fn reset(&mut self) -> Result<()> {
        self.state = self.rom.rest_state();
        self.stepper = Stepper::new(self.rom, Integrator::ImplicitEuler);
        Ok(())
    }

    fn advance(&mut self, pressures_kpa: &[f64; 3], load: &Load, duration_s: f64) -> Result<()> {
        let n = (duration_s / self.dt_s).ceil().max(1.0) as usize;
        let h = duration_s / n as f64;
        for _ in 0..n {
            let (p, v) = self.tcp();
            let f = load.force(&p, &v, self.gravity_m_s2);
            let input = Input {
                pressure_kpa: *pressures_kpa,
                tip_force_n: [f.x, f.y, f.z],
            };
            self.stepper
                .step(&mut self.state, &input, h)
                .map_err(|e| RlError::Invalid(format!("reduced model step: {e}")))?;
        }
        Ok(())
    }

    fn tcp(&self) -> (Vector3<f64>, Vector3<f64>) {
        let xs = self.probe.compact_state(&self.state.q, &self.state.v);
        let n = xs.len() / 2;
        (
            Vector3::new(xs[0], xs[1], xs[2]),
            Vector3::new(xs[n], xs[n + 1], xs[n + 2]),
        )
    }
}

/// The surrogate driven in pressure space: the position motors take f_SP of the pressures.
pub struct SurrogatePlant<'a> {
    robot: Arc<Robot>,
    map: &'a dyn CommandMap,
    state: EnvState,
}

impl<'a> SurrogatePlant<'a> {
    /// A plant at rest at f_SP(0 kPa).
    pub fn new(robot: Arc<Robot>, map: &'a dyn CommandMap) -> Result<Self> {
        let q = map.posture(&[0.0; 3])?;
        let state = robot.state_at(&q, &q)?;
        Ok(SurrogatePlant { robot, map, state })
    }
}

impl Plant for SurrogatePlant<'_> {
    fn name(&self) -> &str {
        "surrogate"
    }

    fn reset(&mut self) -> Result<()> {
        let q = self.map.posture(&[0.0; 3])?;
        self.state = self.robot.state_at(&q, &q)?;
        Ok(())
    }

    fn advance(&mut self, pressures_kpa: &[f64; 3], load: &Load, duration_s: f64) -> Result<()> {
        let q = self.map.posture(pressures_kpa)?;
        self.robot.command(&mut self.state, &q)?;
        let steps = (duration_s / self.robot.dt_s()).round().max(1.0) as usize;
        self.robot.advance(&mut self.state, load, steps);
        Ok(())
    }

    fn tcp(&self) -> (Vector3<f64>, Vector3<f64>) {
        self.robot.tcp_and_velocity(&self.state)
    }
}

/// One chamber vented for a while (Ch.4.10.4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Disconnect {
    /// Chamber index, 0..3.
    pub chamber: usize,
    /// Start, s after the scored run begins.
    pub start_s: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Back on the path: the error is within this margin of its mean before the cut, mm ...
    pub margin_mm: f64,
    /// ... for this long without a break, s.
    pub hold_s: f64,
}

impl Default for Disconnect {
    /// Chamber 1 cut 5 s into the run for 5 s; back on the path within 1 mm of the error
    /// before the cut, held for 0.5 s.
    fn default() -> Self {
        Disconnect {
            chamber: 0,
            start_s: 5.0,
            duration_s: 5.0,
            margin_mm: 1.0,
            hold_s: 0.5,
        }
    }
}

/// An outer force loop between the policy and the plant (admittance control), for paths with
/// a target force: each command, the normal force error e = n . (F_ref - F) (n the target
/// force's direction, F the measured force of the surroundings on the TCP) moves a task-space
/// offset of the commanded TCP by `gain_m_per_n` e along -n (into the surface when pressing too
/// little), and the policy's action is shifted by the offset through the surrogate statics'
/// action Jacobian. Without a target force the offset stays zero.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Admittance {
    /// Offset per newton of normal force error and command, m/N (an integral gain).
    pub gain_m_per_n: f64,
    /// Largest offset, m.
    pub max_offset_m: f64,
}

impl Default for Admittance {
    /// 0.5 mm per N and command, offsets up to 10 mm. Chosen on two plants: on the reduced FEM
    /// 0.1, 0.2, 0.5 and 1 mm/N give force errors of 0.69, 0.40, 0.24 and 0.21 N on the force
    /// task (its compliance in series with the 5000 N/m contact keeps the loop slow); on the
    /// stiffer surrogate 1 mm/N overshoots (0.45 N against 0.12 N at 0.5 mm/N).
    fn default() -> Self {
        Admittance {
            gain_m_per_n: 5e-4,
            max_offset_m: 0.01,
        }
    }
}

impl Admittance {
    /// The next offset after measuring `force` against `force_target` (N).
    pub fn update(
        &self,
        offset: &Vector3<f64>,
        force: &Vector3<f64>,
        force_target: &Vector3<f64>,
    ) -> Vector3<f64> {
        let Some(n) = force_target.try_normalize(1e-12) else {
            return *offset;
        };
        let e = n.dot(&(force_target - force));
        let next = offset - n * (self.gain_m_per_n * e);
        let len = next.norm();
        if len > self.max_offset_m {
            next * (self.max_offset_m / len)
        } else {
            next
        }
    }

    /// The action whose static TCP is that of `a` moved by `offset` (linearised at `a` under
    /// the target force), clamped to the action box.
    pub fn shift(
        robot: &Robot,
        a: &[f64; 3],
        force_target: &Vector3<f64>,
        offset: &Vector3<f64>,
    ) -> [f64; 3] {
        if offset.norm() == 0.0 {
            return *a;
        }
        let a0 = a.map(|v| v.clamp(-1.0, 1.0));
        let jac = robot.action_jacobian(&a0, force_target);
        let jt = jac.transpose();
        // Damped least squares: near a joint stop a column vanishes.
        let lhs = jt * jac + nalgebra::Matrix3::identity() * 1e-8;
        match lhs.lu().solve(&(jt * offset)) {
            Some(d) => std::array::from_fn(|k| (a0[k] + d[k]).clamp(-1.0, 1.0)),
            None => a0,
        }
    }
}

/// Settings of a deployment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TransferConfig {
    /// Command rate, Hz (one policy action and one pressure command per period).
    pub command_rate_hz: f64,
    /// Moving average over this many pressure commands (1: no filter).
    pub filter_window: usize,
    /// Unscored time before the run during which the policy approaches the first target, s.
    pub settle_s: f64,
    /// Laps of the path (each of [`POINTS`] commands).
    pub laps: usize,
    /// A chamber cut, if any.
    pub disconnect: Option<Disconnect>,
    /// Runs with the TCP ever farther than this from its target count as failures, m.
    pub lost_distance_m: f64,
    /// The outer force loop, if any.
    pub admittance: Option<Admittance>,
}

impl Default for TransferConfig {
    /// 20 Hz (the environments' control rate), a moving average of 3 commands (150 ms), 1 s of
    /// settling, one lap, no cut.
    fn default() -> Self {
        TransferConfig {
            command_rate_hz: 20.0,
            filter_window: 3,
            settle_s: 1.0,
            laps: 1,
            disconnect: None,
            lost_distance_m: 0.05,
            admittance: None,
        }
    }
}

impl TransferConfig {
    fn validate(&self) -> Result<()> {
        let fin = |v: f64, lo: f64| v.is_finite() && v >= lo;
        let mut checks: Vec<(&str, f64, bool, &str)> = vec![
            (
                "command rate (Hz)",
                self.command_rate_hz,
                fin(self.command_rate_hz, 0.0) && self.command_rate_hz > 0.0,
                "> 0",
            ),
            (
                "filter window",
                self.filter_window as f64,
                self.filter_window >= 1,
                ">= 1",
            ),
            (
                "settle time (s)",
                self.settle_s,
                fin(self.settle_s, 0.0),
                ">= 0",
            ),
            ("laps", self.laps as f64, self.laps >= 1, ">= 1"),
        ];
        if let Some(a) = &self.admittance {
            checks.push((
                "admittance gain (m/N)",
                a.gain_m_per_n,
                fin(a.gain_m_per_n, 0.0),
                ">= 0",
            ));
            checks.push((
                "admittance offset (m)",
                a.max_offset_m,
                fin(a.max_offset_m, 0.0),
                ">= 0",
            ));
        }
        if let Some(d) = &self.disconnect {
            // the command line counts chambers from 1
            checks.push((
                "cut chamber",
                d.chamber as f64 + 1.0,
                d.chamber < 3,
                "1, 2 or 3",
            ));
            checks.push(("cut start (s)", d.start_s, fin(d.start_s, 0.0), ">= 0"));
            checks.push((
                "cut duration (s)",
                d.duration_s,
                fin(d.duration_s, 0.0) && d.duration_s > 0.0,
                "> 0",
            ));
            checks.push((
                "cut margin (mm)",
                d.margin_mm,
                fin(d.margin_mm, 0.0),
                ">= 0",
            ));
            checks.push(("cut hold (s)", d.hold_s, fin(d.hold_s, 0.0), ">= 0"));
        }
        match checks.iter().find(|c| !c.2) {
            Some((name, v, _, range)) => Err(RlError::Invalid(format!(
                "deployment setting {name} = {v} is out of range (must be {range})"
            ))),
            None => Ok(()),
        }
    }
}

/// What the chamber cut did to one run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DisconnectRun {
    /// Mean TCP error before the cut, mm.
    pub before_mm: f64,
    /// Mean TCP error during the cut, mm.
    pub during_mm: f64,
    /// Largest TCP error during the cut, mm.
    pub max_during_mm: f64,
    /// Time from the reconnection until the TCP is back on the path, s (`None`: not within the
    /// run).
    pub recovery_s: Option<f64>,
    /// Mean TCP error after the recovery, mm (`None` without recovery).
    pub after_mm: Option<f64>,
}

/// The outcome of a deployment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransferReport {
    /// The plant.
    pub plant: String,
    /// Settings.
    pub config: TransferConfig,
    /// Errors over all scored commands, as the surrogate evaluation reports them.
    pub eval: EvalReport,
    /// Per run, when a chamber was cut.
    pub disconnect: Vec<DisconnectRun>,
    /// Length of the admittance layer's offset over the scored commands, mm (zeros without it).
    pub admittance_offset_mm: MeanStd,
}

/// One scored run: step details and their times since the scored run began (s).
struct Run {
    steps: Vec<StepInfo>,
    times_s: Vec<f64>,
    episode_return: f64,
    lost: bool,
    /// Length of the admittance offset at each scored command, mm.
    offsets_mm: Vec<f64>,
}

/// Chooses an action from the observation and the index of the next target.
type Actor<'a> = dyn FnMut(&[f64], usize) -> Result<[f64; 3]> + 'a;

/// Chooses an action from the episode, the observation and the index of the next target.
pub type EpisodeActor<'a> = dyn FnMut(&Episode, &[f64], usize) -> Result<[f64; 3]> + 'a;

fn run_episode(
    plant: &mut dyn Plant,
    map: &dyn CommandMap,
    robot: &Robot,
    ep: &Episode,
    cfg: &TransferConfig,
    act: &mut Actor,
) -> Result<Run> {
    plant.reset()?;
    let period = 1.0 / cfg.command_rate_hz;
    let gravity = robot.gravity_m_s2();
    let settle = (cfg.settle_s * cfg.command_rate_hz).round() as usize;
    let scored = cfg.laps * POINTS;
    let mut window: VecDeque<[f64; 3]> = VecDeque::with_capacity(cfg.filter_window);
    let mut applied = [0.0; 3];
    let mut q_est = map.posture(&applied)?;
    let mut dq_est = [0.0; N_JOINTS];
    let mut offset = Vector3::zeros();
    let mut run = Run {
        steps: Vec::with_capacity(scored),
        times_s: Vec::with_capacity(scored),
        episode_return: 0.0,
        lost: false,
        offsets_mm: Vec::with_capacity(scored),
    };
    for i in 0..settle + scored {
        let k = i.saturating_sub(settle) % POINTS;
        let (p, v) = plant.tcp();
        let force = ep.load.force(&p, &v, gravity);
        let obs = observation_of(
            robot,
            &ObservedState {
                q: &q_est,
                dq: &dq_est,
                tcp_m: p,
                tcp_velocity_m_s: v,
                force_n: force,
            },
            &ep.targets[k],
            &ep.force_targets[k],
        );
        let a = act(&obs, k)?;
        if let Some(bad) = a.iter().find(|v| !v.is_finite()) {
            return Err(RlError::Invalid(format!(
                "the policy gave a non-finite action {bad}"
            )));
        }
        let a = match &cfg.admittance {
            Some(adm) => {
                let ft = ep.force_targets[k];
                offset = adm.update(&offset, &force, &ft);
                Admittance::shift(robot, &a, &ft, &offset)
            }
            None => a,
        };
        let q_cmd = robot.posture_of(&robot.command_of_action(&a));
        // The valves saturate: the inverse map may extrapolate past the supply range.
        let p_cmd = map
            .pressures(&q_cmd)?
            .map(|x| x.clamp(P_MIN_KPA, P_MAX_KPA));
        if window.len() == cfg.filter_window {
            window.pop_front();
        }
        window.push_back(p_cmd);
        applied =
            std::array::from_fn(|c| window.iter().map(|w| w[c]).sum::<f64>() / window.len() as f64);
        let t = (i as f64 - settle as f64) * period;
        let mut driven = applied;
        if let Some(d) = cfg.disconnect
            && i >= settle
            && t >= d.start_s - 1e-9
            && t < d.start_s + d.duration_s - 1e-9
        {
            driven[d.chamber] = 0.0;
        }
        plant.advance(&driven, &ep.load, period)?;
        let q_new = map.posture(&driven)?;
        dq_est = std::array::from_fn(|j| (q_new[j] - q_est[j]) / period);
        q_est = q_new;
        if i < settle {
            continue;
        }
        let (p, v) = plant.tcp();
        let force = ep.load.force(&p, &v, gravity);
        let target = ep.targets[k];
        let ft = ep.force_targets[k];
        let dq = (p - target).norm();
        if !dq.is_finite() {
            return Err(RlError::Invalid(format!(
                "the {} plant left the finite range at t = {t} s",
                plant.name()
            )));
        }
        let force_err = if ep.task.has_force() {
            (force - ft).norm()
        } else {
            0.0
        };
        run.lost |= dq > cfg.lost_distance_m;
        run.episode_return += combined_reward(ep.task.alpha(), dq, force_err);
        run.times_s.push(t + period);
        run.offsets_mm.push(offset.norm() * 1e3);
        run.steps.push(StepInfo {
            point: k,
            tcp_m: [p.x, p.y, p.z],
            target_m: [target.x, target.y, target.z],
            position_error_m: dq,
            force_n: [force.x, force.y, force.z],
            force_target_n: [ft.x, ft.y, ft.z],
            force_error_n: force_err,
            clipped: a.iter().any(|v| v.abs() > 1.0),
        });
    }
    Ok(run)
}

fn mean(v: &[f64]) -> f64 {
    MeanStd::of(v).mean
}

/// The cut's effect on a run (errors in mm against the step's time, s, at its end).
fn disconnect_run(d: &Disconnect, times_s: &[f64], err_mm: &[f64]) -> DisconnectRun {
    let end = d.start_s + d.duration_s;
    let pick = |lo: f64, hi: f64| -> Vec<f64> {
        times_s
            .iter()
            .zip(err_mm)
            .filter(|(t, _)| **t > lo + 1e-9 && **t <= hi + 1e-9)
            .map(|(_, e)| *e)
            .collect()
    };
    let before = mean(&pick(f64::NEG_INFINITY, d.start_s));
    let during = pick(d.start_s, end);
    let limit = before + d.margin_mm;
    let mut recovery = None;
    for (i, &t) in times_s.iter().enumerate() {
        if t <= end + 1e-9 {
            continue;
        }
        let window: Vec<usize> = (i..times_s.len())
            .take_while(|&j| times_s[j] <= t + d.hold_s + 1e-9)
            .collect();
        let covers = times_s[*window.last().unwrap_or(&i)] >= t + d.hold_s - 1e-9;
        if covers && window.iter().all(|&j| err_mm[j] <= limit) {
            // The step's error is measured at its end: the TCP got there during the step.
            recovery = Some(i);
            break;
        }
    }
    let recovery_s = recovery.map(|i| (times_s[i] - end).max(0.0));
    let after_mm = recovery.map(|i| mean(&err_mm[i..]));
    DisconnectRun {
        before_mm: before,
        during_mm: mean(&during),
        max_during_mm: during.iter().cloned().fold(0.0, f64::max),
        recovery_s,
        after_mm,
    }
}

/// Deploys `act` on `plant` for `episodes` runs; run `e` follows `episode(seed + e)`.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_on_plant(
    plant: &mut dyn Plant,
    map: &dyn CommandMap,
    robot: &Robot,
    cfg: &TransferConfig,
    episodes: usize,
    seed: u64,
    episode: &dyn Fn(u64) -> Episode,
    act: &mut EpisodeActor,
) -> Result<TransferReport> {
    cfg.validate()?;
    let (mut pos, mut force, mut returns) = (vec![], vec![], vec![]);
    let (mut failures, mut first, mut cuts, mut offsets) = (0, vec![], vec![], vec![]);
    for e in 0..episodes {
        let ep = episode(seed.wrapping_add(e as u64));
        if ep.targets.len() != POINTS || ep.force_targets.len() != POINTS {
            return Err(RlError::Invalid(format!(
                "an episode has {POINTS} targets, not {}",
                ep.targets.len()
            )));
        }
        let run = run_episode(plant, map, robot, &ep, cfg, &mut |o, k| act(&ep, o, k))?;
        let err_mm: Vec<f64> = run.steps.iter().map(|s| s.position_error_m * 1e3).collect();
        if let Some(d) = &cfg.disconnect {
            cuts.push(disconnect_run(d, &run.times_s, &err_mm));
        }
        pos.extend_from_slice(&err_mm);
        force.extend(run.steps.iter().map(|s| s.force_error_n));
        returns.push(run.episode_return / cfg.laps as f64);
        failures += usize::from(run.lost);
        offsets.extend_from_slice(&run.offsets_mm);
        if e == 0 {
            first = run.steps;
        }
    }
    Ok(TransferReport {
        plant: plant.name().to_string(),
        config: *cfg,
        eval: EvalReport {
            episodes,
            steps: pos.len(),
            position_error_mm: MeanStd::of(&pos),
            force_error_n: MeanStd::of(&force),
            episode_return: MeanStd::of(&returns),
            failures,
            first_episode: first,
        },
        disconnect: cuts,
        admittance_offset_mm: MeanStd::of(&offsets),
    })
}

/// The expert of eq 4.31 as an actor for [`evaluate_on_plant`]: the inverse of the surrogate's
/// statics for the planned TCP of target `k`, warm-started from its previous answer.
pub fn expert_actor(robot: &Robot) -> impl FnMut(&Episode, &[f64], usize) -> Result<[f64; 3]> + '_ {
    let mut warm = [0.0; 3];
    move |ep, _, k| {
        let (a, _) = robot.inverse(
            &ep.planned_tcp(k),
            &ep.planned_force(k, robot.gravity_m_s2()),
            &warm,
        );
        warm = a;
        Ok(a)
    }
}
