//! One-step consistency of the Galerkin reduced model against the full FEM around the input
//! jumps of a held-out sequence: `cargo run --release -p ocm-mor --example one_step -- S RANK [SEQ]`
//! (S a snapshot folder of `ocm mor snapshots`; SEQ the sequence index, default the first held-out
//! one). MOR_PG=1: the Petrov-Galerkin model with the test basis J0^-1 V (J0 the step matrix at
//! rest) instead; MOR_PG=2: with the step matrix at each start state (a full factorisation each).
//!
//! The full model runs the sequence; the reduced model (plain Galerkin, rtol 1e-10, damping tangent
//! at every step start) starts from the projected full state of step j (q = V^T u, backward-Euler
//! velocity of the projected states) and takes three steps. Printed: the TCP error after each step
//! next to that of the projected full state (the basis floor), and the relative error of the
//! reduced increment. Then, at the projected full solution of a step, the terms of the reduced
//! residual M_r a + D_r v + f_r - g_r, and the defect of f_r - g_r against V^T of the full
//! model's net nodal force: which term of the reduced step disagrees with the full model.
use nalgebra::{DMatrix, DVector};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_fem::model::{Pattern, State};
use ocm_fem::solve::dynamics::Integrator;
use ocm_mor::pod::{PodOptions, Truncation, pod};
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::{self, ReducedProbe};
use ocm_mor::xs::XsProbe;

fn main() -> ocm_mor::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = std::path::PathBuf::from(a.first().map_or("target/mor-figures", |s| s.as_str()));
    let r: usize = a.get(1).and_then(|s| s.parse().ok()).unwrap_or(48);
    let path = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
        .map_err(|e| ocm_mor::MorError::Invalid(e.to_string()))?;
    let b = Bellows::load(&path, BellowsConfig::default())?;
    let s = store::load_snapshots(&dir, &store::model_hash(&b))?;
    let seq: u64 = a
        .get(2)
        .and_then(|v| v.parse().ok())
        .unwrap_or(s.rec.sequences as u64);
    let train = s.matrix(0, s.train_rows());
    let p = pod(
        train.as_ref(),
        &PodOptions {
            truncation: Truncation::Rank(r),
            ..PodOptions::default()
        },
    )?;
    drop(train);
    let n = s.disp.cols;
    let v = DMatrix::from_fn(n, r, |i, j| p.modes[(i, j)]);
    // MOR_PG: Petrov-Galerkin with the test basis J0^-1 V instead of Galerkin.
    let mut rom = if std::env::var("MOR_PG").is_ok() {
        let w = ocm_mor::modes::step_test_basis(&b.model, &v, s.rec.dt_s)?;
        ReducedModel::petrov_galerkin(&b.model, v.clone(), w, &b.top_face)?
    } else {
        ReducedModel::galerkin(&b.model, v.clone(), &b.top_face)?
    };
    rom.rtol = 1e-10;
    rom.damping_tangent_age = 1;
    let probe = XsProbe::of_bellows(&b);
    let rp = ReducedProbe::new(probe.clone(), &rom);
    let drive = ocm_mor::drive::DriveConfig {
        dt_s: s.rec.dt_s,
        ..ocm_mor::drive::DriveConfig::default()
    };
    let h = drive.dt_s;
    let inputs = ocm_mor::drive::sequence(&drive, s.rec.seed, seq, s.rec.steps);
    // The steps whose pressures jump by more than 10 kPa, and a quiet reference step.
    let jumps: Vec<usize> = (2..inputs.len() - 3)
        .filter(|&j| {
            (0..3).any(|c| (inputs[j].pressure_kpa[c] - inputs[j - 1].pressure_kpa[c]).abs() > 10.0)
        })
        .collect();
    let mut starts = vec![2usize.max(inputs.len() / 4)];
    for &j in jumps.iter().take(3) {
        starts.extend([j - 1, j, j + 1, j + 3]);
    }
    let last = starts.iter().max().copied().unwrap_or(0) + 3;
    let mut sim = ocm_mor::full::FullSim::new(&b)?;
    let mut states: Vec<State> = vec![];
    for inp in inputs.iter().take(last + 1) {
        sim.step(inp, h)?;
        states.push(sim.state.clone());
    }
    let q_of = |st: &State| -> DVector<f64> {
        v.transpose() * DVector::from_fn(n, |d, _| st.x[d] - b.model.rest[d / 3][d % 3])
    };
    println!("rank {r}, sequence {seq}, pressure jumps > 10 kPa at steps {jumps:?}");
    for &start in &starts {
        let q0 = q_of(&states[start]);
        let mut rs = rom.rest_state();
        rs.v = (&q0 - q_of(&states[start - 1])) / h;
        rs.q = q0.clone();
        // MOR_PG=2: the test basis of the step matrix at the start state itself (an oracle: a
        // sparse factorisation per step).
        let local;
        let rom = if std::env::var("MOR_PG").is_ok_and(|v| v == "2") {
            let x: Vec<f64> = (0..n)
                .map(|d| b.model.rest[d / 3][d % 3] + (&v * &q0)[d])
                .collect();
            let p: Vec<f64> = inputs[start + 1]
                .pressure_kpa
                .iter()
                .map(|p| p * 1e3)
                .collect();
            let w = ocm_mor::modes::step_test_basis_at(&b.model, &v, h, &x, &p)?;
            let mut m = ReducedModel::petrov_galerkin(&b.model, v.clone(), w, &b.top_face)?;
            m.rtol = 1e-10;
            m.damping_tangent_age = 1;
            local = m;
            &local
        } else {
            &rom
        };
        let mut line = format!("from step {start}:");
        let mut qn = q0;
        for k in 1..=3 {
            rom.step(&mut rs, &inputs[start + k], h, Integrator::ImplicitEuler)?;
            let full = probe.of_full_state(&states[start + k]);
            let qf = q_of(&states[start + k]);
            let e =
                |x: &[f64; 16]| (0..3).map(|d| (x[d] - full[d]).powi(2)).sum::<f64>().sqrt() * 1e3;
            line += &format!(
                " +{k}: TCP {:.4} mm (floor {:.4}), increment error {:.1}%;",
                e(&rp.compact_state(&rs.q, &rs.v)),
                e(&rp.compact_state(&qf, &rs.v)),
                100.0 * (&rs.q - &qf).norm() / (&qf - &qn).norm()
            );
            qn = qf;
        }
        println!("{line}");
    }
    let pat = Pattern::new(&b.model)?;
    let masses = b.model.nodal_masses();
    for &j in &starts {
        let (q0, q1, q2) = (q_of(&states[j - 2]), q_of(&states[j - 1]), q_of(&states[j]));
        let vp = (&q2 - &q1) / h;
        let ap = (&q2 - &q1) / (h * h) - (&q1 - &q0) / (h * h);
        let inp = &inputs[j];
        let k1 = rom
            .internal(&q1, true)?
            .k
            .unwrap_or_else(|| DMatrix::zeros(r, r));
        let dg1 = rom
            .external(&q1, inp, true)
            .1
            .unwrap_or_else(|| DMatrix::zeros(r, r));
        let kd = k1 - dg1;
        let fg = rom.internal(&q2, false)?.f_int - rom.external(&q2, inp, false).0;
        let ma = &rom.mass * &ap;
        let dv = (&rom.mass * rom.alpha + &kd * rom.beta) * &vp;
        let st = &states[j];
        let ev = b
            .model
            .evaluate(&pat, &st.x, &b.loads_kpa(&inp.pressure_kpa), 1.0, false)?;
        let fgf = v.transpose() * DVector::from_fn(n, |d, _| ev.f_int[d] - ev.f_ext[d]);
        let ma_full = v.transpose() * DVector::from_fn(n, |d, _| masses[d / 3] * st.a[d]);
        println!(
            "step {j}: reduced residual at the projected full solution {:.3e} N: |M a| {:.3e}, |D v| {:.3e}, |f - g| {:.3e}; (f - g) - V^T (f - g)_full {:.3e}, M_r a - V^T M a_full {:.3e}",
            (&ma + &dv + &fg).norm(),
            ma.norm(),
            dv.norm(),
            fg.norm(),
            (&fg - &fgf).norm(),
            (&ma_full - &ma).norm()
        );
    }
    Ok(())
}
