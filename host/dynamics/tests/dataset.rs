//! Reading `ocm mor` data sets: a row holds the state *after* its inputs' step, so the reader must
//! pair each state with the next row's inputs. Checked on a data set written by `ocm_mor`'s own
//! writer from exact trajectories of a known lumped system: the physics residual of the true
//! system is then at discretisation level, as on trajectories made directly.

use ocm_dynamics::dataset::read_trajectories;
use ocm_dynamics::lumped::demo_system;
use ocm_dynamics::{LumpedModel, Trajectory};
use ocm_mor::dataset::{self, DatasetSpec, ModelKind};
use ocm_mor::drive::{DriveConfig, Input};
use ocm_mor::xs::XS_DIM;

fn rel_rms(model: &LumpedModel, trajs: &[Trajectory]) -> f64 {
    let (r, a) = model.residual_rms(trajs);
    r.iter().zip(&a).map(|(r, a)| r / a).fold(0.0, f64::max)
}

#[test]
fn data_set_rows_are_paired_with_the_inputs_that_drive_the_next_step() {
    let sys = demo_system(XS_DIM, 4).unwrap();
    let dt = 0.01;
    let spec = DatasetSpec {
        model: ModelKind::Reduced,
        model_hash: "m".repeat(64),
        basis_hash: Some("b".repeat(64)),
        samples: 3 * 300,
        sequence_steps: 300,
        seed: 21,
        drive: DriveConfig {
            dt_s: dt,
            ..DriveConfig::default()
        },
    };
    // The simulator writes what `ocm mor dataset` writes: after each step, X_S and its rate.
    let mut simulate = |inputs: &[Input]| -> ocm_mor::Result<Vec<[f64; 2 * XS_DIM]>> {
        let mut p: Vec<f64> = inputs.iter().flat_map(|u| u.pressure_kpa).collect();
        let mut f: Vec<f64> = inputs.iter().flat_map(|u| u.tip_force_n).collect();
        // One more (held) step so that the state after the last input exists.
        p.extend_from_within(p.len() - 3..);
        f.extend_from_within(f.len() - 3..);
        let t = sys.simulate(dt, &[0.0; XS_DIM], &[0.0; XS_DIM], &p, &f, 8);
        Ok((1..=inputs.len())
            .map(|k| {
                let mut row = [0.0; 2 * XS_DIM];
                row[..XS_DIM].copy_from_slice(t.x(k));
                row[XS_DIM..].copy_from_slice(t.v(k));
                row
            })
            .collect())
    };
    let dir = std::env::temp_dir().join(format!("ocm-dynamics-align-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dataset::write_shard(&dir, &spec, 0, 1, &mut simulate, &mut |_, _| {}).unwrap();
    let (manifest, trajs) = read_trajectories(&dir).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(manifest.sequences, 3);
    assert_eq!(trajs.len(), 3);
    // The rest state before the first row is not stored: one step fewer than rows.
    assert!(trajs.iter().all(|t| t.len() == 299), "lengths");
    let aligned = rel_rms(&sys, &trajs);
    eprintln!("aligned {aligned:.4}");
    // Same bound as on directly simulated trajectories (tests/dynamics.rs).
    assert!(
        aligned < 0.05,
        "residual / acceleration read back: {aligned:.4}"
    );
    // Pairing each state with its own row's inputs (the inputs of the step that led to it)
    // breaks the equations of motion wherever an input jumps.
    let stale: Vec<Trajectory> = trajs
        .iter()
        .map(|t| {
            let mut s = t.clone();
            s.pressure_kpa.rotate_right(3);
            s.force_n.rotate_right(3);
            s
        })
        .collect();
    let misaligned = rel_rms(&sys, &stale);
    eprintln!("one step late {misaligned:.4}");
    assert!(
        misaligned > 5.0 * aligned,
        "one-step-late inputs {misaligned:.4} vs {aligned:.4}"
    );
}
