//! PPO from scratch on a task with the approach term and per-action exploration scales (a
//! quick driver for the studies of the README; `ocm rl train` is the user's command).
//!
//! `cargo run -p ocm-rl --example contact_scratch -- MODEL TASK ITERATIONS STD0 STD1 SX SY SD APPROACH LOST_MM OUT`

use ocm_rl::env::{Env, EnvConfig, PHYSICS_DT_S};
use ocm_rl::eval::evaluate;
use ocm_rl::ppo::{self, PpoConfig};
use ocm_rl::robot::Robot;
use ocm_rl::tasks::TaskKind;
use std::path::PathBuf;
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() != 12 {
        return Err("usage: MODEL TASK ITERATIONS STD0 STD1 SX SY SD APPROACH LOST_MM OUT".into());
    }
    let f = |i: usize| a[i].parse::<f64>();
    let robot = Arc::new(Robot::read(&PathBuf::from(&a[1]), PHYSICS_DT_S)?);
    let task = TaskKind::from_name(&a[2]).ok_or("unknown task")?;
    let env_cfg = EnvConfig {
        approach_n_per_m: f(9)?,
        lost_distance_m: f(10)? * 1e-3,
        ..EnvConfig::new(task)
    };
    let cfg = PpoConfig {
        iterations: a[3].parse()?,
        std_start: f(4)?,
        std_end: f(5)?,
        std_scale: [f(6)?, f(7)?, f(8)?],
        ..PpoConfig::default()
    };
    let zero = nalgebra::Vector3::zeros();
    let rest = robot.static_tcp(&[0.0; 3], &zero);
    for k in 0..3 {
        let mut u = [0.0; 3];
        u[k] = 0.1;
        let d = (robot.static_tcp(&u, &zero) - rest) * 1e3 / 0.1;
        eprintln!("action {k}: TCP moves {d:.1} mm per unit at the middle of the range");
    }
    let out = PathBuf::from(&a[11]);
    std::fs::create_dir_all(&out)?;
    let t0 = std::time::Instant::now();
    let (policy, curve) = ppo::train(&robot, &env_cfg, &cfg, |r| {
        if r.eval_return.is_finite() {
            eprintln!(
                "it {} reward {:.3} eval {:.2} {:.2} mm {:.3} N",
                r.iteration,
                r.mean_reward,
                r.eval_return,
                r.eval_position_error_mm,
                r.eval_force_error_n
            );
        }
    })?;
    ppo::write_curve_csv(&out.join("curve.csv"), &curve)?;
    let mut env = Env::new(robot.clone(), EnvConfig::new(task))?;
    let r = evaluate(&mut env, 5, 2_000_000, |_, o| policy.act(o))?;
    println!(
        "{} {:.1} s: {:.3} +- {:.3} mm, {:.3} +- {:.3} N",
        task.name(),
        t0.elapsed().as_secs_f64(),
        r.position_error_mm.mean,
        r.position_error_mm.std,
        r.force_error_n.mean,
        r.force_error_n.std
    );
    Ok(())
}
