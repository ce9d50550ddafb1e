//! Plant physics against independent references.

use ocm_hilsim::effects::{BoucWen, COLUMN_LOOP, Effects};
use ocm_hilsim::pcc::Config;
use ocm_hilsim::plant::{Plant, PlantParams, PlateLoad};
use ocm_hilsim::pneumatics::{Regulator, RegulatorParams};
use ocm_hilsim::potential::OcmPotential;

fn plant() -> Plant {
    Plant::new(PlantParams::default(), 7).expect("plant")
}

/// Runs the damped dynamics at constant command until it rests.
fn settle(plant: &Plant, start: Config, p: [f64; 3], load: PlateLoad, seconds: f64) -> Config {
    let mut s = plant.state_at(start, p, load);
    let n = (seconds / plant.params().dt_s) as usize;
    for _ in 0..n {
        plant.step(&mut s, p);
    }
    s.q
}

#[test]
fn potential_matches_the_energy_model() {
    let p = plant();
    let model = p.model();
    let pot = OcmPotential::new(model).expect("potential");
    let l0 = model.params().rest_length_m;
    for eps in [-0.6, -0.25, 0.0, 0.3, 0.55, 1.0] {
        for phi in [0.0, 0.12, 0.3, 0.45] {
            let g = pot.eval(eps, phi * phi);
            for pa in [0.0, 2_000.0] {
                let e = g.elastic.value - pa * g.volume.value;
                let direct = model.energy_j(eps, phi, pa);
                assert!(
                    (e - direct).abs() < 1e-8 + 1e-6 * direct.abs(),
                    "energy at {eps},{phi},{pa}: {e} vs {direct}"
                );
                // Moment dPi/dphi = 2 phi dPi/dw (eq 3.20).
                let m = 2.0 * phi * (g.elastic.d_w - pa * g.volume.d_w);
                let m_direct = model.bending_moment_nm(phi, eps, pa);
                assert!(
                    (m - m_direct).abs() < 1e-7 + 1e-5 * m_direct.abs(),
                    "moment at {eps},{phi},{pa}: {m} vs {m_direct}"
                );
            }
            if phi == 0.0 {
                // Axial force dPi/dl (eq 3.9).
                let f = (g.elastic.d_strain - 1_500.0 * g.volume.d_strain) / l0;
                let f_direct = model.axial_force_n(eps, 1_500.0);
                assert!(
                    (f - f_direct).abs() < 1e-7 + 1e-6 * f_direct.abs(),
                    "force at {eps}: {f} vs {f_direct}"
                );
            }
        }
    }
}

#[test]
fn straight_rest_length_matches_the_inverse_axial_map() {
    // Equal pressures, no lateral load: each column carries a third of the
    // weight (eq 3.27), so S = n l0 (1 + F_A^-1(W/3, P)) (eq 3.33), solved
    // directly on the lut-gen model.
    let p = plant();
    let model = p.model();
    for (pa, payload) in [(8_000.0, 0.0), (15_000.0, 0.25), (22_000.0, 0.1)] {
        let load = PlateLoad {
            payload_kg: payload,
            force_n: [0.0; 3],
        };
        let tension = p.external_force_n(&load)[2] / 3.0;
        let eps = model
            .strain_for_force(tension, pa, (-0.9, 1.1))
            .expect("strain");
        let expected = p.column_rest_length_m() * (1.0 + eps);
        let start = Config::from_polar(expected - 0.01, 0.05, 0.7);
        let q = settle(&p, start, [pa; 3], load, 12.0);
        assert!(
            (q.backbone_m - expected).abs() < 1e-6,
            "{pa} Pa: S {} vs {expected}",
            q.backbone_m
        );
        assert!(q.bend_rad() < 1e-6, "straight: bend {}", q.bend_rad());
    }
}

#[test]
fn damped_dynamics_settle_at_the_static_solution() {
    let p = plant();
    let load = PlateLoad {
        payload_kg: 0.1,
        force_n: [0.3, -0.2, 0.5],
    };
    let press = [12_000.0, 18_000.0, 15_000.0];
    let guess = Config::from_polar(0.155, 0.0, 0.0);
    let stat = p.static_equilibrium(press, &load, guess).expect("static");
    let r = p.static_residual(&stat, press, &load, [0.0; 3]);
    assert!(r.iter().all(|v| v.abs() < 1e-8), "residual {r:?}");
    let dyn_q = settle(&p, guess, press, load, 15.0);
    let (a, b) = (stat.position(), dyn_q.position());
    for k in 0..3 {
        assert!(
            (a[k] - b[k]).abs() < 1e-6,
            "axis {k}: static {a:?} vs dynamic {b:?}"
        );
    }
    // The lateral force really bends the segment.
    assert!(stat.bend_rad() > 0.05);
}

#[test]
fn exact_inverse_holds_the_target() {
    let p = plant();
    let load = PlateLoad {
        payload_kg: 0.25,
        force_n: [0.0; 3],
    };
    let target = Config::from_position([0.02, -0.015, 0.150]).expect("reachable");
    let press = p.pressures_for(&target, &load, [0.0; 3]).expect("inverse");
    let q = p
        .static_equilibrium(press, &load, Config::from_polar(0.15, 0.0, 0.0))
        .expect("static");
    let (a, b) = (target.position(), q.position());
    for k in 0..3 {
        assert!((a[k] - b[k]).abs() < 1e-7, "target {a:?} reached {b:?}");
    }
}

#[test]
fn damping_dissipates_mechanical_energy() {
    let p = plant();
    let load = PlateLoad::default();
    let press = [14_000.0, 18_000.0, 16_000.0];
    let rest = p
        .static_equilibrium(press, &load, Config::from_polar(0.155, 0.0, 0.0))
        .expect("static");
    // Released from a displaced pose at rest, with constant pressures.
    let start = Config::from_array([
        rest.backbone_m + 0.01,
        rest.bend_x_rad + 0.1,
        rest.bend_y_rad,
    ]);
    let mut s = p.state_at(start, press, load);
    for _ in 0..200 {
        // Let the regulators reach their set points first.
        p.step(&mut s, press);
    }
    let e_rest = {
        let r = p.state_at(rest, press, load);
        p.mechanical_energy_j(&r)
    };
    let e0 = p.mechanical_energy_j(&s);
    let mut prev = e0;
    for _ in 0..60 {
        for _ in 0..50 {
            p.step(&mut s, press);
        }
        let e = p.mechanical_energy_j(&s);
        assert!(
            e <= prev + 1e-6 * (e0 - e_rest),
            "energy rose from {prev} to {e}"
        );
        prev = e;
    }
    assert!(e0 > e_rest);
    assert!(
        prev - e_rest < 0.01 * (e0 - e_rest),
        "3 s of damping left {} of {} J",
        prev - e_rest,
        e0 - e_rest
    );
}

#[test]
fn regulator_step_is_a_delayed_first_order_lag() {
    let params = RegulatorParams {
        time_constant_s: 0.05,
        dead_time_s: 0.02,
        ..RegulatorParams::default()
    };
    let dt = 1e-3;
    let mut r = Regulator::new(params, dt, 0.0, 0.0);
    let step = 10_000.0;
    for k in 1..=300 {
        r.step(step, true, dt);
        let t = k as f64 * dt;
        let expected = if t <= params.dead_time_s + 1e-12 {
            0.0
        } else {
            step * (1.0 - (-(t - params.dead_time_s) / params.time_constant_s).exp())
        };
        assert!(
            (r.pressure_pa() - expected).abs() < 1e-6 * step,
            "t {t}: {} vs {expected}",
            r.pressure_pa()
        );
    }
    // Limits: a command beyond the range saturates, offsets included.
    let mut r = Regulator::new(params, dt, 0.0, 500.0);
    for _ in 0..2_000 {
        r.step(1e9, true, dt);
        assert!(r.pressure_pa() <= params.max_pa);
    }
    assert!((r.pressure_pa() - params.max_pa).abs() < 1e-6);
    // A cut supply vents to 0 Pa gauge.
    for _ in 0..2_000 {
        r.step(20_000.0, false, dt);
    }
    assert!(r.pressure_pa().abs() < 1e-3);
}

#[test]
fn bouc_wen_loop_width_is_twice_the_amplitude() {
    let mut h = BoucWen::default();
    // Drive 10 yield lengths each way: z saturates at +-1.
    for _ in 0..1_000 {
        h.step(1e-2, COLUMN_LOOP);
    }
    assert!((h.z - 1.0).abs() < 1e-3, "z {}", h.z);
    for _ in 0..1_000 {
        h.step(-1e-2, COLUMN_LOOP);
    }
    assert!((h.z + 1.0).abs() < 1e-3, "z {}", h.z);
}

#[test]
fn hysteresis_opens_a_loop_of_the_set_width() {
    // A slow pressure cycle on a straight segment: at the same pressure the
    // column is shorter on the way up (the loop force resists extension)
    // than on the way down, by the loop width (eq 3.37 times the reference
    // force) over the column stiffness from the energy model.
    let params = PlantParams {
        effects: Effects {
            hysteresis_fraction: 0.05,
            hysteresis_reference_n: 10.0,
            ..Effects::NONE
        },
        ..PlantParams::default()
    };
    let p = Plant::new(params, 3).expect("plant");
    let load = PlateLoad::default();
    let (lo, hi) = (10_000.0, 20_000.0);
    let q = p
        .static_equilibrium([lo; 3], &load, Config::from_polar(0.15, 0.0, 0.0))
        .expect("static");
    let mut s = p.state_at(q, [lo; 3], load);
    let ramp = |s: &mut ocm_hilsim::plant::PlantState, a: f64, b: f64| {
        let mut mid = 0.0;
        // 200 s per branch: the regulator lag and the damping then widen
        // the loop by under 2 %.
        let n = 200_000;
        for k in 0..n {
            p.step(s, [a + (b - a) * k as f64 / n as f64; 3]);
            if k == n / 2 {
                mid = s.q.backbone_m;
            }
        }
        mid
    };
    let up = ramp(&mut s, lo, hi);
    let down = ramp(&mut s, hi, lo);
    // Column stiffness at the midpoint: n OCMs in series.
    let mid_p = 0.5 * (lo + hi);
    let n = f64::from(params.manipulator.ocms_per_column);
    let eps = 0.5 * (up + down) / p.column_rest_length_m() - 1.0;
    let k_col = p.model().axial_stiffness_n_per_m(eps, mid_p) / n;
    let e = params.effects;
    let expected = e.hysteresis_fraction * e.hysteresis_reference_n / k_col;
    let gap = down - up;
    assert!(
        (gap - expected).abs() < 0.04 * expected,
        "loop gap {gap} m, expected {expected} m"
    );
}

#[test]
fn gradient_only_evaluation_matches_the_full_one() {
    let p = plant();
    let pot = OcmPotential::new(p.model()).expect("potential");
    for (strains, w) in [
        ([-0.6, 0.1, 0.9], 0.0),
        ([0.2, 0.25, 0.3], 0.04),
        ([1.1, -0.5, 0.0], 0.2),
    ] {
        let (full, grad) = (pot.eval3(strains, w), pot.grad3(strains, w));
        // The gradient path sums derivative expansions without the noise
        // orders: equal to rounding (parts in 1e9 of the part's scale: 1e-3 J
        // for the elastic energy, 1e-5 m^3 for the volume).
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-8 * scale.max(b.abs());
        for (f, g) in full.iter().zip(&grad) {
            assert!(close(g.elastic.d_strain, f.elastic.d_strain, 1e-3));
            assert!(close(g.elastic.d_w, f.elastic.d_w, 1e-3));
            assert!(close(g.volume.d_strain, f.volume.d_strain, 1e-5));
            assert!(close(g.volume.d_w, f.volume.d_w, 1e-5));
            assert_eq!((g.elastic.value, g.volume.value), (0.0, 0.0));
        }
        // And the three-column evaluation is the one-column one.
        for (i, &e) in strains.iter().enumerate() {
            assert_eq!(pot.eval(e, w), full[i]);
        }
    }
}

/// The process keeps fits per design: whatever was fitted before, and
/// after more designs than it keeps, each expansion is its own model's.
#[test]
fn kept_fits_belong_to_their_design() {
    use ocm_lutgen::{OcmModel, OcmParams};
    // Table 3.1, the calibrated set and stiffness scales in between: more
    // designs than the process keeps, then the first ones again.
    let designs: Vec<OcmParams> = (0..12)
        .map(|k| OcmParams {
            bar_stiffness_n_per_m: 1.3 * (1.0 + k as f64),
            hinge_stiffness_n_per_m: 0.1 * (1.0 + 0.5 * k as f64),
            ..OcmParams::TABLE_3_1
        })
        .chain([OcmParams::CALIBRATED, OcmParams::TABLE_3_1])
        .collect();
    for round in 0..2 {
        for (k, params) in designs.iter().enumerate() {
            let model = OcmModel::new(*params).expect("model");
            let pot = OcmPotential::new(&model).expect("potential");
            for (eps, phi) in [(0.3, 0.2), (-0.4, 0.1)] {
                let e = pot.eval(eps, phi * phi).elastic.value;
                let direct = model.energy_j(eps, phi, 0.0);
                assert!(
                    (e - direct).abs() < 1e-8 + 1e-6 * direct.abs(),
                    "round {round}, design {k}: {e} J against the model's {direct} J"
                );
            }
        }
    }
}

/// A state keeps its configuration's trigonometry between steps; setting `q`
/// by hand must not leave the old one behind.
#[test]
fn state_trigonometry_follows_its_configuration() {
    let p = plant();
    let q0 = Config::from_polar(0.15, 0.3, 0.7);
    let mut s = p.state_at(q0, [8_000.0, 9_000.0, 10_000.0], PlateLoad::default());
    for _ in 0..50 {
        p.step(&mut s, [8_000.0, 9_000.0, 10_000.0]);
        assert_eq!(s.position(), s.q.position());
        assert_eq!(s.turn(), s.q.turn());
    }
    s.q = Config::from_polar(0.14, 0.6, -1.2);
    assert_eq!(s.position(), s.q.position());
    assert_eq!(s.turn(), s.q.turn());
    // The cached and the fresh trigonometry give the same step.
    let mut fresh = p.state_at(s.q, s.pressures_pa(), s.load);
    fresh.qdot = s.qdot;
    fresh.regulators = s.regulators.clone();
    fresh.hysteresis = s.hysteresis;
    p.step(&mut s, [8_000.0; 3]);
    p.step(&mut fresh, [8_000.0; 3]);
    assert_eq!(s.q, fresh.q);
}

#[test]
fn a_setting_out_of_range_is_named_with_its_value() {
    let params = PlantParams {
        dt_s: f64::NAN,
        ..PlantParams::default()
    };
    let e = match Plant::new(params, 1) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a NaN step is accepted"),
    };
    assert!(e.contains("dt_s = NaN") && e.contains("(0, 0.01]"), "{e}");
    let mut params = PlantParams::default();
    params.effects.stiffness_spread = -0.1;
    let e = match Plant::new(params, 1) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a negative spread is accepted"),
    };
    assert!(e.contains("effects.stiffness_spread = -0.1"), "{e}");
}

/// The logged kinematic sensitivities are the plate position's derivatives in the column
/// elongations: central differences of the position of the configuration the perturbed
/// column lengths give (eq 3.26), at a bent pose and at the straight one.
#[test]
fn tip_sensitivity_to_elongations_matches_finite_differences() {
    let p = plant();
    let load = PlateLoad::default();
    for q in [
        Config::from_polar(0.16, 0.35, 0.7),
        Config::from_polar(0.15, 0.0, 0.0),
    ] {
        let s = p.state_at(q, [15_000.0; 3], load);
        let jac = p.tip_sensitivity_to_elongations(&s);
        let d = p.params().manipulator.column_radius_m;
        let l = q.column_lengths(d);
        let h = 1e-7;
        for j in 0..3 {
            let at = |dl: f64| {
                let mut l2 = l;
                l2[j] += dl;
                Config::from_column_lengths(l2, d).position()
            };
            let (up, dn) = (at(h), at(-h));
            for r in 0..3 {
                let fd = (up[r] - dn[r]) / (2.0 * h);
                assert!(
                    (jac[r][j] - fd).abs() < 1e-6,
                    "d p{r} / d e{j}: {} against {fd}",
                    jac[r][j]
                );
            }
        }
    }
}
