//! Tests of the full N-layer bar-and-hinge solver: the stack energy against
//! the uniform model, derivatives against central differences, equilibrium
//! residuals, linearised stiffness, mirror symmetry and Newton's
//! convergence rate.

use ocm_lutgen::geometry::SIDES;
use ocm_lutgen::stack::*;
use ocm_lutgen::{OcmModel, OcmParams};

/// The Table 3.1 OCM with `layers` layers of the standard layer height.
fn model(layers: u32) -> OcmModel {
    let mut p = OcmParams::TABLE_3_1;
    p.rest_length_m = p.rest_length_m / p.layers as f64 * layers as f64;
    p.layers = layers;
    OcmModel::new(p).expect("Table 3.1 parameters are valid")
}

/// Deterministic, seeded perturbation of every node by up to `amp` metres.
fn perturbed(x: &[[f64; 3]], amp: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    x.iter()
        .map(|p| {
            [
                p[0] + amp * next(),
                p[1] + amp * next(),
                p[2] + amp * next(),
            ]
        })
        .collect()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn rotate(axis: [f64; 3], angle: f64, v: [f64; 3]) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let k = axis;
    let kxv = [
        k[1] * v[2] - k[2] * v[1],
        k[2] * v[0] - k[0] * v[2],
        k[0] * v[1] - k[1] * v[0],
    ];
    let kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2];
    core::array::from_fn(|i| v[i] * c + kxv[i] * s + k[i] * kv * (1.0 - c))
}

#[test]
fn stack_energy_at_the_uniform_configuration_is_n_times_the_layer_energy() {
    let model = model(10);
    let stack = Stack::new(&model);
    for strain in [-0.5, 0.0, 0.35] {
        let phi_max = model.max_bend_angle_rad(strain);
        for fraction in [0.0, 0.4, 0.85] {
            let phi = fraction * phi_max;
            let x = stack.uniform_positions(strain, phi);
            for pressure in [0.0, 15e3] {
                let full = stack.energy_j(&x, pressure);
                let uniform = model.energy_j(strain, phi, pressure);
                assert!(
                    (full - uniform).abs() <= 1e-9 * uniform.abs() + 1e-15,
                    "eps {strain} phi {phi} P {pressure}: stack {full} vs N * layer {uniform}"
                );
            }
            // The composed frames put the plate exactly where the closed-form
            // arc and rotation put it.
            let c = stack.uniform_plate_centre_m(strain, phi);
            for (n, d) in stack.plate_nodes().into_iter().zip(stack.plate_offsets_m()) {
                let r = rotate(BEND_AXIS, phi, d);
                let expect = [c[0] + r[0], c[1] + r[1], c[2] + r[2]];
                assert!(dist(x[n], expect) < 1e-12, "plate node {n} misplaced");
            }
        }
    }
}

#[test]
fn neutral_axis_of_the_uniform_map_is_the_arc_length() {
    let model = model(10);
    let stack = Stack::new(&model);
    let l0 = model.params().rest_length_m;
    for strain in [-0.3, 0.2] {
        for phi in [0.0, 0.3, 1.0] {
            let axis = stack.neutral_axis(&stack.uniform_positions(strain, phi));
            let s = l0 * (1.0 + strain);
            assert!(
                (axis.arc_m - s).abs() < 1e-12 * s,
                "arc {} vs {s}",
                axis.arc_m
            );
            // Chords of a circular arc of N equal segments.
            let beta = phi / 10.0;
            let chord = if beta == 0.0 {
                s
            } else {
                10.0 * 2.0 * (s / 10.0 / beta) * (0.5 * beta).sin()
            };
            assert!((axis.polyline_m - chord).abs() < 1e-12 * s);
            // Identical layers.
            assert!(axis.layer_arc_max_m - axis.layer_arc_min_m < 1e-12 * s);
            assert!((axis.layer_turn_max_rad - beta).abs() < 1e-9);
            assert!((axis.layer_turn_min_rad - beta).abs() < 1e-9);
        }
    }
}

#[test]
fn energy_gradient_matches_central_differences() {
    let model = model(3);
    let stack = Stack::new(&model);
    let x = perturbed(&stack.uniform_positions(0.1, 0.4), 3e-4, 7);
    let pressure = 2e3;
    let g = stack.energy_gradient_n(&x, pressure);
    let scale = g
        .iter()
        .flat_map(|v| v.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let h = 1e-7;
    for n in 0..stack.node_count() {
        for d in 0..3 {
            let mut xp = x.clone();
            let mut xm = x.clone();
            xp[n][d] += h;
            xm[n][d] -= h;
            let fd = (stack.energy_j(&xp, pressure) - stack.energy_j(&xm, pressure)) / (2.0 * h);
            assert!(
                (fd - g[n][d]).abs() < 1e-6 * scale,
                "node {n} coord {d}: AD {} vs FD {fd}",
                g[n][d]
            );
        }
    }
}

#[test]
fn hessian_matches_central_differences_of_the_gradient() {
    let model = model(2);
    let stack = Stack::new(&model);
    let x = perturbed(&stack.uniform_positions(-0.1, 0.3), 2e-4, 11);
    let pressure = 1e3;
    let asm = stack.assemble(&x, pressure, true);
    let dim = asm.gradient_n.len();
    assert_eq!(dim, stack.free_node_dofs() + 3);
    // Unknown j moves one free node coordinate, or all plate nodes
    // together for the last three.
    let shift = |j: usize, h: f64| {
        let mut y = x.clone();
        if j < stack.free_node_dofs() {
            y[SIDES + j / 3][j % 3] += h;
        } else {
            for n in stack.plate_nodes() {
                y[n][j - stack.free_node_dofs()] += h;
            }
        }
        y
    };
    let scale = asm.hessian_n_per_m.amax();
    let h = 1e-7;
    for j in (0..dim).step_by(5).chain(dim - 3..dim) {
        let gp = stack.assemble(&shift(j, h), pressure, true).gradient_n;
        let gm = stack.assemble(&shift(j, -h), pressure, true).gradient_n;
        let fd = (gp - gm) / (2.0 * h);
        let col = asm.hessian_n_per_m.column(j);
        let err = (&fd - col).amax();
        assert!(
            err < 1e-5 * scale,
            "column {j}: error {err} (scale {scale})"
        );
    }
    // The gradient over the unknowns is the node gradient gathered.
    let plate_sum: f64 = stack
        .plate_nodes()
        .iter()
        .map(|&n| asm.node_gradient_n[n][2])
        .sum();
    assert!((asm.gradient_n[dim - 1] - plate_sum).abs() < 1e-12 * scale);
}

#[test]
fn equilibrium_residual_is_below_tolerance_on_every_free_node() {
    let model = model(10);
    let stack = Stack::new(&model);
    let cfg = SolverConfig::default();
    let rest = stack.rest_equilibrium();
    // Plate held at +10 % strain under a little pressure.
    let held = Load {
        pressure_pa: 100.0,
        bend_angle_rad: 0.0,
        translation: PlateTranslation::Fixed {
            centre_m: stack.uniform_plate_centre_m(0.1, 0.0),
        },
    };
    let eq = stack
        .continue_to(&rest, &held, 3, &cfg)
        .expect("held solve");
    let g = stack.energy_gradient_n(&eq.positions, held.pressure_pa);
    let (base, plate) = (stack.base_nodes(), stack.plate_nodes());
    for (n, gn) in g.iter().enumerate() {
        if base.contains(&n) || plate.contains(&n) {
            continue;
        }
        assert!(
            gn.iter().all(|v| v.abs() < cfg.tolerance_n),
            "node {n}: {gn:?}"
        );
    }
    // Free plate under a dead force: the plate nodes' forces add up to it.
    let force = 0.03;
    let free = Load {
        pressure_pa: 0.0,
        bend_angle_rad: 0.0,
        translation: PlateTranslation::Free {
            force_n: [0.0, 0.0, force],
        },
    };
    let eq = stack
        .continue_to(&rest, &free, 3, &cfg)
        .expect("free solve");
    let g = stack.energy_gradient_n(&eq.positions, 0.0);
    let total: [f64; 3] = core::array::from_fn(|d| plate.iter().map(|&n| g[n][d]).sum::<f64>());
    assert!((total[2] - force).abs() < 1e-8, "plate force {total:?}");
    assert!(total[0].abs() < 1e-8 && total[1].abs() < 1e-8);
    assert!(
        eq.plate_centre_m[2] > stack.rest_plate_centre_m()[2],
        "tension extends"
    );
    assert!(eq.stable);
}

#[test]
fn single_layer_without_load_returns_to_rest() {
    let model = model(1);
    let stack = Stack::new(&model);
    let guess = perturbed(stack.rest_positions(), 2e-4, 3);
    let centre = stack.rest_plate_centre_m();
    let guess_centre = [centre[0] + 1e-4, centre[1] - 1e-4, centre[2] + 2e-4];
    let eq = stack
        .solve(&guess, guess_centre, &Load::NONE, &SolverConfig::default())
        .expect("unloaded solve");
    for (a, b) in eq.positions.iter().zip(stack.rest_positions()) {
        assert!(dist(*a, *b) < 1e-9, "{a:?} vs rest {b:?}");
    }
    assert!(eq.stable, "the rest state is a stable equilibrium");
    assert!(eq.energy_j.abs() < 1e-18);
}

#[test]
fn small_axial_force_matches_the_linearised_stiffness() {
    for layers in [1, 3] {
        let model = model(layers);
        let stack = Stack::new(&model);
        let rest = stack.rest_equilibrium();
        // Linear response from the assembled Hessian at rest.
        let asm = stack.assemble(stack.rest_positions(), 0.0, true);
        let dim = asm.gradient_n.len();
        let force = 1e-4;
        let mut f = nalgebra::DVector::zeros(dim);
        f[dim - 1] = force;
        let u = asm
            .hessian_n_per_m
            .clone()
            .cholesky()
            .expect("rest Hessian is positive definite")
            .solve(&f);
        let linear_dz = u[dim - 1];
        let load = Load {
            translation: PlateTranslation::Free {
                force_n: [0.0, 0.0, force],
            },
            ..Load::NONE
        };
        let eq = stack
            .continue_to(&rest, &load, 1, &SolverConfig::default())
            .expect("small force");
        let dz = eq.plate_centre_m[2] - stack.rest_plate_centre_m()[2];
        assert!(
            (dz - linear_dz).abs() < 2e-3 * linear_dz.abs(),
            "N = {layers}: Newton {dz} vs linear {linear_dz}"
        );
    }
}

#[test]
fn bending_is_mirror_symmetric() {
    let model = model(3);
    let stack = Stack::new(&model);
    let rest = stack.rest_equilibrium();
    let cfg = SolverConfig::default();
    let phi = 0.3 * model.max_bend_angle_rad(0.0);
    let solve = |angle: f64| {
        let load = Load {
            pressure_pa: 0.0,
            bend_angle_rad: angle,
            translation: PlateTranslation::Fixed {
                centre_m: stack.uniform_plate_centre_m(0.0, angle),
            },
        };
        stack.continue_to(&rest, &load, 3, &cfg).expect("bending")
    };
    let (pos, neg) = (solve(phi), solve(-phi));
    assert!(pos.plate_moment_nm > 0.0, "bending resists");
    assert!(
        (pos.plate_moment_nm + neg.plate_moment_nm).abs() < 1e-6 * pos.plate_moment_nm,
        "M(+phi) = {} but M(-phi) = {}",
        pos.plate_moment_nm,
        neg.plate_moment_nm
    );
    // The mirror through the plane of the bending axis and z maps one
    // equilibrium onto the other: x -> x - 2 (x.b) b.
    let b = BEND_DIRECTION;
    let mirror = |p: [f64; 3]| {
        let s = 2.0 * (p[0] * b[0] + p[1] * b[1]);
        [p[0] - s * b[0], p[1] - s * b[1], p[2]]
    };
    for p in &pos.positions {
        let m = mirror(*p);
        let nearest = neg
            .positions
            .iter()
            .map(|q| dist(m, *q))
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest < 1e-8,
            "mirror image of {p:?} is no node of the -phi solution"
        );
    }
}

#[test]
fn newton_converges_quadratically() {
    let model = model(3);
    let stack = Stack::new(&model);
    let load = Load {
        translation: PlateTranslation::Free {
            force_n: [0.0, 0.0, 0.01],
        },
        ..Load::NONE
    };
    let eq = stack
        .solve(
            stack.rest_positions(),
            stack.rest_plate_centre_m(),
            &load,
            &SolverConfig::default(),
        )
        .expect("Newton from rest");
    let r = &eq.residual_history_n;
    assert!(eq.residual_n() < 1e-9);
    let mut pairs = 0;
    for w in r.windows(2) {
        // Once in the basin, the next residual is of the order of the
        // square of this one (above round-off).
        if w[0] < 1e-3 && w[1] > 1e-13 {
            assert!(w[1] < 100.0 * w[0] * w[0], "history {r:?}");
            pairs += 1;
        }
    }
    assert!(pairs >= 1, "no iterations in the quadratic regime: {r:?}");
}

#[test]
fn relaxation_never_raises_the_energy_of_the_uniform_configuration() {
    // Minimum principle: with the plate where the uniform map puts it, the
    // free structure started from the uniform configuration can only lower
    // its energy.
    let model = model(3);
    let stack = Stack::new(&model);
    for (strain, fraction, pressure) in [(0.2, 0.0, 0.0), (-0.2, 0.5, 50.0), (0.0, 0.7, 0.0)] {
        let phi = fraction * model.max_bend_angle_rad(strain);
        let load = Load {
            pressure_pa: pressure,
            bend_angle_rad: phi,
            translation: PlateTranslation::Fixed {
                centre_m: stack.uniform_plate_centre_m(strain, phi),
            },
        };
        let start = stack.uniform_positions(strain, phi);
        let eq = stack
            .solve(&start, load_centre(&load), &load, &SolverConfig::default())
            .expect("relaxation");
        let uniform = model.energy_j(strain, phi, pressure);
        assert!(
            eq.energy_j <= uniform + 1e-15,
            "relaxed {} above uniform {uniform}",
            eq.energy_j
        );
        assert!(
            eq.energy_j < 0.9 * uniform,
            "the uniform map is far from equilibrium"
        );
    }
}

fn load_centre(load: &Load) -> [f64; 3] {
    match load.translation {
        PlateTranslation::Fixed { centre_m } => centre_m,
        PlateTranslation::Free { .. } => [0.0; 3],
    }
}

#[test]
fn bad_input_is_rejected_with_a_named_error() {
    let model = model(1);
    let stack = Stack::new(&model);
    let cfg = SolverConfig::default();
    let nan = Load {
        pressure_pa: f64::NAN,
        ..Load::NONE
    };
    let err = stack
        .solve(stack.rest_positions(), [0.0; 3], &nan, &cfg)
        .expect_err("NaN pressure");
    assert!(err.to_string().contains("load"), "{err}");
    let err = stack
        .solve(&stack.rest_positions()[..3], [0.0; 3], &Load::NONE, &cfg)
        .expect_err("short guess");
    assert!(err.to_string().contains("guess"), "{err}");
    let bad = AssumptionConfig {
        bend_fraction: 1.5,
        ..AssumptionConfig::default()
    };
    let err = measure_assumptions(&model, &bad).expect_err("bend fraction");
    assert!(err.to_string().contains("bend_fraction"), "{err}");
    let bad = AssumptionConfig {
        axial_strains: vec![5.0],
        ..AssumptionConfig::default()
    };
    let err = measure_assumptions(&model, &bad).expect_err("strain");
    assert!(err.to_string().contains("axial_strains"), "{err}");
}

#[test]
fn deviation_summary_of_known_pairs() {
    let s = DeviationSummary::of([(1.0, 10.0), (-3.0, -20.0), (2.0, 5.0)]);
    assert_eq!(s.count, 3);
    assert_eq!(s.max_abs, 3.0);
    assert_eq!(s.mean_abs, 2.0);
    assert_eq!(s.max_rel_fs, 3.0 / 20.0);
    assert_eq!(s.mean_rel_fs, 2.0 / 20.0);
}

#[test]
fn assumption_sweep_on_a_short_stack() {
    let model = model(2);
    let cfg = AssumptionConfig {
        pressures_pa: vec![0.0],
        stable_pressure_fractions: vec![],
        axial_strains: vec![-0.05, 0.05],
        bend_strains: vec![0.0],
        bend_points: 2,
        bend_fraction: 0.5,
        load_steps: 2,
        ..AssumptionConfig::default()
    };
    let report = measure_assumptions(&model, &cfg).expect("sweep");
    assert_eq!(report.layers, 2);
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.axial.len(), 2);
    for a in &report.axial {
        // Force and strain have the same sign, and the relaxed structure is
        // softer than the kinematically constrained one.
        assert!(a.force_full_n * a.strain > 0.0, "{a:?}");
        assert!(a.force_full_n.abs() < a.force_uniform_n.abs(), "{a:?}");
        let u = a.strain_uniform_at_full_force.expect("force in range");
        assert!((model.axial_force_n(u, 0.0) - a.force_full_n).abs() < 1e-9);
    }
    assert_eq!(report.bending.len(), 2);
    for b in &report.bending {
        assert!(b.moment_arc_nm > 0.0 && b.moment_uniform_nm > 0.0, "{b:?}");
        assert!(
            (b.moment_arc_deviation_nm - (b.moment_arc_nm - b.moment_uniform_nm)).abs() < 1e-15
        );
    }
    let s = &report.force_deviation_n;
    assert_eq!(s.count, 2);
    assert!(s.max_abs >= s.mean_abs && s.mean_abs > 0.0);
    // The summary is the largest neutral-axis change of the bending cases, and there is one.
    let changes: Vec<f64> = report
        .bending
        .iter()
        .filter_map(|b| b.neutral_axis_change_mm)
        .collect();
    assert!(
        !changes.is_empty(),
        "no bending case measured the neutral axis"
    );
    let largest = changes.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert_eq!(report.neutral_axis_max_deviation_mm, largest);
    assert!(largest > 0.0, "a bent stack moves its neutral axis");
}

#[test]
fn pressure_beyond_the_stability_limit_fails_with_an_error() {
    // With the fitted k_b the free facets cannot carry kilopascals: the
    // solver must say so instead of returning NaN or a bogus state.
    let model = model(2);
    let stack = Stack::new(&model);
    let rest = stack.rest_equilibrium();
    let load = Load {
        pressure_pa: 30e3,
        ..Load::NONE
    };
    match stack.continue_to(&rest, &load, 2, &SolverConfig::default()) {
        Err(e) => assert!(e.to_string().contains("Pa"), "{e}"),
        Ok(eq) => assert!(
            !eq.stable,
            "a stable equilibrium at 30 kPa: plate at {:?}",
            eq.plate_centre_m
        ),
    }
}

#[test]
fn reaction_moment_is_the_derivative_of_the_relaxed_energy() {
    // Envelope theorem: along the plate path c(phi), R(phi), the relaxed
    // energy's slope is the generalised force f . c' + M read off the plate.
    let model = model(2);
    let stack = Stack::new(&model);
    let cfg = SolverConfig {
        tolerance_n: 1e-12,
        ..SolverConfig::default()
    };
    let strain = 0.1;
    let phi = 0.4 * model.max_bend_angle_rad(strain);
    let at = |angle: f64| Load {
        pressure_pa: 30.0,
        bend_angle_rad: angle,
        translation: PlateTranslation::Fixed {
            centre_m: stack.uniform_plate_centre_m(strain, angle),
        },
    };
    let eq = stack
        .continue_to(&stack.rest_equilibrium(), &at(phi), 3, &cfg)
        .expect("bent state");
    let h = 1e-4;
    let energy = |angle: f64| {
        stack
            .continue_to(&eq, &at(angle), 1, &cfg)
            .expect("neighbour")
            .energy_j
    };
    let slope = (energy(phi + h) - energy(phi - h)) / (2.0 * h);
    let cp = stack.uniform_plate_centre_m(strain, phi + h);
    let cm = stack.uniform_plate_centre_m(strain, phi - h);
    let dc: [f64; 3] = core::array::from_fn(|d| (cp[d] - cm[d]) / (2.0 * h));
    let moment = Stack::generalised_moment_nm(&eq, dc);
    assert!(
        (moment - slope).abs() < 1e-5 * slope.abs(),
        "plate reaction {moment} vs energy slope {slope}"
    );
}
