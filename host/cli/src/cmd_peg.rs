//! `ocm peg`: peg-in-hole with two DIGIT pads: expert demonstrations, behaviour cloning with and
//! without touch, evaluation on randomised trials, trajectory replay.

use crate::plot::{Chart, Series};
use crate::progress::bar;
use anyhow::Context;
use ocm_peg::replay::{npe_fields, read_path, replay, write_frames, write_npe_fields};
use ocm_peg::{
    ActionNoise, BcConfig, BcPolicy, ContactFeatures, DaggerConfig, DemoSet, DemoSettings,
    Evaluation, ExpertConfig, Grasp, InHandError, NpeEncoder, Randomisation, SceneConfig,
    SensorNoise, SpiralSearch, TactileEncoder, TrialSpec, dagger, evaluate_expert, evaluate_policy,
    train_bc,
};
use std::path::{Path, PathBuf};

/// Peg subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum PegCommand {
    /// Runs the privileged scripted expert (noisy execution, clean labels) on seeded random
    /// trials until COUNT have inserted the peg; writes obs.npy, actions.npy, episodes.npy,
    /// demos.json and paths/demo_NNN.csv into OUT.
    Demos {
        /// Successful demonstrations to keep.
        #[arg(long, default_value_t = 137)]
        count: usize,
        /// Seed of the trials and of the execution noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Tactile latents from this trained neural physics engine (`ocm npe train`'s
        /// npe.ckpt: its global contact code h_global per pad) instead of the raw contact
        /// features.
        #[arg(long)]
        npe: Option<PathBuf>,
        #[command(flatten)]
        scene: SceneArgs,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Behaviour cloning (eq 6.19) on the demonstrations in DEMOS: the touch policy
    /// ([proprioception, Z_left, Z_right]) and the no-touch baseline (proprioception only);
    /// writes policy_touch.ckpt, policy_notouch.ckpt and their loss curves into OUT.
    Train {
        /// Folder written by `ocm peg demos`.
        demos: PathBuf,
        /// Training epochs (upper bound; early stopping on the validation loss).
        #[arg(long, default_value_t = 60)]
        epochs: usize,
        /// Seed of the weights, the split and the shuffling.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// After cloning the touch policy, this many DAgger rounds: each runs the policy on
        /// fresh trials (the demonstrations' scene, randomisation and expert), labels every
        /// state it visits with the expert's action there and clones again on all rows (0:
        /// plain cloning).
        #[arg(long, default_value_t = 0)]
        dagger_rounds: usize,
        /// Run the DAgger rounds on the no-touch baseline too (it cannot see what the expert's
        /// labels depend on, and gets worse: see the peg README).
        #[arg(long)]
        dagger_baseline: bool,
        /// Trials per DAgger round.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 100)]
        dagger_trials: usize,
        /// Seed of the DAgger rounds' trials (keep it apart from the evaluation's seeds).
        #[arg(long, default_value_t = 5000)]
        dagger_seed: u64,
        /// With --dagger-rounds: the neural physics engine the demonstrations' latents came
        /// from (required when they were made with `--npe`).
        #[arg(long)]
        npe: Option<PathBuf>,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Success rates over TRIALS randomised trials (a seed other than the demonstrations') of
    /// the touch policy, the no-touch baseline and the expert; writes eval.csv, eval.json and
    /// the tip-depth plots into OUT.
    Eval {
        /// Folder with policy_touch.ckpt and policy_notouch.ckpt (from `ocm peg train`).
        policies: PathBuf,
        /// Trials per controller.
        #[arg(long, default_value_t = 100)]
        trials: usize,
        /// Seed of the trials.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Output folder (default: POLICIES).
        #[arg(long)]
        out: Option<PathBuf>,
        /// The neural physics engine the touch policy's latents come from (required when
        /// its demonstrations were made with `--npe`).
        #[arg(long)]
        npe: Option<PathBuf>,
        /// Evaluate in a scene with this grasp instead of the one the policies were trained in
        /// (e.g. policies cloned with a rigid grasp, run with a compliant one).
        #[arg(long, value_enum)]
        grasp: Option<GraspKind>,
        /// Gel-on-peg friction coefficient of a compliant grasp given with --grasp.
        #[arg(long, value_parser = crate::arg_check::positive, default_value_t = 1.0)]
        pad_friction: f64,
        /// Evaluate with these sensor errors instead of the ones the policies were trained
        /// with.
        #[arg(long, value_enum)]
        sensor_noise: Option<NoiseKind>,
        /// Multiplies every deviation of --sensor-noise.
        #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 1.0)]
        noise_scale: f64,
        /// Correlation time of the sensor errors while a contact lasts, s (0: a fresh draw
        /// each control step; inf: one draw per contact), instead of the policies' own.
        #[arg(long, value_parser = crate::arg_check::non_negative_or_inf)]
        noise_correlation_s: Option<f64>,
        /// Low-pass the latents with this time constant, s, instead of the policies' own.
        #[arg(long, value_parser = crate::arg_check::non_negative)]
        touch_filter_s: Option<f64>,
        /// The hole lies up to this far from where the robot believes it, mm, instead of the
        /// demonstrations' range.
        #[arg(long, value_parser = crate::arg_check::non_negative)]
        hole_error_mm: Option<f64>,
        /// The reference expert's strategy, instead of the one the policies were cloned from.
        #[arg(long, value_enum)]
        expert: Option<ExpertKind>,
        /// A trial fails when it has not inserted after this long, s, instead of the
        /// policies' own limit.
        #[arg(long, value_parser = crate::arg_check::positive)]
        time_limit_s: Option<f64>,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Replays a gripper path (CSV: time_s, x_m, y_m, z_m, roll_rad in the hole frame) holding
    /// the peg with the given in-hand error; writes per-frame contact points, latents and
    /// forces (NPY, CSV) and a plot into OUT.
    Replay {
        /// The path CSV (e.g. paths/demo_000.csv of `ocm peg demos`).
        path: PathBuf,
        /// How the pads hold the peg (with --demo: the demonstrations' grasp unless given).
        #[arg(long, value_enum)]
        grasp: Option<GraspKind>,
        /// Gel-on-peg friction coefficient of a compliant grasp given with --grasp.
        #[arg(long, value_parser = crate::arg_check::positive, default_value_t = 1.0)]
        pad_friction: f64,
        /// In-hand offset along the pads' horizontal direction, mm.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        offset_y_mm: f64,
        /// In-hand offset along the fingers, mm.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        offset_z_mm: f64,
        /// In-hand tilt, degrees.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        tilt_deg: f64,
        /// Take the in-hand error and the hole's position of demonstration N from the
        /// demos.json beside the path's folder (overrides the three values above).
        #[arg(long)]
        demo: Option<usize>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Latents from this trained neural physics engine, and its nodal fields of both pads
        /// per frame (npe_displacement.npy, npe_force.npy).
        #[arg(long)]
        npe: Option<PathBuf>,
        /// With --npe: render the engine's displacement of both pads through the DIGIT
        /// renderer (ocm-tactile's optics: calibration digit/optics/taxim_polycalib.npz over
        /// the background digit/real-frames-edge6/edge6_00.jpg) into images/tactile_NNNN.png,
        /// left pad | right pad.
        #[arg(long)]
        images: bool,
        /// Render every N-th frame (and the last).
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 1)]
        every: usize,
        /// Gel mesh the engine was trained on (in the data folder's digit/).
        #[arg(long, default_value = "DIGIT_v8.vtk")]
        mesh: String,
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
}

/// How the pads hold the peg.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GraspKind {
    /// A fixed joint: the peg never moves in the hand.
    Rigid,
    /// The gels' shear as springs (sliding along the pads, turning about their normal) with
    /// Coulomb slip beyond the pads' friction.
    Compliant,
}

/// What the sensors report.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoiseKind {
    /// The exact contact of the rigid proxies.
    None,
    /// The patch with the perception network's errors on held-out FEM set-ups (centroid
    /// 0.046 mm, rotation 0.010 rad, medians).
    Fem,
    /// The patch with the same network's errors on the real DIGIT frames (centroid 0.81 mm,
    /// rotation 0.094 rad).
    Real,
}

impl NoiseKind {
    /// The errors of this kind, every deviation times `scale`, with correlation time
    /// `correlation_s`.
    fn noise(self, scale: f64, correlation_s: f64) -> SensorNoise {
        match self {
            NoiseKind::None => SensorNoise::default(),
            NoiseKind::Fem => SensorNoise::perception_on_fem(),
            NoiseKind::Real => SensorNoise::perception_on_real_frames(),
        }
        .scaled(scale)
        .correlated(correlation_s)
    }
}

/// The scene options of `ocm peg demos`.
#[derive(clap::Args, Debug)]
pub struct SceneArgs {
    /// How the pads hold the peg.
    #[arg(long, value_enum, default_value_t = GraspKind::Rigid)]
    grasp: GraspKind,
    /// Gel-on-peg friction coefficient of the compliant grasp (the pads hold 2 mu N against
    /// sliding).
    #[arg(long, value_parser = crate::arg_check::positive, default_value_t = 1.0)]
    pad_friction: f64,
    /// Errors of what the sensors report, drawn per sensor and control step.
    #[arg(long, value_enum, default_value_t = NoiseKind::None)]
    sensor_noise: NoiseKind,
    /// Multiplies every deviation of --sensor-noise.
    #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 1.0)]
    noise_scale: f64,
    /// Correlation time of the --sensor-noise errors while a contact lasts, s (0: a fresh
    /// draw each control step; inf: one draw per contact).
    #[arg(long, value_parser = crate::arg_check::non_negative_or_inf, default_value_t = 0.0)]
    noise_correlation_s: f64,
    /// Time constant of a first-order low-pass on each sensor's latent before the policy
    /// reads it, s (0: the latest reading alone).
    #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 0.0)]
    touch_filter_s: f64,
    /// The hole lies up to this far from where the robot believes it, in x and in y, mm
    /// (uniform per trial; nobody sees it, the expert included).
    #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 0.0)]
    hole_error_mm: f64,
    /// The expert's strategy.
    #[arg(long, value_enum, default_value_t = ExpertKind::Align)]
    expert: ExpertKind,
    /// A trial fails when it has not inserted after this long, s.
    #[arg(long, value_parser = crate::arg_check::positive, default_value_t = 8.0)]
    time_limit_s: f64,
}

/// The expert's strategy.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExpertKind {
    /// Aligns the tip over where it believes the hole is and descends.
    Align,
    /// Aligns and descends, and where the tip meets the board slides it along a spiral about
    /// the believed axis while pressing until it drops in (for --hole-error-mm).
    Search,
}

impl ExpertKind {
    fn config(self) -> ExpertConfig {
        ExpertConfig {
            search: (self == ExpertKind::Search).then(SpiralSearch::default),
            ..ExpertConfig::default()
        }
    }
}

/// The default scene with the grasp `kind` (a compliant one derived from the scene's gel).
fn scene_with(kind: GraspKind, pad_friction: f64) -> anyhow::Result<SceneConfig> {
    let base = SceneConfig::default();
    let grasp = match kind {
        GraspKind::Rigid => Grasp::Rigid,
        GraspKind::Compliant => Grasp::Compliant(base.gel_grasp(pad_friction)?),
    };
    Ok(SceneConfig { grasp, ..base })
}

/// The tactile encoder: the engine of `npe` when given, else the raw contact features.
fn encoder(npe: Option<&Path>) -> anyhow::Result<Box<dyn TactileEncoder>> {
    Ok(match npe {
        Some(p) => Box::new(
            NpeEncoder::load(p).with_context(|| format!("loading the engine {}", p.display()))?,
        ),
        None => Box::new(ContactFeatures),
    })
}

fn mkdir(out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))
}

fn tip_depth_chart(out: &Path, stem: &str, title: &str, ev: &Evaluation) -> anyhow::Result<()> {
    let series = ev
        .tip_paths
        .iter()
        .zip(&ev.outcomes)
        .take(20)
        .enumerate()
        .map(|(i, (p, o))| Series {
            label: format!(
                "trial {i} ({})",
                if o.success { "inserted" } else { "failed" }
            ),
            points: p.iter().map(|r| (r[0], r[3] * 1e3)).collect(),
            dots: false,
        })
        .collect();
    Chart {
        title,
        x_label: "time (s)",
        y_label: "peg tip height above the board (mm)",
        series,
        equal_axes: false,
    }
    .write(out, stem)
}

/// Runs a peg subcommand.
pub fn run(cmd: PegCommand) -> anyhow::Result<()> {
    match cmd {
        PegCommand::Demos {
            count,
            seed,
            out,
            npe,
            scene,
            json,
        } => {
            let enc = encoder(npe.as_deref())?;
            mkdir(&out)?;
            let settings = DemoSettings {
                count,
                seed,
                scene: SceneConfig {
                    sensor_noise: scene
                        .sensor_noise
                        .noise(scene.noise_scale, scene.noise_correlation_s),
                    touch_filter_s: scene.touch_filter_s,
                    time_limit_s: scene.time_limit_s,
                    ..scene_with(scene.grasp, scene.pad_friction)?
                },
                randomisation: Randomisation {
                    hole_xy_m: scene.hole_error_mm * 1e-3,
                    ..Randomisation::default()
                },
                expert: scene.expert.config(),
                noise: ActionNoise::default(),
            };
            let pb = bar(count, "expert demonstrations");
            let t = std::time::Instant::now();
            let set =
                DemoSet::collect(&settings, enc.as_ref(), &mut |k| pb.set_position(k as u64))?;
            pb.finish_and_clear();
            let secs = t.elapsed().as_secs_f64();
            set.save(&out)?;
            let tried = set.outcomes.len();
            let slipped = set
                .outcomes
                .iter()
                .filter(|o| o.success && o.slip != [0.0; 3])
                .count();
            let summary = serde_json::json!({
                "demos": set.demos(),
                "grasp": set.settings.scene.grasp,
                "sensor_noise": set.settings.scene.sensor_noise,
                "touch_filter_s": set.settings.scene.touch_filter_s,
                "hole_error_m": set.settings.randomisation.hole_xy_m,
                "expert": set.settings.expert,
                "demos_with_slip": slipped,
                "trials_run": tried,
                "expert_success_rate": set.demos() as f64 / tried.max(1) as f64,
                "rows": set.rows(),
                "encoder": set.encoder,
                "npe": npe,
                "seed": seed,
                "wall_time_s": secs,
                "out": out,
            });
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!(
                    "{} demonstrations ({} trials run), {} control steps, {:.1} s -> {}",
                    set.demos(),
                    tried,
                    set.rows(),
                    secs,
                    out.display()
                );
            }
            Ok(())
        }
        PegCommand::Train {
            demos,
            epochs,
            seed,
            out,
            dagger_rounds,
            dagger_baseline,
            dagger_trials,
            dagger_seed,
            npe,
            json,
        } => {
            let rounds = DaggerConfig {
                rounds: dagger_rounds,
                trials: dagger_trials,
                seed: dagger_seed,
            };
            if dagger_rounds > 0 {
                rounds.validate()?;
            }
            mkdir(&out)?;
            let set = DemoSet::load(&demos)?;
            let enc = encoder(npe.as_deref())?;
            let mut cfg = BcConfig::default();
            cfg.train.epochs = epochs;
            cfg.train.seed = seed;
            cfg.train.progress = !json;
            cfg.weight_seed = seed;
            let mut summary = serde_json::Map::new();
            for (touch, name) in [(true, "touch"), (false, "notouch")] {
                let tr = if dagger_rounds == 0 || !(touch || dagger_baseline) {
                    train_bc(&set, touch, &cfg)?
                } else {
                    let pb = bar(dagger_rounds, &format!("DAgger, {name}"));
                    let tr = dagger(&set, touch, &cfg, &rounds, enc.as_ref(), &mut |r| {
                        pb.set_position(r as u64 - 1)
                    })?;
                    pb.finish_and_clear();
                    tr
                };
                tr.policy.save(&out.join(format!("policy_{name}.ckpt")))?;
                ocm_learn::write_curve(
                    &out,
                    &format!("loss_{name}"),
                    &format!("behaviour cloning, {name}"),
                    &tr.curve,
                )?;
                let m = &tr.policy.meta;
                if !json {
                    println!(
                        "{name}: {} demos, {} rows, best epoch {} (val loss {:.4}), {:.1} s",
                        m.demos, m.rows, m.best_epoch, m.best_loss, m.train_time_s
                    );
                    for r in m.dagger.iter().flat_map(|d| &d.rounds) {
                        println!(
                            "  DAgger round {}: the policy inserted {:.0} % of {} trials, +{} rows \
                             ({} in all), val loss {:.4}, {:.1} s",
                            r.round,
                            100.0 * r.success_rate,
                            dagger_trials,
                            r.rows_added,
                            r.rows,
                            r.best_loss,
                            r.wall_time_s
                        );
                    }
                }
                summary.insert(name.into(), serde_json::to_value(m)?);
            }
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            }
            Ok(())
        }
        PegCommand::Eval {
            policies,
            trials,
            seed,
            out,
            npe,
            grasp,
            pad_friction,
            sensor_noise,
            noise_scale,
            noise_correlation_s,
            touch_filter_s,
            hole_error_mm,
            expert,
            time_limit_s,
            json,
        } => {
            let out = out.unwrap_or_else(|| policies.clone());
            mkdir(&out)?;
            let enc = encoder(npe.as_deref())?;
            let loaded = ["touch", "notouch"].map(|name| {
                let file = policies.join(format!("policy_{name}.ckpt"));
                BcPolicy::load(&file).with_context(|| format!("loading {}", file.display()))
            });
            let [touch, notouch] = loaded;
            let (touch, notouch) = (touch?, notouch?);
            let trained = touch.meta.scene.clone().unwrap_or_default();
            anyhow::ensure!(
                notouch.meta.scene.clone().unwrap_or_default() == trained,
                "the touch and no-touch policies in {} were trained in different scenes",
                policies.display()
            );
            let mut scene = match grasp {
                Some(kind) => SceneConfig {
                    sensor_noise: trained.sensor_noise,
                    touch_filter_s: trained.touch_filter_s,
                    ..scene_with(kind, pad_friction)?
                },
                None => trained.clone(),
            };
            if let Some(kind) = sensor_noise {
                scene.sensor_noise = kind.noise(noise_scale, noise_correlation_s.unwrap_or(0.0));
            } else if let Some(c) = noise_correlation_s {
                scene.sensor_noise = scene.sensor_noise.correlated(c);
            }
            if let Some(tau) = touch_filter_s {
                scene.touch_filter_s = tau;
            }
            if let Some(limit) = time_limit_s {
                scene.time_limit_s = limit;
            }
            let mut rand = touch.meta.randomisation.clone().unwrap_or_default();
            if let Some(mm) = hole_error_mm {
                rand.hole_xy_m = mm * 1e-3;
            }
            let reference = match expert {
                Some(kind) => kind.config(),
                None => touch.meta.expert.clone().unwrap_or_default(),
            };
            let spec = TrialSpec {
                scene: &scene,
                randomisation: &rand,
                seed,
                trials,
            };
            let mut evals = Vec::new();
            for (name, p) in [("touch", touch), ("notouch", notouch)] {
                let file = policies.join(format!("policy_{name}.ckpt"));
                anyhow::ensure!(
                    !p.meta.touch || p.meta.encoder == enc.name(),
                    "{} reads {} latents but the encoder is {}{}",
                    file.display(),
                    p.meta.encoder,
                    enc.name(),
                    if p.meta.encoder == "npe" {
                        ": pass --npe with the engine its demonstrations were made with"
                    } else {
                        ": leave out --npe"
                    }
                );
                let pb = bar(scene.max_control_steps(), &format!("{name} policy"));
                let t = std::time::Instant::now();
                let ev = evaluate_policy(name, &p, spec, enc.as_ref(), &mut |k| {
                    pb.set_position(k as u64)
                })?;
                pb.finish_and_clear();
                evals.push((ev, t.elapsed().as_secs_f64()));
            }
            let t = std::time::Instant::now();
            let ex = evaluate_expert(&reference, spec, enc.as_ref())?;
            evals.push((ex, t.elapsed().as_secs_f64()));
            let mut w = csv::Writer::from_path(out.join("eval.csv"))?;
            w.write_record([
                "controller",
                "trial",
                "success",
                "time_s",
                "tip_x_m",
                "tip_y_m",
                "tip_z_m",
                "offset_y_m",
                "offset_z_m",
                "tilt_rad",
                "hole_x_m",
                "hole_y_m",
                "slip_y_m",
                "slip_z_m",
                "slip_turn_rad",
                "largest_shift_y_m",
                "largest_shift_z_m",
                "largest_turn_rad",
            ])?;
            let mut summary = Vec::new();
            for (ev, secs) in &evals {
                for o in &ev.outcomes {
                    let e = o.trial.error;
                    w.write_record([
                        ev.controller.clone(),
                        o.trial.index.to_string(),
                        u8::from(o.success).to_string(),
                        format!("{:.4}", o.time_s),
                        format!("{:.6e}", o.tip_m[0]),
                        format!("{:.6e}", o.tip_m[1]),
                        format!("{:.6e}", o.tip_m[2]),
                        format!("{:.6e}", e.offset_y_m),
                        format!("{:.6e}", e.offset_z_m),
                        format!("{:.6e}", e.tilt_rad),
                        format!("{:.6e}", o.trial.hole_m[0]),
                        format!("{:.6e}", o.trial.hole_m[1]),
                        format!("{:.6e}", o.slip[0]),
                        format!("{:.6e}", o.slip[1]),
                        format!("{:.6e}", o.slip[2]),
                        format!("{:.6e}", o.largest_shift[0]),
                        format!("{:.6e}", o.largest_shift[1]),
                        format!("{:.6e}", o.largest_shift[2]),
                    ])?;
                }
                tip_depth_chart(
                    &out,
                    &format!("tip_depth_{}", ev.controller),
                    &format!(
                        "{}: {:.0} % inserted",
                        ev.controller,
                        100.0 * ev.success_rate()
                    ),
                    ev,
                )?;
                summary.push(serde_json::json!({
                    "controller": ev.controller,
                    "trials": ev.outcomes.len(),
                    "success_rate": ev.success_rate(),
                    "median_success_time_s": ev.median_success_time_s(),
                    "trials_with_slip": ev.outcomes.iter().filter(|o| o.slip != [0.0; 3]).count(),
                    "largest_turn_in_hand_rad": ev
                        .outcomes
                        .iter()
                        .map(|o| o.largest_shift[2])
                        .fold(0.0, f64::max),
                    "median_largest_turn_in_hand_rad": ev.median_largest_turn_rad(),
                    "wall_time_s": secs,
                }));
            }
            w.flush()?;
            // Success against the size of the in-hand error (what touch has to reveal).
            // Each controller's dots sit slightly apart so that they do not hide each other.
            let series = evals
                .iter()
                .enumerate()
                .map(|(k, (ev, _))| Series {
                    label: format!(
                        "{} (1 = inserted, drawn {:+.2} apart)",
                        ev.controller,
                        0.05 * k as f64
                    ),
                    points: ev
                        .outcomes
                        .iter()
                        .map(|o| {
                            let e = o.trial.error;
                            let lateral = (e.offset_y_m
                                + (scene.peg_length_m - scene.peg_top_m) * e.tilt_rad.sin())
                            .abs();
                            (
                                lateral * 1e3,
                                f64::from(u8::from(o.success)) + 0.05 * k as f64,
                            )
                        })
                        .collect(),
                    dots: true,
                })
                .collect();
            Chart {
                title: "success against the in-hand error at the tip",
                x_label: "|tip displacement by the in-hand error| (mm)",
                y_label: "inserted",
                series,
                equal_axes: false,
            }
            .write(&out, "success_vs_error")?;
            let report = serde_json::json!({
                "seed": seed,
                "encoder": enc.name(),
                "npe": npe,
                "grasp": scene.grasp,
                "trained_grasp": trained.grasp,
                "sensor_noise": scene.sensor_noise,
                "trained_sensor_noise": trained.sensor_noise,
                "touch_filter_s": scene.touch_filter_s,
                "trained_touch_filter_s": trained.touch_filter_s,
                "hole_error_m": rand.hole_xy_m,
                "time_limit_s": scene.time_limit_s,
                "expert": reference,
                "controllers": summary,
            });
            std::fs::write(
                out.join("eval.json"),
                serde_json::to_string_pretty(&report)?,
            )?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                for (ev, secs) in &evals {
                    println!(
                        "{:8} {:5.1} % inserted over {} trials (median {:.2} s to insert), {:.1} s",
                        ev.controller,
                        100.0 * ev.success_rate(),
                        ev.outcomes.len(),
                        ev.median_success_time_s(),
                        secs
                    );
                }
            }
            Ok(())
        }
        PegCommand::Replay {
            path,
            grasp,
            pad_friction,
            offset_y_mm,
            offset_z_mm,
            tilt_deg,
            demo,
            out,
            npe,
            images,
            every,
            mesh,
            data,
            json,
        } => {
            anyhow::ensure!(
                !images || npe.is_some(),
                "--images renders the engine's fields: pass --npe with a trained engine"
            );
            mkdir(&out)?;
            let engine = npe
                .as_deref()
                .map(|p| {
                    NpeEncoder::load(p)
                        .with_context(|| format!("loading the engine {}", p.display()))
                })
                .transpose()?;
            let enc: &dyn TactileEncoder = match &engine {
                Some(e) => e,
                None => &ContactFeatures,
            };
            let rows = read_path(&path)?;
            let (error, hole_m, demo_scene) = match demo {
                Some(k) => {
                    let dir = path
                        .parent()
                        .and_then(Path::parent)
                        .context("the path has no demos folder above it")?;
                    let set = DemoSet::load(dir)?;
                    let trial = set
                        .outcomes
                        .iter()
                        .filter(|o| o.success)
                        .nth(k)
                        .with_context(|| format!("{} has no demonstration {k}", dir.display()))?
                        .trial;
                    (trial.error, trial.hole_m, Some(set.settings.scene))
                }
                None => (
                    InHandError {
                        offset_y_m: offset_y_mm * 1e-3,
                        offset_z_m: offset_z_mm * 1e-3,
                        tilt_rad: tilt_deg.to_radians(),
                    },
                    [0.0; 2],
                    None,
                ),
            };
            let scene = match (grasp, demo_scene) {
                (Some(kind), _) => scene_with(kind, pad_friction)?,
                (None, Some(s)) => s,
                (None, None) => SceneConfig::default(),
            };
            let pb = bar(0, "replay");
            let frames = replay(&scene, &rows, error, hole_m, enc, &mut |k, n| {
                pb.set_length(n as u64);
                pb.set_position(k as u64);
            })?;
            pb.finish_and_clear();
            write_frames(&out, &frames, error, enc.name())?;
            let mut npe_force = None;
            let mut written_images: Option<Vec<PathBuf>> = None;
            if let Some(e) = &engine {
                let pb = bar(frames.len(), "NPE fields");
                let t = std::time::Instant::now();
                let fields = npe_fields(&frames, e, &mut |k, _| pb.set_position(k as u64))?;
                pb.finish_and_clear();
                let secs = t.elapsed().as_secs_f64();
                write_npe_fields(&out, &fields, e)?;
                if images {
                    written_images = Some(render_images(
                        &out.join("images"),
                        &fields,
                        e,
                        data.as_deref(),
                        &mesh,
                        every,
                    )?);
                }
                npe_force = Some((
                    fields
                        .iter()
                        .map(|p| p.clone().map(|f| f.total_force_n()[2]))
                        .collect::<Vec<[f64; 2]>>(),
                    secs,
                ));
            }
            let series = vec![
                Series {
                    label: "left sensor".into(),
                    points: frames.iter().map(|f| (f.time_s, f.force_n[0])).collect(),
                    dots: false,
                },
                Series {
                    label: "right sensor".into(),
                    points: frames.iter().map(|f| (f.time_s, f.force_n[1])).collect(),
                    dots: false,
                },
                Series {
                    label: "peg tip height (mm)".into(),
                    points: frames
                        .iter()
                        .map(|f| (f.time_s, f.tip_m[2] * 1e3))
                        .collect(),
                    dots: false,
                },
            ];
            let mut series = series;
            if let Some((f, _)) = &npe_force {
                // The engine's force on the body in the mesh frame (z up, out of the gel): its
                // z component is the normal force, comparable with the scene's.
                for (s, side) in ["left", "right"].iter().enumerate() {
                    series.push(Series {
                        label: format!("{side} sensor, NPE nodal forces summed"),
                        points: frames
                            .iter()
                            .zip(f)
                            .map(|(fr, v)| (fr.time_s, v[s]))
                            .collect(),
                        dots: false,
                    });
                }
            }
            Chart {
                title: "replay: normal force per sensor and tip height",
                x_label: "time (s)",
                y_label: "force (N) / height (mm)",
                series,
                equal_axes: false,
            }
            .write(&out, "replay")?;
            let summary = serde_json::json!({
                "frames": frames.len(),
                "in_hand_error": error,
                "grasp": scene.grasp,
                "final_tip_m": frames.last().map(|f| f.tip_m),
                "encoder": enc.name(),
                "npe_fields_s": npe_force.as_ref().map(|(_, s)| s),
                "images": written_images.as_ref().map(Vec::len),
                "out": out,
            });
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("{} frames -> {}", frames.len(), out.display());
            }
            Ok(())
        }
    }
}

/// Renders the engine's fields of every `every`-th frame into `dir` (see `--images`).
fn render_images(
    dir: &Path,
    fields: &[[ocm_npe::Fields; 2]],
    npe: &NpeEncoder,
    data: Option<&Path>,
    mesh: &str,
    every: usize,
) -> anyhow::Result<Vec<PathBuf>> {
    use ocm_tactile::gel::{Gel, GelMaterial};
    let digit = ocm_datadir::data_file(data, "digit")?;
    let gel = Gel::digit(digit.join(mesh), GelMaterial::default())?;
    let renderer = ocm_tactile::real::default_renderer(&digit)?;
    let imager = ocm_peg::images::TactileImager::new(&gel, renderer, &npe.npe().surface)
        .with_context(|| format!("the engine and the mesh {mesh}"))?;
    let pb = bar(0, "tactile images");
    let written = ocm_peg::images::write_images(dir, fields, &imager, every, &mut |k, n| {
        pb.set_length(n as u64);
        pb.set_position(k as u64);
    })?;
    pb.finish_and_clear();
    Ok(written)
}
