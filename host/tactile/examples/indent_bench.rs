//! Seconds per indentation step of the full FEM on a DIGIT mesh (issue goal: at most 1 s per
//! step on DIGIT_v8), wall and process CPU time, per step and as medians.
//!
//! `cargo run -p ocm-tactile --example indent_bench -- [SETUP] [STEPS] [STEP_UM] [MESH]`
//! (defaults edge6, 30 steps of 10 um, DIGIT_v8.vtk; the data folder from `OCM_DATA_DIR` or
//! ../shared/data).

use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::indent::{IndentOptions, Indentation};
use ocm_tactile::indenter::Indenter;
use ocm_tactile::setup::digit_setups;

/// CPU seconds used by this process so far (user + system), from /proc (Linux).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    let tick = |k: usize| {
        f.get(k)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    // Fields 14 and 15 of the stat line (utime, stime), counted after the name's ')'.
    (tick(11) + tick(12)) / 100.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("edge6", String::as_str);
    let steps: usize = args.get(1).map_or(Ok(30), |v| v.parse())?;
    let step_um: f64 = args.get(2).map_or(Ok(10.0), |v| v.parse())?;
    let mesh = args.get(3).map_or("DIGIT_v8.vtk", String::as_str);
    let data = ocm_datadir::data_dir(None)?;
    let digit = data.join("digit");
    let material = GelMaterial::default();
    let gel = Gel::digit(digit.join(mesh), material)?;
    let setup = digit_setups(&digit)?
        .into_iter()
        .find(|s| s.name == name)
        .ok_or_else(|| format!("no set-up '{name}'"))?;
    let indenter = Indenter::from_stl(&setup.stl)?;
    let mut o = IndentOptions::protocol(material.young_pa);
    o.steps = steps;
    o.step_m = step_um * 1e-6;
    let mut run = Indentation::new(&setup.name, &gel, &indenter, setup.placement, o)?;
    let (mut wall, mut cpu, mut iters) = (vec![], vec![], vec![]);
    for k in 1..=steps {
        let (t0, c0) = (std::time::Instant::now(), cpu_seconds());
        let s = run.advance_to(k as f64 * o.step_m)?;
        wall.push(t0.elapsed().as_secs_f64());
        cpu.push(cpu_seconds() - c0);
        iters.push(s.newton_iterations as f64);
        println!(
            "step {k}: depth {:.3} mm, {} Newton iterations, {} updates, wall {:.3} s, cpu {:.2} s",
            s.depth_m * 1e3,
            s.newton_iterations,
            s.multiplier_updates,
            wall[k - 1],
            cpu[k - 1]
        );
    }
    println!(
        "{name} on {mesh} ({} nodes), {steps} steps of {step_um} um: median wall {:.3} s/step, \
         median cpu {:.2} s/step (10 ms ticks), median {} Newton iterations/step, total wall {:.1} s",
        gel.num_nodes(),
        ocm_mor::run::median(&wall),
        ocm_mor::run::median(&cpu),
        ocm_mor::run::median(&iters),
        wall.iter().sum::<f64>()
    );
    Ok(())
}
