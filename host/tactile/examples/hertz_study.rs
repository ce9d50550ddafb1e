//! Hertz study: a rigid sphere pressed into the graded quarter block, the force against
//! 4/3 E* R^1/2 d^3/2 at each depth, for a given mesh density, block size and grading, to tell
//! the mesh's share of the error from the finite block's.
//!
//! `cargo run -p ocm-tactile --example hertz_study -- N L_MM FINE [R_MM] [STEPS] [STEP_UM]`
//! (defaults R = 2 mm, 10 steps of 20 um, as the test `hertz_sphere`).

use ocm_tactile::indent::{IndentOptions, Indentation, Placement};
use ocm_tactile::shapes;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |k: usize, d: f64| -> Result<f64, Box<dyn std::error::Error>> {
        Ok(match args.get(k) {
            Some(v) => v
                .parse::<f64>()
                .map_err(|e| format!("argument {}: '{v}': {e}", k + 1))?,
            None => d,
        })
    };
    let n = get(0, 16.0)? as usize;
    let l = get(1, 8.0)? * 1e-3;
    let fine = get(2, 0.08)?;
    let r = get(3, 2.0)? * 1e-3;
    let steps = get(4, 10.0)? as usize;
    let step = get(5, 20.0)? * 1e-6;
    let (e, nu) = (1e5, 0.3);
    let gel = shapes::quarter_block(n, l, l, fine, e, nu)?;
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
        "n {n}, L {:.1} mm, fine {fine}, first element {:.1} um, {} nodes, {:.1} s",
        l * 1e3,
        l * fine / n as f64 * 1e6,
        gel.num_nodes(),
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
