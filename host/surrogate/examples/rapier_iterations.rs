//! What limits the rapier scene's speed: steps per second of one scene on one thread with and
//! without a plate, and the plate's force on the TCP sensor once the robot pushes into it
//! (extensions commanded to their 20 mm limit, plate 20 mm above the sensor at rest), at 1, 2 and
//! 4 constraint-solver iterations.
//! `cargo run -p ocm-surrogate --example rapier_iterations -- MODEL.json [STEPS]`
use ocm_surrogate::chain::N_JOINTS;
use ocm_surrogate::model::SurrogateModel;
use ocm_surrogate::sim::{SceneConfig, Sim, Surface};
fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let m = SurrogateModel::read(std::path::Path::new(&a[0])).expect("model");
    let steps: usize = a.get(1).map_or(2000, |s| s.parse().expect("steps"));
    let g = m.geometry.chain;
    let cfg0 = SceneConfig::default();
    let top = g.tcp(&[0.0; N_JOINTS]).z + cfg0.tcp_sensor_radius_m + 0.02;
    for plate in [false, true] {
        for iterations in [4, 2, 1] {
            let cfg = SceneConfig {
                surfaces: if plate {
                    vec![Surface::Plane { height_m: top }]
                } else {
                    vec![]
                },
                solver_iterations: iterations,
                ..cfg0.clone()
            };
            let mut sim = Sim::new(&g, &m.limits, cfg).expect("scene");
            let mut q = [0.0; N_JOINTS];
            for j in [2, 5, 8] {
                q[j] = m.limits.prismatic_m[1];
            }
            sim.command(&q).expect("command");
            let t = std::time::Instant::now();
            for _ in 0..steps {
                sim.step();
            }
            let rate = steps as f64 / t.elapsed().as_secs_f64();
            println!(
                "plate {plate}, {iterations} iterations: {rate:.0} steps/s, TCP force z {:.2} N",
                sim.tcp_force().z
            );
        }
    }
}
