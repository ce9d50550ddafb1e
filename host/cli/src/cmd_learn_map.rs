//! `ocm learn train map` and `ocm learn eval --map`: the mapping MLPs of App. D (f_SP, its
//! inverse, f_RS) trained and scored against the surrogate's interpolant.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::progress::bar_if;
use anyhow::{Context, Result, bail};
use ocm_dynamics::mapping::{
    MapConfig, MapRole, PosturePairs, SurrogateMlp, TrainedMap, dissertation_train_config,
};
use ocm_dynamics::pressure_match::{self, PressureMatchConfig, PressurePair};
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_learn::{LrSchedule, TrainConfig, write_curve};
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::{self, ReducedProbe};
use ocm_mor::xs::XsProbe;
use ocm_surrogate::fem_samples::FemSamples;
use ocm_surrogate::mapping::{Match, match_samples};
use ocm_surrogate::model::{MapErrors, SurrogateModel, map_errors};
use serde::Serialize;

use crate::cmd_fem::{BELLOWS_MESH, data_path};
use crate::cmd_learn_args::{EvalArgs, TrainArgs};

/// f_RS checkpoint name in the output folder.
const FRS_FILE: &str = "frs.ckpt";

/// The surrogate folder's model, samples and the held-out Algorithm 1 postures.
struct SurrogateData {
    model: SurrogateModel,
    samples: FemSamples,
    held: Vec<Match>,
    train: Vec<Match>,
}

fn read_surrogate(dir: &Path) -> Result<SurrogateData> {
    let model = SurrogateModel::read(&dir.join("surrogate.json"))
        .with_context(|| format!("reading {}/surrogate.json", dir.display()))?;
    let samples = FemSamples::read(&dir.join("fem_samples.json"))
        .with_context(|| format!("reading {}/fem_samples.json", dir.display()))?;
    if samples.samples.len() != model.training_postures.len() || samples.held_out.is_empty() {
        bail!(
            "{}: {} training samples but {} stored postures, {} held-out samples",
            dir.display(),
            samples.samples.len(),
            model.training_postures.len(),
            samples.held_out.len()
        );
    }
    let chain = model.geometry.chain;
    let train: Vec<Match> = samples
        .samples
        .iter()
        .zip(&model.training_postures)
        .map(|(s, q)| Match {
            posture: *q,
            error_m: (chain.tcp(q) - nalgebra::Vector3::from(s.tcp_m)).norm(),
        })
        .collect();
    let held = match_samples(
        &chain,
        &model.limits,
        &samples.held_out,
        &model.match_config,
        |_| {},
    )?;
    Ok(SurrogateData {
        model,
        samples,
        held,
        train,
    })
}

/// Errors of one regression on the training and held-out samples, in the units users read.
#[derive(Serialize)]
struct RegressionScores {
    regression: String,
    training: Scores,
    held_out: Scores,
}

#[derive(Serialize)]
struct Scores {
    samples: usize,
    tcp_rmse_mm: f64,
    tcp_max_mm: f64,
    rotation_mae_deg: f64,
    extension_mae_mm: f64,
    inverse_rmse_kpa: f64,
}

impl From<MapErrors> for Scores {
    fn from(e: MapErrors) -> Self {
        Self {
            samples: e.samples,
            tcp_rmse_mm: 1e3 * e.mapped_tcp_rmse_m,
            tcp_max_mm: 1e3 * e.mapped_tcp_max_m,
            rotation_mae_deg: e.rotation_mae_rad.to_degrees(),
            extension_mae_mm: 1e3 * e.extension_mae_m,
            inverse_rmse_kpa: e.inverse_rmse_kpa,
        }
    }
}

fn score(
    d: &SurrogateData,
    map: &ocm_surrogate::mapping::ActuationMap,
) -> Result<RegressionScores> {
    let g = &d.model.geometry;
    Ok(RegressionScores {
        regression: map.regression_name().to_string(),
        training: map_errors(g, map, &d.samples.samples, &d.train)?.into(),
        held_out: map_errors(g, map, &d.samples.held_out, &d.held)?.into(),
    })
}

fn fsp_scores(d: &SurrogateData, mlp: SurrogateMlp) -> Result<serde_json::Value> {
    let rbf = score(d, &d.model.map)?;
    let with_mlp = d.model.map.clone().with_regressor(Arc::new(mlp));
    let mlp = score(d, &with_mlp)?;
    Ok(serde_json::json!({
        "mlp": mlp, "rbf": rbf,
        "dissertation": {"rotation_mae_deg": 0.32, "extension_mae_mm": 4.23},
    }))
}

/// The reduced model and its X_S reader.
fn load_rom(dir: &Path, mesh: Option<PathBuf>) -> Result<(ReducedModel, ReducedProbe)> {
    let path = data_path(mesh, None, BELLOWS_MESH)?;
    let b = Bellows::load(&path, BellowsConfig::default())?;
    let hash = store::model_hash(&b);
    let (v, _) = store::load_basis(dir, &hash, 3 * b.model.num_nodes())?;
    let gal = ReducedModel::galerkin(&b.model, v, &b.top_face)?;
    let (rom, _) = store::load_rom(dir, &gal)?;
    let probe = ReducedProbe::new(XsProbe::of_bellows(&b), &rom);
    Ok((rom, probe))
}

/// f_RS pairs of the training and held-out FEM samples, and the held-out samples kept.
#[allow(clippy::type_complexity)]
fn rs_pairs(
    d: &SurrogateData,
    rom: &ReducedModel,
    probe: &ReducedProbe,
    show: bool,
) -> Result<(
    Vec<PressurePair>,
    Vec<PressurePair>,
    Vec<([f64; 3], [f64; 3])>,
    usize,
)> {
    let cfg = PressureMatchConfig::default();
    let set = |s: &[ocm_surrogate::fem_samples::FemSample]| -> Vec<([f64; 3], [f64; 3])> {
        s.iter().map(|s| (s.pressures_kpa, s.tcp_m)).collect()
    };
    let (tr, ho) = (set(&d.samples.samples), set(&d.samples.held_out));
    let pb = bar_if(tr.len() + ho.len(), "f_RS pairs", show);
    let (a, fa) =
        pressure_match::match_samples(rom, probe, &tr, &cfg, |k| pb.set_position(k as u64))?;
    let (b, fb) = pressure_match::match_samples(rom, probe, &ho, &cfg, |k| {
        pb.set_position((tr.len() + k) as u64)
    })?;
    pb.finish_and_clear();
    let kept = ho
        .iter()
        .enumerate()
        .filter(|(i, _)| !fb.contains(i))
        .map(|(_, s)| *s)
        .collect();
    Ok((a, b, kept, fa.len() + fb.len()))
}

/// Held-out scores of f_RS: its pressure error against the matched pressures, and the reduced
/// model's static TCP at f_RS(P_R) and at P_R itself against the full FEM's.
fn frs_scores(
    frs: &TrainedMap,
    pairs: &[PressurePair],
    d_held: &[([f64; 3], [f64; 3])],
    rom: &ReducedModel,
    probe: &ReducedProbe,
) -> Result<serde_json::Value> {
    let x: Vec<f64> = pairs.iter().flat_map(|p| p.real_kpa).collect();
    let y = frs.predict(&x)?;
    let (mut mae, mut tcp_map, mut tcp_id, mut tcp_match) = (0.0, 0.0, 0.0, 0.0);
    let (mut fail, mut n_ok) = (0usize, 0usize);
    for (i, (p, (_, tcp))) in pairs.iter().zip(d_held).enumerate() {
        let ps: [f64; 3] = std::array::from_fn(|k| y[3 * i + k].clamp(-20.0, 35.0));
        mae += (0..3).map(|k| (ps[k] - p.sim_kpa[k]).abs()).sum::<f64>() / 3.0;
        let target = nalgebra::Vector3::from(*tcp);
        let t_id = pressure_match::reduced_static_tcp(rom, probe, &p.real_kpa, 4)?;
        let Ok(t_map) = pressure_match::reduced_static_tcp(rom, probe, &ps, 4) else {
            fail += 1;
            continue;
        };
        n_ok += 1;
        tcp_map += (t_map - target).norm_squared();
        tcp_id += (t_id - target).norm_squared();
        tcp_match += p.tcp_error_m * p.tcp_error_m;
    }
    let n = pairs.len().max(1) as f64;
    Ok(serde_json::json!({
        "samples": pairs.len(),
        "pressure_mae_kpa": mae / n,
        "reduced_tcp_rmse_mm_at_frs": 1e3 * (tcp_map / n_ok.max(1) as f64).sqrt(),
        "reduced_statics_fail_at_frs": fail,
        "reduced_tcp_rmse_mm_at_same_pressure": 1e3 * (tcp_id / n_ok.max(1) as f64).sqrt(),
        "reduced_tcp_rmse_mm_at_matched_pressure": 1e3 * (tcp_match / n_ok.max(1) as f64).sqrt(),
        "dissertation_frs_kpa": 0.13,
    }))
}

/// `ocm learn train map`.
pub fn train(a: &TrainArgs) -> Result<()> {
    let dir = a
        .data
        .data
        .as_deref()
        .context("--data DIR (the folder of `ocm surrogate map`) is required for map")?;
    let d = read_surrogate(dir)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut cfg: TrainConfig = dissertation_train_config(a.seed);
    cfg.epochs = a.epochs.unwrap_or(cfg.epochs);
    cfg.batch_size = a.batch_size.unwrap_or(cfg.batch_size);
    cfg.learning_rate = a.lr.unwrap_or(cfg.learning_rate);
    cfg.patience = a.patience.unwrap_or(cfg.patience);
    cfg.lr_schedule = LrSchedule::cosine_to(a.lr_final);
    let start = std::time::Instant::now();
    let pairs = PosturePairs::from_matches(&d.samples.samples, &d.train)?;
    let (mlp, c1, c2) = SurrogateMlp::train(&pairs, &cfg, a.seed)?;
    mlp.save(&a.out)?;
    write_curve(&a.out, "fsp_loss", "f_SP (pressures to joints)", &c1)?;
    write_curve(
        &a.out,
        "fsp_inverse_loss",
        "inverse f_SP (groups to pressures)",
        &c2,
    )?;
    let fsp_seconds = start.elapsed().as_secs_f64();
    let mut summary = serde_json::json!({
        "model": "map", "surrogate": dir, "train_samples": pairs.len(),
        "held_out_samples": d.samples.held_out.len(), "fsp_train_seconds": fsp_seconds,
        "fsp_epochs_run": c1.len(), "fsp_inverse_epochs_run": c2.len(),
        "fsp": fsp_scores(&d, mlp)?,
    });
    if let Some(rom_dir) = &a.rom {
        let (rom, probe) = load_rom(rom_dir, a.mesh.clone())?;
        let t = std::time::Instant::now();
        let (tr, ho, held, failed) = rs_pairs(&d, &rom, &probe, !a.json)?;
        let pair_seconds = t.elapsed().as_secs_f64();
        write_pairs(&a.out.join("frs_pairs.csv"), &tr, &ho)?;
        let x: Vec<f64> = tr.iter().flat_map(|p| p.real_kpa).collect();
        let y: Vec<f64> = tr.iter().flat_map(|p| p.sim_kpa).collect();
        let (frs, c3) = TrainedMap::train(
            &x,
            &y,
            &MapConfig::dissertation(MapRole::PressureToPressure, 3, 3),
            &cfg,
            a.seed.wrapping_add(2),
        )?;
        frs.save(&a.out.join(FRS_FILE))?;
        write_curve(
            &a.out,
            "frs_loss",
            "f_RS (full FEM to reduced pressures)",
            &c3,
        )?;
        let mut scores = frs_scores(&frs, &ho, &held, &rom, &probe)?;
        scores["pair_seconds"] = pair_seconds.into();
        scores["samples_where_reduced_statics_fail"] = failed.into();
        scores["epochs_run"] = c3.len().into();
        scores["rom"] = serde_json::to_value(rom_dir)?;
        summary["frs"] = scores;
    }
    summary["train_seconds"] = start.elapsed().as_secs_f64().into();
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    print_summary(&summary, a.json)
}

fn write_pairs(path: &Path, train: &[PressurePair], held: &[PressurePair]) -> Result<()> {
    let mut csv = String::from(
        "set,real_p1_kpa,real_p2_kpa,real_p3_kpa,sim_p1_kpa,sim_p2_kpa,sim_p3_kpa,tcp_error_mm\n",
    );
    for (set, list) in [("training", train), ("held_out", held)] {
        for p in list {
            csv.push_str(&format!(
                "{set},{},{},{},{:.6},{:.6},{:.6},{:.6}\n",
                p.real_kpa[0],
                p.real_kpa[1],
                p.real_kpa[2],
                p.sim_kpa[0],
                p.sim_kpa[1],
                p.sim_kpa[2],
                1e3 * p.tcp_error_m
            ));
        }
    }
    std::fs::write(path, csv).with_context(|| format!("writing {}", path.display()))
}

fn print_summary(s: &serde_json::Value, json: bool) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(s)?);
        return Ok(());
    }
    for r in ["mlp", "rbf"] {
        let h = &s["fsp"][r]["held_out"];
        println!(
            "f_SP {r}: held-out TCP RMSE {:.3} mm (max {:.3}), joints {:.3} deg / {:.3} mm, inverse {:.3} kPa",
            h["tcp_rmse_mm"].as_f64().unwrap_or(f64::NAN),
            h["tcp_max_mm"].as_f64().unwrap_or(f64::NAN),
            h["rotation_mae_deg"].as_f64().unwrap_or(f64::NAN),
            h["extension_mae_mm"].as_f64().unwrap_or(f64::NAN),
            h["inverse_rmse_kpa"].as_f64().unwrap_or(f64::NAN),
        );
    }
    if let Some(f) = s.get("frs") {
        println!(
            "f_RS: held-out pressure MAE {:.3} kPa; reduced TCP RMSE {:.3} mm at f_RS(P) vs {:.3} mm at P",
            f["pressure_mae_kpa"].as_f64().unwrap_or(f64::NAN),
            f["reduced_tcp_rmse_mm_at_frs"].as_f64().unwrap_or(f64::NAN),
            f["reduced_tcp_rmse_mm_at_same_pressure"]
                .as_f64()
                .unwrap_or(f64::NAN),
        );
    }
    Ok(())
}

/// `ocm learn eval --map DIR --data SURROGATE_DIR [--rom ROM]`.
pub fn eval(map_dir: &Path, a: &EvalArgs) -> Result<()> {
    let dir = a
        .data
        .data
        .as_deref()
        .context("--data DIR (the folder of `ocm surrogate map`) is required with --map")?;
    let d = read_surrogate(dir)?;
    let mlp = SurrogateMlp::load(map_dir)
        .with_context(|| format!("loading the mapping networks in {}", map_dir.display()))?;
    let mut summary = serde_json::json!({
        "model": "map", "surrogate": dir, "fsp": fsp_scores(&d, mlp)?,
    });
    let frs_path = map_dir.join(FRS_FILE);
    if let Some(rom_dir) = &a.rom {
        let frs = TrainedMap::load(&frs_path)
            .with_context(|| format!("loading {}", frs_path.display()))?;
        let (rom, probe) = load_rom(rom_dir, a.mesh.clone())?;
        let held: Vec<([f64; 3], [f64; 3])> = d
            .samples
            .held_out
            .iter()
            .map(|s| (s.pressures_kpa, s.tcp_m))
            .collect();
        let (pairs, failed) = pressure_match::match_samples(
            &rom,
            &probe,
            &held,
            &PressureMatchConfig::default(),
            |_| {},
        )?;
        let held: Vec<_> = held
            .iter()
            .enumerate()
            .filter(|(i, _)| !failed.contains(i))
            .map(|(_, s)| *s)
            .collect();
        summary["frs"] = frs_scores(&frs, &pairs, &held, &rom, &probe)?;
        summary["frs"]["samples_where_reduced_statics_fail"] = failed.len().into();
    }
    print_summary(&summary, a.json)
}
