//! The contact solver against closed-form contact mechanics and its own guarantees.

use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::indent::{IndentOptions, Indentation, Placement, StepOutput};
use ocm_tactile::shapes;

const E: f64 = 1e5;
const NU: f64 = 0.3;

/// The graded quarter block of `shapes::quarter_block` with this file's material.
fn quarter_block(n: usize, l: f64, h: f64, fine: f64) -> Gel {
    shapes::quarter_block(n, l, h, fine, E, NU).unwrap()
}

fn options(steps: usize, step_m: f64) -> IndentOptions {
    let mut o = IndentOptions::protocol(E);
    o.steps = steps;
    o.step_m = step_m;
    o
}

fn check_solver_guarantees(out: &[StepOutput], o: &IndentOptions) {
    for s in out {
        assert!(
            s.max_penetration_m <= o.contact.penetration_tol_m,
            "step {}: penetration {} m",
            s.step,
            s.max_penetration_m
        );
        assert!(
            s.newton_iterations <= 60,
            "step {}: {} iterations",
            s.step,
            s.newton_iterations
        );
    }
}

/// Relative force error allowed on the fast tensor-product test block of the flat punch (16^3
/// graded hexes, 8 mm): linear tets on this mesh are stiffer than the continuum.
const FAST_TOL: f64 = 0.15;

/// Hertz: a rigid sphere R = 2 mm on an elastic half-space, F = 4/3 E* R^1/2 delta^3/2 (a quarter
/// model with symmetry planes), on the shell-graded block of `shapes::shell_quarter_block`
/// (6 x 6 hexes per shell face, a 0.2 mm core, 75 shells out to 32 mm, 9,868 nodes): within
/// 5 % at delta/R = 0.01, within 9 % at 0.05 and 0.1 (measured +3.8, +6.7 and +7.6 %; the
/// `hertz_study` example and the README show the error falling with the radial refinement
/// and the block size), and F grows as delta^3/2 within 3 %.
#[test]
fn hertz_sphere() {
    let r = 2e-3;
    let gel = shapes::shell_quarter_block(6, 75, 0.2e-3, 32e-3, E, NU).unwrap();
    let sphere = shapes::sphere(r, 48).unwrap();
    let o = options(10, 0.02e-3);
    let place = Placement {
        xy_m: [0.0, 0.0],
        euler_deg: [0.0; 3],
    };
    let mut ind = Indentation::new("hertz", &gel, &sphere, place, o).unwrap();
    let out = ind.run(|_| {}).unwrap();
    check_solver_guarantees(&out, &o);
    let e_star = E / (1.0 - NU * NU);
    let mut f = vec![];
    for (s, tol) in [(&out[0], 0.05), (&out[4], 0.09), (&out[9], 0.09)] {
        let d = s.depth_m;
        let hertz = 4.0 / 3.0 * e_star * r.sqrt() * d.powf(1.5);
        f.push(4.0 * s.indenter_force_n[2]);
        let rel = (f[f.len() - 1] - hertz) / hertz;
        println!(
            "delta/R {:.3}: F {:.5} N, Hertz {hertz:.5} N, {:+.2} %",
            d / r,
            f[f.len() - 1],
            100.0 * rel
        );
        assert!(rel.abs() < tol, "delta/R {}: {:+.2} %", d / r, 100.0 * rel);
    }
    let exponent = (f[2] / f[1]).ln() / 2f64.ln();
    println!("force exponent {exponent:.3} (Hertz 1.5)");
    assert!((exponent - 1.5).abs() < 0.03 * 1.5, "{exponent}");
}

/// Flat cylindrical punch (Boussinesq): F = 2 a E* delta, linear in delta.
#[test]
fn flat_punch() {
    let a = 1e-3;
    let gel = quarter_block(16, 8e-3, 8e-3, 0.1);
    let punch = shapes::cylinder(a, 1e-3, 128).unwrap();
    let o = options(2, 0.01e-3);
    let place = Placement {
        xy_m: [0.0, 0.0],
        euler_deg: [0.0; 3],
    };
    let mut ind = Indentation::new("punch", &gel, &punch, place, o).unwrap();
    let out = ind.run(|_| {}).unwrap();
    check_solver_guarantees(&out, &o);
    let e_star = E / (1.0 - NU * NU);
    for s in &out {
        let exact = 2.0 * a * e_star * s.depth_m;
        let f = 4.0 * s.indenter_force_n[2];
        let rel = (f - exact) / exact;
        println!(
            "delta {:.4} mm: F {f:.5} N, 2aE*d {exact:.5} N, {:+.2} %",
            s.depth_m * 1e3,
            100.0 * rel
        );
        assert!(rel.abs() < FAST_TOL, "{:+.2} %", 100.0 * rel);
    }
    let ratio = out[1].indenter_force_n[2] / out[0].indenter_force_n[2];
    assert!(
        (ratio - 2.0).abs() < 0.01,
        "punch force is linear in depth: {ratio}"
    );
}

/// A 4 x 4 x 2 mm block with its base clamped.
fn small_block() -> Gel {
    let mesh = ocm_fem::mesh::generate::box_mesh([8, 8, 4], [4e-3, 4e-3, 2e-3]);
    Gel::from_mesh(mesh, GelMaterial::new(E, NU), 1e-9).unwrap()
}

/// Above the gel nothing happens: zero force, zero displacement, no active node.
#[test]
fn no_force_without_contact() {
    let gel = small_block();
    let ball = shapes::sphere(1e-3, 16).unwrap();
    let o = options(1, 0.02e-3);
    let place = Placement {
        xy_m: [2e-3, 2e-3],
        euler_deg: [0.0; 3],
    };
    let mut ind = Indentation::new("gap", &gel, &ball, place, o).unwrap();
    for gap in [0.2e-3, 1e-6] {
        let s = ind.advance_to(-gap).unwrap();
        assert_eq!(s.active_nodes, 0);
        assert_eq!(s.indenter_force_n, [0.0; 3]);
        assert!(s.displacement.iter().flatten().all(|&u| u == 0.0));
    }
    // Touching it does produce a force, so the zero above is not vacuous.
    let s = ind.advance_to(0.02e-3).unwrap();
    assert!(s.indenter_force_n[2] > 0.0 && s.active_nodes > 0);
}

/// A flat face tilted by 5 degrees about x, its lowest edge off the gel: frictionless, every
/// contact force is along the face normal, so F_y / F_z = tan 5 deg; with friction (mu = 1)
/// the surface sticks, slides less and the ratio departs from tan 5 deg.
#[test]
fn friction_against_frictionless_on_a_tilted_face() {
    let gel = small_block();
    let plate = shapes::block(4e-3, 4e-3, 1e-3).unwrap();
    let theta: f64 = 5.0;
    // Box centre offset so its lowest edge (y = -4 mm in the box, turned) lies at y = -1 mm.
    let c = theta.to_radians().cos();
    let place = Placement {
        xy_m: [2e-3, -1e-3 + 4e-3 * c],
        euler_deg: [theta, 0.0, 0.0],
    };
    let mut slips = vec![];
    for mu in [0.0, 1.0] {
        let mut o = options(5, 0.04e-3);
        o.contact.friction = mu;
        let mut ind = Indentation::new("tilt", &gel, &plate, place, o).unwrap();
        let out = ind.run(|_| {}).unwrap();
        check_solver_guarantees(&out, &o);
        let last = out.last().unwrap();
        let f = last.indenter_force_n;
        let ratio = f[1] / f[2];
        let tan = theta.to_radians().tan();
        println!(
            "mu {mu}: F = {f:?}, Fy/Fz {ratio:.5}, tan {tan:.5}, slipping {}",
            last.slipping_nodes
        );
        // Mean |u_y| of the nodes in contact at the end: the tangential slide along the face.
        let (mut s, mut n) = (0.0, 0.0);
        for (u, fc) in last.displacement.iter().zip(&last.contact_force) {
            if fc.iter().any(|&v| v != 0.0) {
                s += u[1].abs();
                n += 1.0;
            }
        }
        slips.push(s / n);
        if mu == 0.0 {
            assert!((ratio.abs() - tan).abs() < 0.01 * tan, "{ratio} vs {tan}");
        } else {
            assert!(
                (ratio.abs() - tan).abs() > 0.05 * tan,
                "friction changes the force direction"
            );
        }
    }
    println!(
        "mean |u_y| in contact: frictionless {:.3e} m, mu = 1 {:.3e} m",
        slips[0], slips[1]
    );
    assert!(slips[1] < 0.5 * slips[0]);
}

/// A flat plate pressed into a crowned block touches it around the apex first: at depth delta
/// every node carrying contact force lies within the geometric overlap of the paraboloid,
/// sqrt(2 R delta), plus one element of the apex, while on the flat block the same plate
/// presses nodes out to the block's corners.
#[test]
fn a_crowned_gel_is_pressed_from_its_apex_outwards() {
    use ocm_tactile::gel::Crown;
    let material = GelMaterial::new(E, NU);
    let apex = [2e-3, 2e-3];
    let radius = 10e-3;
    let flat = ocm_fem::mesh::generate::box_mesh([8, 8, 4], [4e-3, 4e-3, 2e-3]);
    let mut crowned = flat.clone();
    Crown {
        radius_m: radius,
        apex_m: apex,
    }
    .apply(&mut crowned, 1e-9)
    .unwrap();
    let plate = shapes::block(4e-3, 4e-3, 1e-3).unwrap();
    let place = Placement {
        xy_m: apex,
        euler_deg: [0.0; 3],
    };
    // Distance from the apex of the farthest node carrying contact force at each depth.
    let reach = |mesh: ocm_fem::mesh::Mesh, depths: &[f64]| -> Vec<f64> {
        let gel = Gel::from_mesh(mesh, material, 1e-9).unwrap();
        let mut ind = Indentation::new("crown", &gel, &plate, place, options(1, 0.02e-3)).unwrap();
        depths
            .iter()
            .map(|&d| {
                let s = ind.advance_to(d).unwrap();
                assert!(s.active_nodes > 0, "depth {d}: no contact");
                s.contact_force
                    .iter()
                    .zip(&gel.mesh.points)
                    .filter(|(f, _)| f[2].abs() > 0.0)
                    .map(|(_, p)| (p[0] - apex[0]).hypot(p[1] - apex[1]))
                    .fold(0.0, f64::max)
            })
            .collect()
    };
    let depths = [0.02e-3, 0.06e-3];
    let crowned_reach = reach(crowned, &depths);
    let element = 0.5e-3 * 2f64.sqrt();
    for (d, r) in depths.iter().zip(&crowned_reach) {
        let geometric = (2.0 * radius * d).sqrt();
        assert!(
            *r <= geometric + element,
            "depth {d}: contact reaches {r} m from the apex (overlap {geometric} m)"
        );
    }
    assert!(crowned_reach[1] > crowned_reach[0], "{crowned_reach:?}");
    let flat_reach = reach(flat, &depths[..1]);
    assert!(
        flat_reach[0] > 2.5e-3,
        "the flat block is pressed all over: {flat_reach:?}"
    );
}

/// A Newton solve that converges on its last allowed iteration converges: with the least
/// iteration limit at which a one-solve step succeeds, that step took exactly the limit (the
/// check after the last iteration used to be skipped, so a step converged on its last
/// iteration was reported as "Newton iteration limit reached" with its residual below target).
#[test]
fn newton_may_converge_on_its_last_iteration() {
    let gel = small_block();
    let ball = shapes::sphere(1e-3, 16).unwrap();
    let place = Placement {
        xy_m: [2e-3, 2e-3],
        euler_deg: [0.0; 3],
    };
    let mut least = None;
    for limit in 1..=30 {
        let mut o = options(1, 0.05e-3);
        o.max_newton = limit;
        o.max_cuts = 0;
        o.held_plane_retry = false;
        let mut ind = Indentation::new("last", &gel, &ball, place, o).unwrap();
        if let Ok(s) = ind.advance_to(0.05e-3) {
            least = Some((limit, s));
            break;
        }
    }
    let (limit, s) = least.expect("no iteration limit up to 30 converges");
    assert!(limit > 1, "a one-iteration solve tests nothing");
    assert_eq!(s.multiplier_updates, 0, "one Newton solve per step");
    assert_eq!(s.newton_iterations, limit);
}
