//! The time-domain loop: plant, sensors and controller tick by tick.

use std::collections::BTreeMap;
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::SimError;
use crate::mcu::{GroundTruth, Mcu, McuInput};
use crate::metrics::{distance, rms, step_times};
use crate::pcc::{Config, quaternion_error_rad};
use crate::plant::{Plant, PlateLoad};
use crate::sensors::Sensors;

use super::figures::{disconnect_figures, points_figures};
use super::report::LogRow;
use super::setup::setup;
use super::{RunReport, SimConfig};

/// Runs the time-domain scenario `name` with an external controller (the
/// firmware in-process, or a serial link).
pub fn run_with_mcu(name: &str, cfg: &SimConfig, mcu: &mut dyn Mcu) -> Result<RunReport, SimError> {
    cfg.validate()?;
    let plant = Plant::new(cfg.plant, cfg.seed)?;
    simulate(name, &plant, cfg, mcu)
}

pub(super) fn simulate(
    name: &str,
    plant: &Plant,
    cfg: &SimConfig,
    mcu: &mut dyn Mcu,
) -> Result<RunReport, SimError> {
    let su = setup(name, cfg)?;
    let dt = cfg.plant.dt_s;
    let load0 = su.load_at(0.0, cfg);
    let q_start = su.path.config_at(0.0);
    // Every controller starts from the same rest state at the start point.
    let p0 = plant
        .pressures_for(&q_start, &load0, [0.0; 3])?
        .map(|p| p.clamp(cfg.limits.min_pa, cfg.limits.max_pa));
    let q0 = plant.static_equilibrium(p0, &load0, q_start)?;
    let mut state = plant.state_at(q0, p0, load0);
    let mut sensors = Sensors::new(
        cfg.hall,
        cfg.imu,
        cfg.plant.manipulator.column_radius_m,
        f64::from(cfg.plant.manipulator.ocms_per_column),
        ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(0x5e05)),
    );
    let duration = cfg
        .duration_cap_s
        .map_or(su.duration_s, |c| c.min(su.duration_s));
    let steps = (duration / dt).round() as usize;
    // Sized once: no reallocation inside the loop.
    let mut log = Vec::with_capacity(steps / cfg.log_every.max(1) + 1);
    let mut errs = Vec::with_capacity(steps);
    let mut err_t = Vec::with_capacity(steps);
    let mut q_errs = Vec::with_capacity(steps);
    let (mut p_hi, mut p_lo) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut cmd_hi, mut cmd_lo) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut violations = 0usize;
    let start = Instant::now();
    let expected = PlateLoad::default();
    let preview = cfg.preview();
    // The target changes only with each update of the stream: its
    // configuration (an inverse solve) is computed once per update.
    let mut target: Option<(f64, Config)> = None;
    let log_every = cfg.log_every.max(1);
    let mut log_in = 0usize;
    for k in 0..steps {
        let t = k as f64 * dt;
        state.load = su.load_at(t, cfg);
        if let Some((ch, a, b)) = su.cut {
            state.connected[ch] = !(t >= a && t < b);
        }
        let sample = sensors.sample_with(&state.q, &state.turn(), state.pressures_pa());
        // Announced loads reach the controller with the target updates.
        let announced = if cfg.ol_knows_load || su.announced {
            su.load_at(target_time(t, cfg.target_period_s), cfg)
        } else {
            expected
        };
        let target_t = target_time(t, cfg.target_period_s) + preview;
        let target_q = match target {
            Some((at, q)) if at == target_t => q,
            _ => {
                let q = su.path.config_at(target_t);
                target = Some((target_t, q));
                q
            }
        };
        let input = McuInput {
            time_s: t,
            sensors: &sample,
            reference: &su.path,
            target: target_q,
            expected_load: announced,
        };
        let truth = GroundTruth {
            load: state.load,
            hysteresis_n: plant.hysteresis_n(&state),
        };
        let cmd = crate::mcu::tick(mcu, &input, &truth).map_err(|e| SimError::Mcu {
            name: mcu.name().to_string(),
            message: format!("at t = {t:.3} s: {e}"),
        })?;
        plant.step(&mut state, cmd);
        let p = state.pressures_pa();
        for i in 0..3 {
            p_hi = p_hi.max(p[i]);
            p_lo = p_lo.min(p[i]);
            cmd_hi = cmd_hi.max(cmd[i]);
            cmd_lo = cmd_lo.min(cmd[i]);
            let lim = &cfg.plant.regulator;
            // The firmware holds its limits in f32 and commands in Q24.8.
            let tol = 1e-6 * cfg.limits.max_pa.abs().max(cfg.limits.min_pa.abs()) + 1.0 / 128.0;
            if p[i] > lim.max_pa + 1e-9
                || p[i] < lim.min_pa - 1e-9
                || cmd[i] > cfg.limits.max_pa + tol
                || cmd[i] < cfg.limits.min_pa - tol
            {
                violations += 1;
            }
        }
        let tn = state.time_s;
        let tip = state.position();
        let rf = su.path.tip_at(tn);
        let err = distance(tip, rf);
        // k % log_every == 0, counted down rather than divided.
        let logged = log_in == 0;
        log_in = if logged { log_every - 1 } else { log_in - 1 };
        let scored = tn >= su.score_from_s;
        // The orientation error costs a configuration solve: only where used.
        let q_err = if logged || (scored && name == "orientation") {
            quaternion_error_rad(
                state.q.quaternion_with(&state.turn()),
                su.path.config_at(tn).quaternion(),
            )
        } else {
            0.0
        };
        if scored {
            errs.push(err);
            err_t.push(tn);
            q_errs.push(q_err);
        }
        if logged {
            let e = plant.column_elongations_m(&state);
            let de = plant.tip_sensitivity_to_elongations(&state);
            log.push(LogRow {
                t_s: tn,
                ref_x_mm: rf[0] * 1e3,
                ref_y_mm: rf[1] * 1e3,
                ref_z_mm: rf[2] * 1e3,
                x_mm: tip[0] * 1e3,
                y_mm: tip[1] * 1e3,
                z_mm: tip[2] * 1e3,
                err_mm: err * 1e3,
                q_err_rad: q_err,
                cmd1_pa: cmd[0],
                cmd2_pa: cmd[1],
                cmd3_pa: cmd[2],
                p1_pa: p[0],
                p2_pa: p[1],
                p3_pa: p[2],
                hall1: sample.hall_codes[0],
                hall2: sample.hall_codes[1],
                hall3: sample.hall_codes[2],
                load_z_n: state.load.force_n[2],
                e1_mm: e[0] * 1e3,
                e2_mm: e[1] * 1e3,
                e3_mm: e[2] * 1e3,
                dx_de1: de[0][0],
                dx_de2: de[0][1],
                dx_de3: de[0][2],
                dy_de1: de[1][0],
                dy_de2: de[1][1],
                dy_de3: de[1][2],
                dz_de1: de[2][0],
                dz_de2: de[2][1],
                dz_de3: de[2][2],
            });
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let sim_s = steps as f64 * dt;
    let mut figures = BTreeMap::new();
    figures.insert("max_chamber_pa".into(), p_hi);
    figures.insert("min_chamber_pa".into(), p_lo);
    figures.insert("max_command_pa".into(), cmd_hi);
    figures.insert("min_command_pa".into(), cmd_lo);
    figures.insert("limit_violations".into(), violations as f64);
    match name {
        "orientation" => {
            figures.insert("q_rmse_rad".into(), rms(&q_errs));
            figures.insert(
                "q_max_rad".into(),
                q_errs.iter().cloned().fold(0.0, f64::max),
            );
        }
        "points" => points_figures(&su, &err_t, &errs, &mut figures),
        "disconnect" => {
            if let Some((_, a, b)) = su.cut {
                disconnect_figures(a, b, &err_t, &errs, &mut figures);
            }
        }
        "step_load" => {
            let samples: Vec<(f64, f64)> =
                err_t.iter().copied().zip(errs.iter().copied()).collect();
            let peak = errs.iter().cloned().fold(0.0, f64::max);
            // Back within 1 mm for good (the 5 % band of a step response
            // makes no sense when the reference does not move).
            let (_, settle) = step_times(&samples, 0.0, 1e-3);
            figures.insert("max_deviation_mm".into(), peak * 1e3);
            figures.insert(
                "final_error_mm".into(),
                errs.last().copied().unwrap_or(0.0) * 1e3,
            );
            // Never back: the whole observed window, flagged.
            let window = err_t.last().copied().unwrap_or(0.0) - su.score_from_s;
            figures.insert("recovery_s".into(), settle.unwrap_or(window));
            figures.insert("recovered".into(), if settle.is_some() { 1.0 } else { 0.0 });
        }
        _ => {}
    }
    Ok(RunReport {
        controller: mcu.name().to_string(),
        rmse_mm: rms(&errs) * 1e3,
        max_err_mm: errs.iter().cloned().fold(0.0, f64::max) * 1e3,
        figures,
        sim_s,
        realtime_factor: if wall > 0.0 {
            sim_s / wall
        } else {
            f64::INFINITY
        },
        log,
    })
}

/// The time of the last target update at or before `t`.
fn target_time(t: f64, period_s: f64) -> f64 {
    if period_s > 0.0 {
        // The small bias keeps t = k * period on update k despite rounding.
        (t / period_s + 1e-9).floor() * period_s
    } else {
        t
    }
}
