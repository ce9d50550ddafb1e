//! Trajectory replay: a demonstration's path replayed with its in-hand error reaches the depth
//! the demonstration reached; path files with bad content are refused naming line and column.

use ocm_peg::replay::{read_path, replay, write_frames, write_path};
use ocm_peg::{
    ActionNoise, ContactFeatures, DemoSet, DemoSettings, ExpertConfig, InHandError, Randomisation,
    SceneConfig,
};

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("ocm-peg-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn replaying_a_demonstration_reproduces_its_insertion() {
    let scene = SceneConfig::default();
    let settings = DemoSettings {
        count: 2,
        seed: 11,
        scene: scene.clone(),
        randomisation: Randomisation::default(),
        expert: ExpertConfig::default(),
        noise: ActionNoise::default(),
    };
    let set = DemoSet::collect(&settings, &ContactFeatures, &mut |_| {}).unwrap();
    let dir = tmp("replay");
    let outcome = set.outcomes.iter().find(|o| o.success).unwrap();
    let csv = dir.join("demo.csv");
    write_path(&csv, &set.paths[0]).unwrap();
    let rows = read_path(&csv).unwrap();
    assert_eq!(rows.len(), set.paths[0].len());
    let frames = replay(
        &scene,
        &rows,
        outcome.trial.error,
        outcome.trial.hole_m,
        &ContactFeatures,
        &mut |_, _| {},
    )
    .unwrap();
    let last = frames.last().unwrap();
    // The demonstration stopped when its tip reached the success depth; the replay follows the
    // recorded gripper poses, so its tip ends there too (to the tracking error of one step).
    for k in 0..3 {
        assert!(
            (last.tip_m[k] - outcome.tip_m[k]).abs() < 2e-4,
            "tip {k}: replay {:?} vs demonstration {:?}",
            last.tip_m,
            outcome.tip_m
        );
    }
    assert!(
        frames
            .iter()
            .all(|f| f.force_n[0] > 0.0 && f.force_n[1] > 0.0)
    );
    write_frames(
        &dir.join("out"),
        &frames,
        outcome.trial.error,
        "contact-features",
    )
    .unwrap();
    let lat = ocm_fem::npy::read_f64_2d(dir.join("out/latents.npy")).unwrap();
    assert_eq!((lat.rows, lat.cols), (frames.len(), 20));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_path_files_name_line_and_column() {
    let dir = tmp("badpath");
    let cases = [
        ("time_s,x_m,y_m,z_m\n0,0,0,0\n", "roll_rad"),
        (
            "time_s,x_m,y_m,z_m,roll_rad\n0,0,0,0.05,0\n1,0,abc,0.05,0\n",
            "line 3, column y_m",
        ),
        (
            "time_s,x_m,y_m,z_m,roll_rad\n0,0,0,0.05,0\n1,0,NaN,0.05,0\n",
            "not finite",
        ),
        (
            "time_s,x_m,y_m,z_m,roll_rad\n0,0,0,0.05,0\n0,0,0,0.05,0\n",
            "does not increase",
        ),
        (
            "time_s,x_m,y_m,z_m,roll_rad\n0,0,0,0.05,0\n",
            "at least two",
        ),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let p = dir.join(format!("p{i}.csv"));
        std::fs::write(&p, text).unwrap();
        let e = read_path(&p).unwrap_err().to_string();
        assert!(e.contains(want) && e.contains(&format!("p{i}.csv")), "{e}");
    }
    let e = read_path(&dir.join("missing.csv")).unwrap_err().to_string();
    assert!(e.contains("missing.csv"), "{e}");
    // A path of 1e12 s would be billions of frames: refused before the scene is built.
    let e = replay(
        &SceneConfig::default(),
        &[[0.0, 0.0, 0.0, 0.05, 0.0], [1e12, 0.0, 0.0, 0.04, 0.0]],
        InHandError::default(),
        [0.0; 2],
        &ContactFeatures,
        &mut |_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("frames") && e.contains("1000000000000 s"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
