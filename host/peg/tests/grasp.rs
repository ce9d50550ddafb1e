//! The compliant grasp against statics: the peg's weight on the sliding spring, the weight's
//! torque on the twisting spring of a tilted peg, a press onto the board below and beyond the
//! pads' friction (elastic, then slip that stays), and stored configurations. The expert with a
//! compliant grasp: `tests/scene.rs`.

use ocm_peg::{Grasp, GripperPose, InHandError, PegScene, SceneConfig};

const G: f64 = 9.81;

fn compliant() -> SceneConfig {
    compliant_with(1.0)
}

fn compliant_with(pad_friction: f64) -> SceneConfig {
    let c = SceneConfig::default();
    let grasp = c.gel_grasp(pad_friction).unwrap();
    SceneConfig {
        grasp: Grasp::Compliant(grasp),
        ..c
    }
}

fn stiffness(c: &SceneConfig) -> (f64, f64, f64, f64) {
    match c.grasp {
        Grasp::Compliant(g) => (
            g.shear_stiffness_n_m,
            g.twist_stiffness_nm_rad,
            g.slip_force_n,
            g.slip_torque_nm,
        ),
        Grasp::Rigid => unreachable!(),
    }
}

/// Mass of the hexagonal peg, kg.
fn peg_mass(c: &SceneConfig) -> f64 {
    let apothem = 0.5 * c.peg_across_flats_m;
    2.0 * 3f64.sqrt() * apothem * apothem * c.peg_length_m * c.peg_density_kg_m3
}

fn hold(scene: &mut PegScene, steps: usize) {
    for _ in 0..steps {
        scene.step([0.0; 4]).unwrap();
    }
}

/// Hanging still, the peg sinks by its weight over the sliding stiffness, m g / k (about
/// 10 um), and does not slip.
#[test]
fn the_weight_stretches_the_sliding_spring_by_mg_over_k() {
    let c = compliant();
    let (k, _, _, _) = stiffness(&c);
    let start = GripperPose {
        z_m: 0.1,
        ..Default::default()
    };
    let mut scene = PegScene::new(&c, start, InHandError::default()).unwrap();
    hold(&mut scene, 60);
    let d = scene.in_hand_shift();
    let expected = -peg_mass(&c) * G / k;
    assert!(
        (d[1] - expected).abs() < 0.03 * expected.abs(),
        "sag {} m, m g / k = {expected} m",
        d[1]
    );
    assert!(d[0].abs() < 1e-9 && d[2].abs() < 1e-6, "{d:?}");
    assert_eq!(scene.slip_steps(), 0);
    assert_eq!(scene.slipped(), [0.0; 3]);
}

/// A peg tilted in the hand hangs its weight beside the springs' centre (half the length inside
/// the pads below the top face): the torque m g (L / 2 - d) sin(t) turns it back towards
/// hanging straight by that over the twisting stiffness (0.42 mrad at 5 degrees).
#[test]
fn a_tilted_peg_turns_by_its_weights_torque_over_the_twist_stiffness() {
    let c = compliant();
    let (_, kt, _, _) = stiffness(&c);
    let tilt = 5f64.to_radians();
    let start = GripperPose {
        z_m: 0.1,
        ..Default::default()
    };
    let mut scene = PegScene::new(
        &c,
        start,
        InHandError {
            tilt_rad: tilt,
            ..Default::default()
        },
    )
    .unwrap();
    hold(&mut scene, 90);
    let d = scene.in_hand_shift();
    let below_top = 0.5 * (c.peg_top_m + 0.5 * c.pad_height_m);
    let lever = 0.5 * c.peg_length_m - below_top;
    let turn = -peg_mass(&c) * G * lever * tilt.sin() / kt;
    assert!(
        (d[2] - turn).abs() < 0.03 * turn.abs(),
        "turn {} rad, m g l sin(t) / k = {turn} rad",
        d[2]
    );
    assert_eq!(scene.slip_steps(), 0);
}

/// The gripper presses the peg onto the board beside the hole and lifts it again. A short press
/// loads the sliding spring below the pads' friction: nothing slips, and the lift gives the
/// deflection back. A long one slides the peg up the pads: while it slides the spring holds
/// exactly the friction limit, and after the lift the peg stays where it slid to. The gripper
/// (a 1 kg body whose velocity is set every physics step) pushes with at most about its mass
/// times its speed over the time step, 1.2 N at 5 mm/s, so the pads' friction is set to 0.1
/// here (0.83 N of slip force).
#[test]
fn pressing_on_the_board_is_elastic_below_the_friction_limit_and_slips_beyond() {
    let c = compliant_with(0.1);
    let (k, _, slip_force, _) = stiffness(&c);
    let limit = slip_force / k;
    let sag = peg_mass(&c) * G / k;
    let v = 0.005;
    // The tip 1 mm above the board, 20 mm off the hole's axis.
    let start = GripperPose {
        x_m: 0.02,
        z_m: 0.001 + c.peg_length_m - c.peg_top_m,
        ..Default::default()
    };
    // Down until the spring is loaded by `load` of the friction limit, or for `steps` steps;
    // then up until the tip is 1 mm above the board again. Returns the sliding spring's largest
    // stretch, its stretch and rest at the deepest point, and the shift and rest after the lift.
    let press = |load: f64, steps: usize| {
        let mut scene = PegScene::new(&c, start, InHandError::default()).unwrap();
        hold(&mut scene, 30);
        let mut stretch: f64 = 0.0;
        for _ in 0..steps {
            scene.step([0.0, 0.0, -v, 0.0]).unwrap();
            let s = scene.in_hand_shift()[1] - scene.slipped()[1];
            stretch = stretch.max(s);
            if s > load * limit {
                break;
            }
        }
        let deepest = (
            scene.in_hand_shift()[1] - scene.slipped()[1],
            scene.slipped()[1],
        );
        while scene.peg_tip().0[2] < 0.001 {
            scene.step([0.0, 0.0, v, 0.0]).unwrap();
        }
        hold(&mut scene, 30);
        (
            stretch,
            deepest,
            scene.in_hand_shift()[1],
            scene.slipped()[1],
            scene.slip_steps(),
        )
    };

    let (stretch, _, after, rest, slips) = press(0.5, 200);
    assert!(
        stretch > 0.5 * limit && stretch < limit,
        "loaded to {stretch} m of the {limit} m the friction holds"
    );
    assert_eq!((slips, rest), (0, 0.0), "no slip below the friction limit");
    assert!(
        (after + sag).abs() < 0.02 * limit,
        "the lift gives the deflection back: {after} m, the weight alone -{sag} m"
    );

    let (stretch, (held, slid), after, rest, slips) = press(f64::INFINITY, 60);
    assert!(
        slips > 0 && slid > 0.2 * limit,
        "slid {slid} m in {slips} steps"
    );
    assert!(
        (held - limit).abs() < 0.03 * limit && stretch < 1.1 * limit,
        "the spring holds the friction limit while the peg slides: {held} m (largest {stretch} \
         m) against {limit} m"
    );
    assert_eq!(rest, slid, "nothing slips on the way up");
    assert!(
        (after - (rest - sag)).abs() < 0.02 * limit,
        "the peg stays where it slid to: {after} m against {rest} m less the weight's {sag} m"
    );
}

#[test]
fn stored_configurations_without_a_grasp_read_as_rigid_and_bad_values_are_named() {
    let mut v = serde_json::to_value(SceneConfig::default()).unwrap();
    v.as_object_mut().unwrap().remove("grasp");
    let c: SceneConfig = serde_json::from_value(v).unwrap();
    assert_eq!(c.grasp, Grasp::Rigid);
    let c = compliant();
    let back: SceneConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
    assert_eq!(back, c);
    let Grasp::Compliant(g) = c.grasp else {
        unreachable!()
    };
    let bad = SceneConfig {
        grasp: Grasp::Compliant(ocm_peg::GraspCompliance {
            slip_force_n: -1.0,
            ..g
        }),
        ..c
    };
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("slip_force_n"), "{e}");
    let e = SceneConfig::default()
        .gel_grasp(f64::NAN)
        .unwrap_err()
        .to_string();
    assert!(e.contains("friction"), "{e}");
}
