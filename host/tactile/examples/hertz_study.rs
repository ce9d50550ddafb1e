//! Hertz study: a rigid sphere pressed into the graded quarter block, the force against
//! 4/3 E* R^1/2 d^3/2 at each depth, for a given mesh density, block size and grading, to tell
//! the mesh's share of the error from the finite block's.
//!
//! `cargo run -p ocm-tactile --example hertz_study -- N L_MM FINE [R_MM] [STEPS] [STEP_UM]`
//! (defaults R = 2 mm, 10 steps of 20 um, as the test `hertz_sphere`) on the tensor-product
//! block `shapes::quarter_block`, or
//! `cargo run -p ocm-tactile --example hertz_study -- shell M LAYERS CORE_MM L_MM [R_MM] [STEPS] [STEP_UM]`
//! on the shell-graded block `shapes::shell_quarter_block`.

use ocm_tactile::indent::{IndentOptions, Indentation, Placement};
use ocm_tactile::shapes;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let shell = args.first().is_some_and(|a| a == "shell");
    if shell {
        args.remove(0);
    }
    let get = |k: usize, d: f64| -> Result<f64, Box<dyn std::error::Error>> {
        Ok(match args.get(k) {
            Some(v) => v
                .parse::<f64>()
                .map_err(|e| format!("argument {}: '{v}': {e}", k + 1))?,
            None => d,
        })
    };
    let (e, nu) = (1e5, 0.3);
    let k = if shell { 1 } else { 0 };
    let r = get(3 + k, 2.0)? * 1e-3;
    let steps = get(4 + k, 10.0)? as usize;
    let step = get(5 + k, 20.0)? * 1e-6;
    let (gel, l, first) = if shell {
        let (m, layers) = (get(0, 12.0)? as usize, get(1, 24.0)? as usize);
        let (core, l) = (get(2, 0.2)? * 1e-3, get(3, 8.0)? * 1e-3);
        let gel = shapes::shell_quarter_block(m, layers, core, l, e, nu)?;
        println!(
            "shell block: m {m}, {layers} layers, core {:.3} mm",
            core * 1e3
        );
        (gel, l, core / m as f64)
    } else {
        let (n, l, fine) = (get(0, 16.0)? as usize, get(1, 8.0)? * 1e-3, get(2, 0.08)?);
        let gel = shapes::quarter_block(n, l, l, fine, e, nu)?;
        println!("tensor block: n {n}, fine {fine}");
        (gel, l, l * fine / n as f64)
    };
    let sphere = shapes::sphere(r, 48)?;
    let mut o = IndentOptions::protocol(e);
    o.steps = steps;
    o.step_m = step;
    let place = Placement {
        xy_m: [0.0, 0.0],
        euler_deg: [0.0; 3],
    };
    let t0 = std::time::Instant::now();
    let mut ind = Indentation::new("hertz", &gel, &sphere, place, o)?;
    let out = ind.run(|_| {})?;
    let e_star = e / (1.0 - nu * nu);
    println!(
        "L {:.1} mm, first element {:.1} um, {} nodes, {} tets, {:.1} s",
        l * 1e3,
        first * 1e6,
        gel.num_nodes(),
        gel.mesh.tets.len(),
        t0.elapsed().as_secs_f64()
    );
    for s in &out {
        let d = s.depth_m;
        let hertz = 4.0 / 3.0 * e_star * r.sqrt() * d.powf(1.5);
        let f = 4.0 * s.indenter_force_n[2];
        println!(
            "delta/R {:.3}: a {:.3} mm, F {f:.5} N, Hertz {hertz:.5} N, {:+.2} %",
            d / r,
            (r * d).sqrt() * 1e3,
            100.0 * (f - hertz) / hertz
        );
    }
    Ok(())
}
