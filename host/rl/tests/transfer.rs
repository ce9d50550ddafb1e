//! Deployment through the pressure chain: the figure-eight on its ball, the chain reproducing
//! the environment when the actuation map is exact, a trained policy against a zero policy, the
//! chamber cut and its recovery, and the reduced-FEM plant against the reduced statics.

mod common;
use common::{quick_train, robot};
use nalgebra::{DMatrix, Vector3};
use ocm_rl::bc;
use ocm_rl::env::{Env, EnvConfig};
use ocm_rl::eval::evaluate;
use ocm_rl::robot::Load;
use ocm_rl::tasks::{ContactConfig, Episode, FIGURE_EIGHT_BALL_RADIUS_M, POINTS, TaskKind};
use ocm_rl::transfer::{
    Admittance, CommandMap, Disconnect, Plant, RomPlant, SurrogatePlant, TransferConfig,
    evaluate_on_plant, expert_actor,
};
use ocm_surrogate::chain::{GROUPS, Posture};
use ocm_surrogate::constraints::Limits;

/// An exact, invertible actuation map for the pipeline tests: chamber g drives group g
/// linearly, -20..35 kPa spanning the group's range.
#[derive(Debug)]
struct LinearMap {
    limits: Limits,
}

impl LinearMap {
    fn span(&self, g: usize) -> [f64; 2] {
        self.limits.range(GROUPS[g][0])
    }
}

impl CommandMap for LinearMap {
    fn pressures(&self, q: &Posture) -> ocm_rl::Result<[f64; 3]> {
        Ok(std::array::from_fn(|g| {
            let [lo, hi] = self.span(g);
            let mean = GROUPS[g].iter().map(|&j| q[j]).sum::<f64>() / GROUPS[g].len() as f64;
            -20.0 + 55.0 * (mean - lo) / (hi - lo)
        }))
    }
    fn posture(&self, p: &[f64; 3]) -> ocm_rl::Result<Posture> {
        let mut q = [0.0; 11];
        for (g, members) in GROUPS.iter().enumerate() {
            let [lo, hi] = self.span(g);
            for &j in members.iter() {
                q[j] = lo + (hi - lo) * (p[g] + 20.0) / 55.0;
            }
        }
        Ok(self.limits.project(&q)?)
    }
}

#[test]
fn figure_eight_lies_on_its_ball_and_the_expert_presses_it() {
    let r = robot();
    let contact = ContactConfig::default();
    let ep = Episode::figure_eight(&r.rest_tcp(), &contact, 3);
    assert_eq!(ep.targets.len(), POINTS);
    let Load::Sphere {
        centre_m, radius_m, ..
    } = ep.load
    else {
        panic!("the figure-eight is on a ball");
    };
    let c = Vector3::from(centre_m);
    assert_eq!(radius_m, FIGURE_EIGHT_BALL_RADIUS_M);
    let (mut xmax, mut ymax) = (0.0f64, 0.0f64);
    for (p, f) in ep.targets.iter().zip(&ep.force_targets) {
        assert!(((p - c).norm() - radius_m).abs() < 1e-12, "on the ball");
        assert!(p.z < c.z, "on its underside");
        // 1 N along the outward normal (towards the robot).
        assert!((f.norm() - 1.0).abs() < 1e-12);
        assert!((f - (p - c) / radius_m).norm() < 1e-12);
        xmax = xmax.max((p.x - c.x).abs());
        ymax = ymax.max((p.y - c.y).abs());
    }
    assert!((xmax - 0.025).abs() < 1e-4 && (ymax - 0.0125).abs() < 1e-4);
    // The lemniscate passes its centre twice: at the ball's lowest point.
    let crossings = ep
        .targets
        .iter()
        .filter(|p| (p.x - c.x).hypot(p.y - c.y) < 1e-9)
        .count();
    assert_eq!(crossings, 2);
    // Pressed by F/k along the normal, the penalty law gives the target force back.
    for k in [0, 17, 60] {
        let tcp = ep.planned_tcp(k);
        let f = ep.load.force(&tcp, &Vector3::zeros(), 9.81);
        assert!((f - ep.force_targets[k]).norm() < 1e-9, "{f} at {k}");
        let (a, miss) = r.inverse(&tcp, &ep.planned_force(k, 9.81), &[0.0; 3]);
        assert!(miss < 1e-5, "expert misses point {k} by {miss} m");
        assert!(a.iter().all(|v| v.abs() <= 1.0));
    }
}

#[test]
fn an_exact_map_reproduces_the_environment_and_a_trained_policy_transfers() {
    let r = robot();
    let map = LinearMap {
        limits: *r.limits(),
    };
    let env_cfg = EnvConfig::new(TaskKind::Circle);
    let mut plant = SurrogatePlant::new(r.clone(), &map).unwrap();
    let episode = |s: u64| Episode::new(TaskKind::Circle, &r.rest_tcp(), &env_cfg.contact, s);
    // The expert through the pressure chain without filter equals the expert in the
    // environment on the same episodes once the start transient is over.
    let direct = TransferConfig {
        filter_window: 1,
        ..TransferConfig::default()
    };
    let mut expert = expert_actor(&r);
    let chain =
        evaluate_on_plant(&mut plant, &map, &r, &direct, 2, 40, &episode, &mut expert).unwrap();
    let mut env = Env::new(r.clone(), env_cfg).unwrap();
    let in_env = evaluate(&mut env, 2, 40, |e, _| e.expert_action()).unwrap();
    let (a, b) = (
        chain.eval.position_error_mm.mean,
        in_env.position_error_mm.mean,
    );
    eprintln!("expert: pressure chain {a:.4} mm, environment {b:.4} mm");
    assert!((a - b).abs() < 0.02, "chain {a} mm vs environment {b} mm");
    // A BC policy transfers through the filter; the zero action (the middle of every range)
    // does not track.
    let demos = bc::collect(&r, &env_cfg, 12, 0.03, 0, 2).unwrap();
    let (policy, _) = bc::fit(&demos, &[64, 64], &quick_train(), 0).unwrap();
    let cfg = TransferConfig {
        filter_window: 2,
        ..TransferConfig::default()
    };
    let mut act = |_: &Episode, o: &[f64], _: usize| policy.act(o);
    let bc_run = evaluate_on_plant(&mut plant, &map, &r, &cfg, 2, 40, &episode, &mut act).unwrap();
    let mut zero = |_: &Episode, _: &[f64], _: usize| Ok([0.0; 3]);
    let zero_run =
        evaluate_on_plant(&mut plant, &map, &r, &cfg, 2, 40, &episode, &mut zero).unwrap();
    let (e_bc, e_zero) = (
        bc_run.eval.position_error_mm.mean,
        zero_run.eval.position_error_mm.mean,
    );
    eprintln!("BC {e_bc:.2} mm, zero policy {e_zero:.2} mm through the pressure chain");
    assert!(
        e_bc < 3.0 && e_zero > 10.0,
        "BC {e_bc} mm, zero {e_zero} mm"
    );
    assert_eq!(bc_run.eval.steps, 2 * POINTS);
    // Venting chamber 1 for 2 s pushes the TCP off the path; the policy is back within 2 s of
    // the reconnection.
    let cut = TransferConfig {
        laps: 2,
        disconnect: Some(Disconnect {
            chamber: 0,
            start_s: 2.0,
            duration_s: 2.0,
            ..Disconnect::default()
        }),
        ..cfg
    };
    let run = evaluate_on_plant(&mut plant, &map, &r, &cut, 1, 40, &episode, &mut act).unwrap();
    let d = run.disconnect[0];
    eprintln!("cut: {d:?}");
    assert!(
        d.during_mm > 3.0 * d.before_mm && d.during_mm > 5.0,
        "{d:?}"
    );
    let back = d.recovery_s.expect("back on the path");
    assert!(back < 2.0, "{d:?}");
    assert!(d.after_mm.unwrap() < d.before_mm + 1.0, "{d:?}");
}

#[test]
fn settings_out_of_range_are_refused() {
    let r = robot();
    let map = LinearMap {
        limits: *r.limits(),
    };
    let mut plant = SurrogatePlant::new(r.clone(), &map).unwrap();
    let episode = |s: u64| {
        Episode::new(
            TaskKind::Circle,
            &r.rest_tcp(),
            &ContactConfig::default(),
            s,
        )
    };
    let mut zero = |_: &Episode, _: &[f64], _: usize| Ok([0.0; 3]);
    // each refusal names the setting and its value (chambers counted from 1, as on the
    // command line)
    for (bad, want) in [
        (
            TransferConfig {
                filter_window: 0,
                ..TransferConfig::default()
            },
            "filter window = 0",
        ),
        (
            TransferConfig {
                command_rate_hz: f64::NAN,
                ..TransferConfig::default()
            },
            "command rate (Hz) = NaN",
        ),
        (
            TransferConfig {
                disconnect: Some(Disconnect {
                    chamber: 3,
                    ..Disconnect::default()
                }),
                ..TransferConfig::default()
            },
            "cut chamber = 4",
        ),
    ] {
        let e = evaluate_on_plant(&mut plant, &map, &r, &bad, 1, 0, &episode, &mut zero)
            .err()
            .unwrap_or_else(|| panic!("{bad:?} accepted"))
            .to_string();
        assert!(e.contains(want), "{e}");
    }
    let mut nan = |_: &Episode, _: &[f64], _: usize| Ok([f64::NAN, 0.0, 0.0]);
    let e = evaluate_on_plant(
        &mut plant,
        &map,
        &r,
        &TransferConfig::default(),
        1,
        0,
        &episode,
        &mut nan,
    );
    assert!(e.unwrap_err().to_string().contains("non-finite"));
}

/// The reduced-FEM plant on the real bellows with a small basis of full static solutions:
/// under held pressures it settles where the reduced statics put the TCP, a hanging weight
/// moves it as the reduced statics with that tip load, and pressing a plate it settles with the
/// penalty force equal to the load that the reduced statics need for that TCP.
#[test]
fn reduced_plant_settles_at_the_reduced_statics() {
    use ocm_fem::bellows::{Bellows, BellowsConfig};
    use ocm_fem::solve::statics::StaticSolver;
    use ocm_mor::drive::Input;
    use ocm_mor::rom::ReducedModel;
    use ocm_mor::store::ReducedProbe;
    use ocm_mor::xs::XsProbe;
    let Some(path) = ocm_datadir::test_data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let b = Bellows::load(path, BellowsConfig::default()).unwrap();
    let mut solver = StaticSolver::new(&b.model).unwrap();
    let rest = b.model.rest_dofs();
    let mut cols = vec![];
    for p in [
        [20.0, 0.0, 0.0],
        [0.0, 20.0, 0.0],
        [0.0, 0.0, 20.0],
        [10.0, 10.0, 10.0],
    ] {
        let (s, _) = b.solve_kpa(&mut solver, &p).unwrap();
        cols.push(
            s.x.iter()
                .zip(&rest)
                .map(|(x, r)| x - r)
                .collect::<Vec<f64>>(),
        );
    }
    // Orthonormal basis of the four displacements (modified Gram-Schmidt).
    let n = rest.len();
    let mut basis = DMatrix::<f64>::zeros(n, cols.len());
    for (k, c) in cols.iter().enumerate() {
        let mut v = nalgebra::DVector::from_column_slice(c);
        for j in 0..k {
            let bj = basis.column(j).into_owned();
            v -= &bj * bj.dot(&v);
        }
        basis.set_column(k, &(v.normalize()));
    }
    let rom = ReducedModel::galerkin(&b.model, basis, &b.top_face).unwrap();
    let probe = ReducedProbe::new(XsProbe::of_bellows(&b), &rom);
    let tcp_of = |q: &nalgebra::DVector<f64>| {
        let xs = probe.compact_state(q, &q.scale(0.0));
        Vector3::new(xs[0], xs[1], xs[2])
    };
    let mut plant = RomPlant::new(&rom, &probe, 0.005, 9.81).unwrap();
    let pressures = [15.0, 5.0, 0.0];
    let static_tcp = |tip: [f64; 3]| {
        tcp_of(
            &rom.solve_static(
                &Input {
                    pressure_kpa: pressures,
                    tip_force_n: tip,
                },
                4,
            )
            .unwrap(),
        )
    };
    // Held pressures, no load.
    plant.advance(&pressures, &Load::Free, 3.0).unwrap();
    let (p, v) = plant.tcp();
    let free = static_tcp([0.0; 3]);
    eprintln!("free: plant {p}, statics {free}, speed {}", v.norm());
    assert!((p - free).norm() < 2e-5, "{} m", (p - free).norm());
    // A 200 g weight.
    let weight = Load::Weight { mass_kg: 0.2 };
    plant.reset().unwrap();
    plant.advance(&pressures, &weight, 3.0).unwrap();
    let (pw, _) = plant.tcp();
    let loaded = static_tcp([0.0, 0.0, -0.2 * 9.81]);
    assert!((pw - loaded).norm() < 2e-5 && (loaded - free).norm() > 1e-4);
    // A plate whose face is 3 mm below the free TCP (its solid above): the TCP presses up.
    let plate = Load::Plane {
        point_m: [free.x, free.y, free.z - 0.003],
        normal: [0.0, 0.0, -1.0],
        stiffness_n_m: 5000.0,
        damping_n_s_m: 5.0,
    };
    plant.reset().unwrap();
    plant.advance(&pressures, &plate, 3.0).unwrap();
    let (pc, vc) = plant.tcp();
    let f = plate.force(&pc, &vc, 9.81);
    assert!(f.z < -0.1, "pressing: {f}");
    let balanced = static_tcp([f.x, f.y, f.z]);
    eprintln!("contact: force {f}, plant {pc}, statics {balanced}");
    assert!(
        (pc - balanced).norm() < 2e-5,
        "{} m",
        (pc - balanced).norm()
    );
}

/// The plant's f_SP extends each of the three prismatic joints 1 mm farther than the inverse
/// map the deployment commands with (a model gap of 3 mm along the pressing direction).
#[derive(Debug)]
struct LongerPlant {
    map: LinearMap,
    extra_m: f64,
}

impl CommandMap for LongerPlant {
    fn pressures(&self, q: &Posture) -> ocm_rl::Result<[f64; 3]> {
        self.map.pressures(q)
    }
    fn posture(&self, p: &[f64; 3]) -> ocm_rl::Result<Posture> {
        let mut q = self.map.posture(p)?;
        for &j in GROUPS[2].iter() {
            q[j] += self.extra_m;
        }
        Ok(self.map.limits.project(&q)?)
    }
}

/// Force control through a plant with a model gap: open loop, the 5000 N/m contact turns the
/// gap into newtons of force error; with the admittance layer the measured force closes the
/// loop and the error falls below a fifth of that (the layer's offset is about the gap).
#[test]
fn the_admittance_layer_closes_the_force_loop_across_a_model_gap() {
    let r = robot();
    let map = LinearMap {
        limits: *r.limits(),
    };
    let gap = LongerPlant {
        map: LinearMap {
            limits: *r.limits(),
        },
        extra_m: 0.001,
    };
    let contact = ContactConfig::default();
    let episode = |s: u64| Episode::new(TaskKind::Force, &r.rest_tcp(), &contact, s);
    let mut plant = SurrogatePlant::new(r.clone(), &gap).unwrap();
    let open = TransferConfig::default();
    let closed = TransferConfig {
        admittance: Some(Admittance::default()),
        ..open
    };
    let mut expert = expert_actor(&r);
    let a = evaluate_on_plant(&mut plant, &map, &r, &open, 2, 7, &episode, &mut expert).unwrap();
    let mut expert = expert_actor(&r);
    let b = evaluate_on_plant(&mut plant, &map, &r, &closed, 2, 7, &episode, &mut expert).unwrap();
    let (fa, fb) = (a.eval.force_error_n.mean, b.eval.force_error_n.mean);
    eprintln!(
        "force error: open loop {fa:.3} N, admittance {fb:.3} N (offset {:.3} mm)",
        b.admittance_offset_mm.mean
    );
    assert!(fa > 1.0, "the gap must show open loop: {fa} N");
    assert!(fb < 0.2 * fa && fb < 0.3, "open {fa} N, closed {fb} N");
    let off = b.admittance_offset_mm.mean;
    assert!(off > 1.5 && off < 4.5, "offset {off} mm for a 3 mm gap");
    assert_eq!(a.admittance_offset_mm.mean, 0.0);
    // Without a force target (the circle) the layer does nothing.
    let circle = |s: u64| Episode::new(TaskKind::Circle, &r.rest_tcp(), &contact, s);
    let mut expert = expert_actor(&r);
    let c = evaluate_on_plant(&mut plant, &map, &r, &closed, 1, 7, &circle, &mut expert).unwrap();
    let mut expert = expert_actor(&r);
    let d = evaluate_on_plant(&mut plant, &map, &r, &open, 1, 7, &circle, &mut expert).unwrap();
    assert_eq!(c.eval.position_error_mm, d.eval.position_error_mm);
    // A negative or NaN gain is refused.
    for g in [-1e-4, f64::NAN] {
        let bad = TransferConfig {
            admittance: Some(Admittance {
                gain_m_per_n: g,
                ..Admittance::default()
            }),
            ..open
        };
        let mut expert = expert_actor(&r);
        assert!(
            evaluate_on_plant(&mut plant, &map, &r, &bad, 1, 7, &episode, &mut expert).is_err()
        );
    }
}
