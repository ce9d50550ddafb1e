//! The scene: contact extraction against the closed-form patch of a flat face pressed into a
//! pad, the expert, determinism, bad inputs.

use ocm_peg::encoder::CONTACT_FEATURES;
use ocm_peg::{
    ContactFeatures, ExpertConfig, Grasp, GripperPose, InHandError, PegScene, Randomisation,
    SceneConfig, TactileEncoder,
};

fn high() -> GripperPose {
    GripperPose {
        z_m: 0.1,
        ..Default::default()
    }
}

/// A flat peg face pressed `squeeze` into each pad: every point is `squeeze` deep, the patch is
/// the face's strip (side = across flats / sqrt 3) from the pads' lower edge to the peg's top,
/// shifted by the in-hand offset (mirrored on the left sensor, whose x is -y of the gripper),
/// and the foundation force is E/h x area x squeeze.
#[test]
fn contact_points_match_a_flat_face_pressed_into_the_pad() {
    let c = SceneConfig::default();
    let e = InHandError {
        offset_y_m: 0.001,
        offset_z_m: 0.002,
        tilt_rad: 0.0,
    };
    let scene = PegScene::new(&c, high(), e).unwrap();
    let side = c.peg_across_flats_m / 3f64.sqrt();
    let top = c.peg_top_m + e.offset_z_m;
    let bottom = -0.5 * c.pad_height_m;
    let contacts = scene.contacts().unwrap();
    for (i, sc) in contacts.iter().enumerate() {
        let shift = if i == 0 { -e.offset_y_m } else { e.offset_y_m };
        assert!(sc.points_m.len() >= 4, "sensor {i}: {:?}", sc.points_m);
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in &sc.points_m {
            assert!(
                (p[2] - c.squeeze_m).abs() < 5e-6,
                "sensor {i} depth {}",
                p[2]
            );
            x0 = x0.min(p[0]);
            x1 = x1.max(p[0]);
            y0 = y0.min(p[1]);
            y1 = y1.max(p[1]);
        }
        let tol = 5e-6;
        assert!(
            (x0 - (shift - 0.5 * side)).abs() < tol,
            "sensor {i} x0 {x0}"
        );
        assert!(
            (x1 - (shift + 0.5 * side)).abs() < tol,
            "sensor {i} x1 {x1}"
        );
        assert!((y0 - bottom).abs() < tol, "sensor {i} y0 {y0}");
        assert!((y1 - top).abs() < tol, "sensor {i} y1 {y1}");
        let area = side * (top - bottom);
        let f = c.gel_modulus_pa / c.gel_thickness_m * area * c.squeeze_m;
        assert!(
            (sc.force_n - f).abs() < 0.02 * f,
            "sensor {i}: {} N vs {f} N",
            sc.force_n
        );
        let z = ContactFeatures.latent(&sc.points_m, sc.force_n).unwrap();
        assert_eq!(z.len(), CONTACT_FEATURES);
        assert!((f64::from(z[2]) - shift * 1e3).abs() < 0.01);
        assert!((f64::from(z[3]) - 0.5 * (top + bottom) * 1e3).abs() < 0.01);
    }
}

/// A tilt of the peg in the pads' plane turns the patch's major axis by the same angle (the
/// strip is long and thin; its clipped ends shift the axis by well under a degree here).
#[test]
fn a_tilted_peg_turns_the_patch_axis() {
    let c = SceneConfig::default();
    let t = 4f64.to_radians();
    let scene = PegScene::new(
        &c,
        high(),
        InHandError {
            tilt_rad: t,
            ..Default::default()
        },
    )
    .unwrap();
    let contacts = scene.contacts().unwrap();
    for (i, sc) in contacts.iter().enumerate() {
        let z = ContactFeatures.latent(&sc.points_m, sc.force_n).unwrap();
        let axis = 0.5 * f64::from(z[8]).atan2(f64::from(z[7]));
        // The tilt turns the peg's axis (0, -sin t, cos t) in the gripper; the right sensor's x
        // is the gripper's y, the left's is -y (mirrored).
        let half_pi = 0.5 * std::f64::consts::PI;
        let expected = if i == 0 { half_pi - t } else { half_pi + t };
        let d = (axis - expected).rem_euclid(std::f64::consts::PI);
        let d = d.min(std::f64::consts::PI - d);
        assert!(
            d < 1f64.to_radians(),
            "sensor {i}: axis {axis} expected {expected}"
        );
    }
}

/// With either grasp.
#[test]
fn the_expert_inserts_and_the_same_seed_gives_the_same_run() {
    let rigid = SceneConfig::default();
    let compliant = SceneConfig {
        grasp: Grasp::Compliant(rigid.gel_grasp(1.0).unwrap()),
        ..rigid.clone()
    };
    let r = Randomisation::default();
    let ex = ExpertConfig::default();
    for c in [rigid, compliant] {
        let run = || {
            ocm_peg::evaluate_expert(
                &ex,
                ocm_peg::TrialSpec {
                    scene: &c,
                    randomisation: &r,
                    seed: 7,
                    trials: 3,
                },
                &ContactFeatures,
            )
            .unwrap()
        };
        let a = run();
        let b = run();
        assert_eq!(a, b);
        assert_eq!(a.success_rate(), 1.0, "{:?} {:?}", c.grasp, a.outcomes);
    }
}

#[test]
fn bad_inputs_are_errors_naming_the_value() {
    let c = SceneConfig::default();
    let e = PegScene::new(
        &c,
        GripperPose {
            x_m: f64::NAN,
            ..high()
        },
        InHandError::default(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("start x_m"), "{e}");
    let e = PegScene::new(
        &c,
        high(),
        InHandError {
            offset_y_m: 0.01,
            ..Default::default()
        },
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("off the pads"), "{e}");
    let mut scene = PegScene::new(&c, high(), InHandError::default()).unwrap();
    let e = scene
        .step([0.0, f64::INFINITY, 0.0, 0.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("action[1]"), "{e}");
    let bad = SceneConfig {
        clearance_m: -1.0,
        ..SceneConfig::default()
    };
    let e = PegScene::new(&bad, high(), InHandError::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("clearance_m"), "{e}");
}

/// The sensors' errors reach what a policy sees, are drawn per trial from its seed (the same
/// seed and trial read the same, another trial reads otherwise) and leave the physics alone.
#[test]
fn sensor_errors_are_seeded_per_trial_and_move_only_the_reading() {
    let c = SceneConfig {
        sensor_noise: ocm_peg::SensorNoise::perception_on_real_frames(),
        ..SceneConfig::default()
    };
    let reading = |seed: u64, stream: u64| {
        let mut scene = PegScene::new(&c, high(), InHandError::default()).unwrap();
        scene.seed_sensors(seed, stream);
        let exact = scene.contacts().unwrap();
        let mut read = Vec::new();
        for _ in 0..3 {
            let [l, r] = scene.sensed().unwrap();
            read.push((
                ContactFeatures.latent(&l.points_m, l.force_n).unwrap(),
                ContactFeatures.latent(&r.points_m, r.force_n).unwrap(),
            ));
            scene.step([0.0; 4]).unwrap();
        }
        (exact, read, scene.peg_tip())
    };
    let (exact, a, tip_a) = reading(5, 0);
    let (_, b, _) = reading(5, 0);
    let (_, other, tip_other) = reading(5, 1);
    assert_eq!(a, b);
    assert_ne!(a, other);
    assert_eq!(tip_a, tip_other, "the errors do not touch the physics");
    let z = ContactFeatures
        .latent(&exact[0].points_m, exact[0].force_n)
        .unwrap();
    assert_ne!(a[0].0, z, "the reading is not the exact contact");
    assert_ne!(a[0].0, a[1].0, "drawn afresh every step");
    // The patch keeps its size and its force (only centroid and rotation have errors here).
    assert!((a[0].0[5] - z[5]).abs() < 1e-4 && a[0].0[9] == z[9]);
}

/// With an infinite correlation time each sensor keeps one error while its contact lasts (the
/// reading's centroid sits at the same offset from the exact one every step), and seeding the
/// sensors for a trial starts it afresh.
#[test]
fn correlated_sensor_errors_hold_through_a_contact_and_restart_with_the_trial() {
    let c = SceneConfig {
        sensor_noise: ocm_peg::SensorNoise::perception_on_real_frames().correlated(f64::INFINITY),
        ..SceneConfig::default()
    };
    let centroid = |p: &[[f64; 3]]| {
        let n = p.len() as f64;
        [
            p.iter().map(|q| q[0]).sum::<f64>() / n,
            p.iter().map(|q| q[1]).sum::<f64>() / n,
        ]
    };
    let offsets = |scene: &mut PegScene| {
        let exact = scene.contacts().unwrap();
        let read = scene.sensed().unwrap();
        [0, 1].map(|k| {
            let (e, r) = (centroid(&exact[k].points_m), centroid(&read[k].points_m));
            [r[0] - e[0], r[1] - e[1]]
        })
    };
    let mut scene = PegScene::new(&c, high(), InHandError::default()).unwrap();
    scene.seed_sensors(5, 0);
    let first = offsets(&mut scene);
    assert!(first[0][0].hypot(first[0][1]) > 1e-6, "{first:?}");
    assert_ne!(first[0], first[1], "each sensor has its own error");
    let same = |a: [[f64; 2]; 2], b: [[f64; 2]; 2]| {
        (0..4).all(|i| (a[i / 2][i % 2] - b[i / 2][i % 2]).abs() < 1e-12)
    };
    for _ in 0..5 {
        scene.step([0.0; 4]).unwrap();
        let now = offsets(&mut scene);
        assert!(same(now, first), "{now:?} {first:?}");
    }
    scene.seed_sensors(5, 0);
    assert!(same(offsets(&mut scene), first));
    scene.seed_sensors(5, 1);
    assert!(!same(offsets(&mut scene), first));
}

/// The low-pass on the latents: a step from 0 to 1 reaches 1 - (1 - a)^k after k control steps
/// (a = dt / (tau + dt)); white reading errors keep a / (2 - a) of their variance; no time
/// constant passes the reading through.
#[test]
fn the_touch_filter_is_a_first_order_low_pass() {
    let tau = 0.1;
    let c = SceneConfig {
        sensor_noise: ocm_peg::SensorNoise::perception_on_real_frames(),
        touch_filter_s: tau,
        ..SceneConfig::default()
    };
    let dt = c.control_dt_s();
    let a = dt / (tau + dt);
    let mut scene = PegScene::new(&c, high(), InHandError::default()).unwrap();
    assert_eq!(scene.low_pass(vec![0.0, 2.0]), vec![0.0, 2.0]);
    for k in 1..=10 {
        let y = scene.low_pass(vec![1.0, 2.0]);
        let expected = 1.0 - (1.0 - a).powi(k);
        assert!(
            (y[0] - expected).abs() < 1e-12,
            "step {k}: {} against {expected}",
            y[0]
        );
        assert!((y[1] - 2.0).abs() < 1e-12);
    }
    // The centroid reading of the left sensor, raw and filtered, over 4,000 control steps.
    let mut scene = PegScene::new(&c, high(), InHandError::default()).unwrap();
    scene.seed_sensors(9, 0);
    let (mut raw, mut low) = (Vec::new(), Vec::new());
    for _ in 0..4000 {
        let obs = ocm_peg::rollout::observe(&mut scene, &ContactFeatures).unwrap();
        let [l, _] = scene.sensed().unwrap();
        raw.push(f64::from(
            ContactFeatures.latent(&l.points_m, l.force_n).unwrap()[2],
        ));
        low.push(obs[4 + 2]);
    }
    let var = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64
    };
    let ratio = var(&low[100..]) / var(&raw[100..]);
    let expected = a / (2.0 - a);
    assert!(
        (ratio - expected).abs() < 0.1 * expected,
        "variance kept {ratio}, a / (2 - a) = {expected}"
    );
    let plain = SceneConfig {
        touch_filter_s: 0.0,
        ..c.clone()
    };
    let mut scene = PegScene::new(&plain, high(), InHandError::default()).unwrap();
    assert_eq!(scene.low_pass(vec![3.0]), vec![3.0]);
    assert_eq!(scene.low_pass(vec![5.0]), vec![5.0]);
    let bad = SceneConfig {
        touch_filter_s: -1.0,
        ..c
    };
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("touch_filter_s"), "{e}");
}
