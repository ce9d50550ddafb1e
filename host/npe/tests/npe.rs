//! The engine's contract: order of the contact points, bad inputs, a checkpoint round trip,
//! seeded determinism, and accuracy against the FEM on held-out indentations.

use ocm_learn::{LrSchedule, cpu};
use ocm_npe::data::{Prepared, Sample};
use ocm_npe::fit::{FitOptions, fit, loss};
use ocm_npe::model::NpeConfig;
use ocm_npe::{Npe, NpeError, Surface};

mod common;

/// A 7 x 6 grid of nodes 1 mm apart at z = 2 mm, triangulated.
fn surface() -> Surface {
    common::grid_surface(7, 6, 1e-3, 2e-3)
}

fn engine(seed: u64) -> Npe {
    let s = surface();
    let mut cfg = NpeConfig::new(Prepared::top_center(&s.rest_m), 0.25e-3);
    cfg.layers = 2;
    cfg.width = 12;
    let net = cfg.init(&cpu(), seed).unwrap();
    Npe::new(net, cfg, s).unwrap()
}

/// A small cap of contact points around (cx, cy), `depth_m` deep.
fn cap(cx: f64, cy: f64, depth_m: f64) -> Vec<[f64; 3]> {
    let mut p = Vec::new();
    for a in -4i32..=4 {
        for b in -4i32..=4 {
            let (x, y) = (cx + a as f64 * 0.25e-3, cy + b as f64 * 0.25e-3);
            let r2 = (x - cx).powi(2) + (y - cy).powi(2);
            let z = 2e-3 - depth_m + r2 / (2.0 * 2e-3);
            if z < 2e-3 {
                p.push([x, y, z]);
            }
        }
    }
    p
}

#[test]
fn order_of_contact_points_does_not_matter() {
    let npe = engine(3);
    let pts = cap(3e-3, 2.5e-3, 0.3e-3);
    assert!(pts.len() > 10);
    let a = npe.predict(&pts, 1.2, 0.3e-3).unwrap();
    let mut shuffled = pts.clone();
    shuffled.reverse();
    shuffled.rotate_left(5);
    let b = npe.predict(&shuffled, 1.2, 0.3e-3).unwrap();
    let mut worst: f64 = 0.0;
    for (u, v) in a.displacement_m.iter().zip(&b.displacement_m) {
        for k in 0..3 {
            worst = worst.max((u[k] - v[k]).abs());
        }
    }
    // f32 sums in another order: round-off only.
    assert!(worst < 1e-9, "largest difference {worst} m");
    assert_eq!(
        npe.latent(&pts, 1.2, 0.3e-3).unwrap().len(),
        npe.config.width - 4
    );
    // The field depends on where the contact is (not a constant network).
    let c = npe.predict(&cap(1e-3, 1e-3, 0.3e-3), 1.2, 0.3e-3).unwrap();
    assert_ne!(a.displacement_m, c.displacement_m);
}

#[test]
fn bad_and_empty_inputs_get_defined_answers() {
    let npe = engine(1);
    let n = npe.surface.rest_m.len();
    // No contact points: the gel is untouched.
    let z = npe.predict(&[], 0.0, 0.0).unwrap();
    assert_eq!(z.displacement_m, vec![[0.0; 3]; n]);
    assert_eq!(z.nodal_force_n, vec![[0.0; 3]; n]);
    assert_eq!(
        npe.latent(&[], 0.0, 0.0).unwrap(),
        vec![0.0; npe.config.width - 4]
    );
    // Points off the face or above it are dropped and counted; alone they mean no contact.
    let off = [[50e-3, 1e-3, 1.9e-3], [1e-3, 1e-3, 2.5e-3]];
    let r = npe.predict(&off, 0.5, 0.1e-3).unwrap();
    assert_eq!(r.ignored_points, 2);
    assert_eq!(r.displacement_m, vec![[0.0; 3]; n]);
    let mut mixed = cap(3e-3, 2.5e-3, 0.2e-3);
    let kept = npe.predict(&mixed, 0.5, 0.2e-3).unwrap();
    mixed.extend(off);
    let with_off = npe.predict(&mixed, 0.5, 0.2e-3).unwrap();
    assert_eq!(with_off.ignored_points, 2);
    assert_eq!(with_off.displacement_m, kept.displacement_m);
    // NaN anywhere, negative force or depth, a point through the gel: errors naming it.
    let mut nan = cap(3e-3, 2.5e-3, 0.2e-3);
    nan[4][1] = f64::NAN;
    let e = npe.predict(&nan, 0.5, 0.2e-3).unwrap_err();
    assert!(
        matches!(e, NpeError::Input(_)) && e.to_string().contains("point 4"),
        "{e}"
    );
    let e = npe.predict(&kept_points(), f64::NAN, 0.2e-3).unwrap_err();
    assert!(e.to_string().contains("force"), "{e}");
    let e = npe.predict(&kept_points(), -1.0, 0.2e-3).unwrap_err();
    assert!(e.to_string().contains("force"), "{e}");
    let e = npe.predict(&kept_points(), 1.0, f64::INFINITY).unwrap_err();
    assert!(e.to_string().contains("depth"), "{e}");
    let e = npe.latent(&[[3e-3, 2e-3, -5e-3]], 1.0, 0.1e-3).unwrap_err();
    assert!(e.to_string().contains("below the top face"), "{e}");
}

fn kept_points() -> Vec<[f64; 3]> {
    cap(3e-3, 2.5e-3, 0.2e-3)
}

/// Synthetic indentations on the grid surface: a smooth dent under the contact's centroid
/// whose depth and width follow the inputs, with nodal forces proportional to the dent.
fn synthetic() -> Prepared {
    let s = surface();
    let scales = NpeConfig::new(Prepared::top_center(&s.rest_m), 0.25e-3).scales;
    let mut samples = Vec::new();
    for (k, (cx, cy)) in [(2e-3, 2e-3), (4e-3, 3e-3), (3e-3, 1.5e-3), (5e-3, 2.5e-3)]
        .into_iter()
        .enumerate()
    {
        for step in 1..=6 {
            let d = step as f64 * 0.1e-3;
            let mut target = Vec::new();
            for p in &s.rest_m {
                let r2 = (p[0] - cx).powi(2) + (p[1] - cy).powi(2);
                let uz = -d * (-r2 / 2e-6).exp();
                target.extend([0.0, 0.0, (uz / scales.displacement_m) as f32]);
                target.extend([0.0, 0.0, (uz * 200.0 / scales.nodal_force_n) as f32]);
            }
            samples.push(Sample {
                setup: k,
                depth_m: d,
                force_n: [0.0, 0.0, 4000.0 * d],
                points_m: cap(cx, cy, d),
                target,
            });
        }
    }
    Prepared {
        setup_names: (0..4).map(|k| format!("s{k}")).collect(),
        setup_unseen: vec![false; 4],
        samples,
        without_points: 0,
        locator: ocm_npe::data::NodeLocator::new(&s.rest_m),
        rest_m: s.rest_m,
        edges: s.edges,
        spacing_m: 0.25e-3,
    }
}

fn small_fit(seed: u64) -> FitOptions {
    FitOptions {
        epochs: 3,
        batch_size: 4,
        seed,
        test_setups: 1,
        val_setups: 1,
        width: 12,
        layers: 2,
        ..FitOptions::default()
    }
}

#[test]
fn same_seed_same_engine_and_checkpoint_round_trip() {
    let p = synthetic();
    let a = fit(&p, &small_fit(5)).unwrap();
    let b = fit(&p, &small_fit(5)).unwrap();
    let c = fit(&p, &small_fit(6)).unwrap();
    let s = &p.samples[0];
    let run = |n: &Npe| n.predict(&s.points_m, s.force_n[2], s.depth_m).unwrap();
    assert_eq!(a.curve.len(), b.curve.len());
    for (x, y) in a.curve.iter().zip(&b.curve) {
        assert_eq!(x.train_loss, y.train_loss);
        assert_eq!(x.val_loss.to_bits(), y.val_loss.to_bits());
    }
    assert_eq!(run(&a.npe), run(&b.npe));
    assert_ne!(run(&a.npe), run(&c.npe));
    let path = std::env::temp_dir().join(format!("ocm-npe-{}.ckpt", std::process::id()));
    a.npe
        .save(&path, serde_json::json!({"split": a.split}))
        .unwrap();
    let back = Npe::load(&path).unwrap();
    assert_eq!(run(&a.npe), run(&back));
    assert_eq!(back.surface, a.npe.surface);
    std::fs::remove_file(&path).ok();
}

/// Two threads per batch (`FitOptions::threads`): the same run twice, and the one-thread run
/// up to rounding, with the contact head and the gap input so every input path is forked.
#[test]
fn two_threads_per_batch_train_the_same_engine() {
    let p = synthetic();
    let opts = |threads| FitOptions {
        threads,
        contact_prior: true,
        contact_head: true,
        node_gap: true,
        ..small_fit(5)
    };
    let (one, two, again) = (
        fit(&p, &opts(1)).unwrap(),
        fit(&p, &opts(2)).unwrap(),
        fit(&p, &opts(2)).unwrap(),
    );
    let s = &p.samples[0];
    let run = |n: &Npe| n.predict(&s.points_m, s.force_n[2], s.depth_m).unwrap();
    assert_eq!(run(&two.npe), run(&again.npe));
    assert_eq!(one.curve.len(), two.curve.len());
    for (a, b) in one.curve.iter().zip(&two.curve) {
        assert_eq!(b.val_loss, again.curve[a.epoch - 1].val_loss);
        for (x, y) in [(a.train_loss, b.train_loss), (a.val_loss, b.val_loss)] {
            assert!((x - y).abs() < 1e-4 * x, "epoch {}: {x} vs {y}", a.epoch);
        }
    }
}

/// `FitOptions::lr_schedule` reaches the loop: the cosine run's last epoch ends near its final
/// fraction of the step, and its engine is another than the constant step's.
#[test]
fn the_cosine_schedule_reaches_the_training_loop() {
    let p = synthetic();
    let constant = fit(&p, &small_fit(5)).unwrap();
    let cosine = fit(
        &p,
        &FitOptions {
            lr_schedule: LrSchedule::Cosine {
                final_fraction: 0.05,
            },
            ..small_fit(5)
        },
    )
    .unwrap();
    let base = FitOptions::default().learning_rate;
    assert!(constant.curve.iter().all(|r| r.learning_rate == base));
    let rates: Vec<f64> = cosine.curve.iter().map(|r| r.learning_rate).collect();
    assert!(rates.windows(2).all(|w| w[1] < w[0]), "{rates:?}");
    let last = rates[rates.len() - 1];
    assert!(last < 0.1 * base, "{rates:?}");
    let s = &p.samples[0];
    let run = |n: &Npe| n.predict(&s.points_m, s.force_n[2], s.depth_m).unwrap();
    assert_ne!(run(&constant.npe), run(&cosine.npe));
}

/// The plain kernel behind `predict` and `latent` against the burn network it was copied from,
/// for the engine and both ablations.
#[test]
fn plain_kernel_computes_what_the_burn_network_computes() {
    for (geometry, force, prior) in [
        (true, true, false),
        (false, true, false),
        (true, false, false),
        (true, true, true),
    ] {
        let npe = common::small_engine(surface(), 3, 9, |cfg| {
            cfg.use_geometry = geometry;
            cfg.use_force = force;
            cfg.contact_prior = prior;
        });
        let pts = cap(3.2e-3, 2.4e-3, 0.4e-3);
        let (a, ha) = npe.predict_scaled(&pts, 1.5, 0.4e-3).unwrap();
        let (b, hb) = npe.predict_scaled_burn(&pts, 1.5, 0.4e-3).unwrap();
        assert_eq!((a.len(), ha.len()), (b.len(), hb.len()));
        let scale = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(
            scale > 1e-3,
            "a degenerate output cannot tell the two apart"
        );
        for (x, y) in a.iter().zip(&b).chain(ha.iter().zip(&hb)) {
            assert!(
                (x - y).abs() <= 1e-4 * (1.0 + y.abs()),
                "geometry {geometry} force {force} prior {prior}: {x} vs {y}"
            );
        }
        assert_eq!(npe.latent(&pts, 1.5, 0.4e-3).unwrap(), ha);
    }
}

/// The resultant term of the loss is lambda_total times the mean squared error of the summed
/// nodal force in newtons, computed here from the engine's own predictions.
#[test]
fn resultant_term_adds_the_squared_error_of_the_summed_force() {
    let p = synthetic();
    let mut cfg = NpeConfig::new(Prepared::top_center(&p.rest_m), p.spacing_m);
    cfg.layers = 2;
    cfg.width = 12;
    let net = cfg.init(&cpu(), 4).unwrap();
    let surface = Surface {
        rest_m: p.rest_m.clone(),
        edges: p.edges.clone(),
    };
    let npe = Npe::new(net, cfg.clone(), surface).unwrap();
    let (pos, graph, device) = npe.parts();
    let batch = [2usize, 9];
    let plain = ocm_learn::values(loss(npe.net(), &cfg, &p, &batch, pos, graph, device))[0];
    let mut with = cfg.clone();
    with.lambda_total = 0.5;
    let total = ocm_learn::values(loss(npe.net(), &with, &p, &batch, pos, graph, device))[0];
    let mut sq = 0.0;
    for &i in &batch {
        let s = &p.samples[i];
        let (out, _) = npe
            .predict_scaled(&s.points_m, s.force_n[2], s.depth_m)
            .unwrap();
        for k in 3..6 {
            let e: f64 = out
                .chunks(6)
                .zip(s.target.chunks(6))
                .map(|(a, b)| f64::from(a[k] - b[k]))
                .sum::<f64>()
                * cfg.scales.nodal_force_n;
            sq += e * e;
        }
    }
    let want = f64::from(plain) + 0.5 * sq / (3 * batch.len()) as f64;
    assert!(sq > 1e-6, "the untrained engine should miss the resultant");
    assert!(
        (f64::from(total) - want).abs() < 1e-4 * want,
        "{total} vs {want}"
    );
}

/// The contact gate on a known case: a chain 0-1-2-3-4 with only node 2 penetrated opens 1, 2
/// and 3.
#[test]
fn contact_gate_opens_the_penetrated_nodes_and_their_neighbours() {
    let edges = [[0, 1], [1, 2], [2, 3], [3, 4]];
    let mut out = vec![7.0];
    ocm_npe::data::contact_gate(&[0.0, 0.0, 0.3, 0.0, 0.0], &edges, &mut out);
    assert_eq!(out, vec![7.0, 0.0, 1.0, 1.0, 1.0, 0.0]);
}

/// With the contact prior the same weights give the nodal force only where the gate is open,
/// and the vertical displacement shifted by minus the node's own penetration; elsewhere the
/// readout is untouched. Checked on both the plain kernel and the burn network.
#[test]
fn contact_prior_gates_the_force_and_offsets_the_displacement() {
    let s = surface();
    let mut cfg = NpeConfig::new(Prepared::top_center(&s.rest_m), 0.25e-3);
    cfg.layers = 2;
    cfg.width = 12;
    let net = cfg.init(&cpu(), 3).unwrap();
    let bare = Npe::new(net.clone(), cfg.clone(), s.clone()).unwrap();
    cfg.contact_prior = true;
    let k = f64::from(cfg.depth_to_displacement());
    let with = Npe::new(net, cfg.clone(), s.clone()).unwrap();
    let pts = cap(3.0e-3, 2.0e-3, 0.4e-3);
    // Each node's penetration by its nearest points, from scratch.
    let mut pen = vec![0.0f64; s.rest_m.len()];
    for p in &pts {
        let near = (0..s.rest_m.len())
            .min_by(|&a, &b| {
                let d =
                    |i: usize| (s.rest_m[i][0] - p[0]).powi(2) + (s.rest_m[i][1] - p[1]).powi(2);
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        pen[near] = pen[near].max((s.rest_m[near][2] - p[2]) / cfg.scales.z_m);
    }
    let open: Vec<bool> = (0..s.rest_m.len())
        .map(|v| {
            pen[v] > 0.0
                || s.edges
                    .iter()
                    .any(|e| (e[0] == v && pen[e[1]] > 0.0) || (e[1] == v && pen[e[0]] > 0.0))
        })
        .collect();
    assert!(open.iter().any(|&o| o) && open.iter().any(|&o| !o));
    let (a, _) = bare.predict_scaled(&pts, 1.5, 0.4e-3).unwrap();
    for (b, _) in [
        with.predict_scaled(&pts, 1.5, 0.4e-3).unwrap(),
        with.predict_scaled_burn(&pts, 1.5, 0.4e-3).unwrap(),
    ] {
        for v in 0..s.rest_m.len() {
            let (x, y) = (&a[6 * v..6 * v + 6], &b[6 * v..6 * v + 6]);
            for c in 0..2 {
                assert!((x[c] - y[c]).abs() < 1e-4, "node {v} u{c}");
            }
            let uz = f64::from(x[2]) - k * pen[v];
            assert!(
                (uz - f64::from(y[2])).abs() < 1e-4,
                "node {v}: {uz} vs {}",
                y[2]
            );
            for c in 3..6 {
                let want = if open[v] { x[c] } else { 0.0 };
                assert!(
                    (want - y[c]).abs() < 1e-4,
                    "node {v} f{c}: {want} vs {}",
                    y[c]
                );
            }
        }
    }
}

/// Training with the contact prior cuts the loss (seconds-sized: the synthetic grid, 16 epochs).
#[test]
fn training_with_the_contact_prior_cuts_the_loss() {
    let p = synthetic();
    let r = fit(
        &p,
        &FitOptions {
            epochs: 16,
            contact_prior: true,
            patience: 0,
            ..small_fit(2)
        },
    )
    .unwrap();
    assert!(r.npe.config.contact_prior);
    let first = r.curve[0].train_loss;
    let last = r.curve.last().unwrap().train_loss;
    eprintln!(
        "train loss {first:.4} -> {last:.4}, best val {:.4}",
        r.best_loss
    );
    // Measured: 1.61 -> 0.57.
    assert!(last < 0.5 * first, "train loss {first} -> {last}");
}

/// The contact head's loss: the mean binary cross-entropy against hand-computed values
/// (-ln sigma(z) for a 1, -ln(1 - sigma(z)) for a 0), finite at large logits.
#[test]
fn cross_entropy_of_the_contact_head_matches_the_formula() {
    use ocm_learn::burn::tensor::{Tensor, TensorData};
    let z = [0.0f32, 2.0, -3.0, 40.0, -40.0];
    let y = [1.0f32, 0.0, 0.0, 1.0, 1.0];
    let d = cpu();
    let got = ocm_learn::values(ocm_npe::fit::bce_with_logits(
        Tensor::<1>::from_data(TensorData::new(z.to_vec(), [5]), &d),
        Tensor::<1>::from_data(TensorData::new(y.to_vec(), [5]), &d),
    ))[0];
    let sig = |v: f64| 1.0 / (1.0 + (-v).exp());
    let want: f64 = z
        .iter()
        .zip(&y)
        .map(|(&z, &y)| {
            let z = f64::from(z);
            if y > 0.5 {
                // ln(1 + e^-z), written so z = -40 stays exact.
                -z.min(0.0) + (-z.abs()).exp().ln_1p()
            } else {
                -(1.0 - sig(z)).ln()
            }
        })
        .sum::<f64>()
        / 5.0;
    assert!(got.is_finite());
    assert!((f64::from(got) - want).abs() < 1e-5, "{got} vs {want}");
}

/// The head's targets are the FEM contact flags of the metric (-u_z > 30 um): on the synthetic
/// dent -u_z = d exp(-r^2 / 2 mm^2), so a node is in contact iff that exceeds 30 um.
#[test]
fn contact_flags_are_the_fem_contact_nodes() {
    let p = synthetic();
    let s = &p.samples[5];
    let flags = ocm_npe::fit::contact_flags(&p, &[0, 5], 1e-4);
    let n = p.rest_m.len();
    assert_eq!(flags.len(), 2 * n);
    let (cx, cy) = (2e-3, 2e-3);
    let mut on = 0;
    for (v, q) in p.rest_m.iter().enumerate() {
        let r2 = (q[0] - cx).powi(2) + (q[1] - cy).powi(2);
        let want = s.depth_m * (-r2 / 2e-6).exp() > 30e-6;
        assert_eq!(flags[n + v] == 1.0, want, "node {v}");
        on += usize::from(want);
    }
    assert!(on > 3 && on < n, "{on} contact nodes");
}

fn engine_with_head(seed: u64, prior: bool) -> Npe {
    let s = surface();
    let mut cfg = NpeConfig::new(Prepared::top_center(&s.rest_m), 0.25e-3);
    cfg.layers = 3;
    cfg.width = 12;
    cfg.contact_prior = prior;
    cfg.contact_head = true;
    cfg.lambda_contact = 1.0;
    let net = cfg.init(&cpu(), seed).unwrap();
    Npe::new(net, cfg, s).unwrap()
}

/// The contact head: the plain kernel computes burn's logits, the order of the contact points
/// does not change them, no point means no node in contact, and `predict_contact` reads the
/// state off the head (logit > 0).
#[test]
fn contact_head_kernel_matches_burn_and_ignores_point_order() {
    for prior in [false, true] {
        let npe = engine_with_head(11, prior);
        assert!(npe.has_contact_head());
        let pts = cap(3.2e-3, 2.4e-3, 0.4e-3);
        let (a, b) = npe.contact_logits_both(&pts, 1.5, 0.4e-3).unwrap();
        let (a, b) = (a.unwrap(), b.unwrap());
        assert_eq!(a.len(), npe.surface.rest_m.len());
        assert_eq!(a.len(), b.len());
        assert!(b.iter().any(|v| v.abs() > 1e-3));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()), "{x} vs {y}");
        }
        let (f, c) = npe.predict_contact(&pts, 1.5, 0.4e-3).unwrap();
        assert_eq!(c, a.iter().map(|&v| v > 0.0).collect::<Vec<_>>());
        assert_eq!(f, npe.predict(&pts, 1.5, 0.4e-3).unwrap());
        let mut shuffled = pts.clone();
        shuffled.reverse();
        shuffled.rotate_left(7);
        let (a2, _) = npe.contact_logits_both(&shuffled, 1.5, 0.4e-3).unwrap();
        for (x, y) in a.iter().zip(&a2.unwrap()) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
        let (_, none) = npe.predict_contact(&[], 0.0, 0.0).unwrap();
        assert!(none.iter().all(|&c| !c));
    }
    // Without a head the state is -u_z > 30 um of the predicted field.
    let npe = engine(3);
    let pts = cap(3e-3, 2.5e-3, 0.3e-3);
    let (f, c) = npe.predict_contact(&pts, 1.2, 0.3e-3).unwrap();
    let want: Vec<bool> = f.displacement_m.iter().map(|u| -u[2] > 30e-6).collect();
    assert_eq!(c, want);
}

/// Saves a trained engine with its split (what `--init-from` reads) to a temporary file.
fn saved(r: &ocm_npe::fit::FitReport, tag: &str) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("ocm-npe-{tag}-{}.ckpt", std::process::id()));
    r.npe
        .save(&path, serde_json::json!({"split": r.split}))
        .unwrap();
    path
}

/// Fine-tuning starts from the trained weights (at a vanishing step size the fields stay the
/// source's), adds a contact head, refuses another split, and the head learns the known
/// contact nodes of the synthetic dents.
#[test]
fn fine_tuning_adds_a_contact_head_that_learns_the_contact_nodes() {
    let p = synthetic();
    let src = fit(&p, &small_fit(4)).unwrap();
    let path = saved(&src, "ft");
    let frozen = fit(
        &p,
        &FitOptions {
            epochs: 1,
            learning_rate: 1e-12,
            contact_head: true,
            init_from: Some(path.clone()),
            ..small_fit(4)
        },
    )
    .unwrap();
    assert!(frozen.npe.has_contact_head() && !src.npe.has_contact_head());
    for s in &p.samples[..6] {
        let a = src
            .npe
            .predict(&s.points_m, s.force_n[2], s.depth_m)
            .unwrap();
        let b = frozen
            .npe
            .predict(&s.points_m, s.force_n[2], s.depth_m)
            .unwrap();
        for (x, y) in a.displacement_m.iter().zip(&b.displacement_m) {
            for k in 0..3 {
                assert!((x[k] - y[k]).abs() < 1e-9, "{x:?} vs {y:?}");
            }
        }
    }
    let other = fit(
        &p,
        &FitOptions {
            init_from: Some(path.clone()),
            ..small_fit(5)
        },
    );
    assert!(
        other
            .as_ref()
            .is_err_and(|e| e.to_string().contains("another split")),
        "{other:?}"
    );
    let tuned = fit(
        &p,
        &FitOptions {
            epochs: 60,
            patience: 0,
            contact_head: true,
            lambda_contact: 1.0,
            init_from: Some(path.clone()),
            ..small_fit(4)
        },
    )
    .unwrap();
    std::fs::remove_file(&path).ok();
    let n = p.rest_m.len();
    let (mut right, mut right_before, mut total) = (0usize, 0usize, 0usize);
    for (i, s) in p.samples.iter().enumerate() {
        let want = ocm_npe::fit::contact_flags(&p, &[i], 1e-4);
        let (_, c) = tuned
            .npe
            .predict_contact(&s.points_m, s.force_n[2], s.depth_m)
            .unwrap();
        let (_, c0) = src
            .npe
            .predict_contact(&s.points_m, s.force_n[2], s.depth_m)
            .unwrap();
        right += c
            .iter()
            .zip(&want)
            .filter(|(a, w)| **a == (**w == 1.0))
            .count();
        right_before += c0
            .iter()
            .zip(&want)
            .filter(|(a, w)| **a == (**w == 1.0))
            .count();
        total += n;
    }
    let (acc, acc0) = (
        right as f64 / total as f64,
        right_before as f64 / total as f64,
    );
    eprintln!("contact-node accuracy: source (-u_z > 30 um) {acc0:.4}, fine-tuned head {acc:.4}");
    assert!(acc > 0.95 && acc > acc0, "{acc0} -> {acc}");
}

/// A copy of the synthetic set-ups under other names (`e0`..), with `unseen` flags.
fn extra_setups(prefix: &str, unseen: bool) -> Prepared {
    let mut q = synthetic();
    q.setup_names = (0..q.setup_names.len())
        .map(|k| format!("{prefix}{k}"))
        .collect();
    q.setup_unseen = vec![unseen; q.setup_names.len()];
    q
}

/// Training-only set-ups join the training set and leave the seeded held-out set-ups as they
/// are without them; unknown, unseen, duplicate and foreign-surface ones are refused.
#[test]
fn training_only_setups_leave_the_held_out_split_alone() {
    use ocm_npe::data::SetupSplit;
    let p = synthetic();
    let mut q = synthetic();
    q.append(extra_setups("e", false)).unwrap();
    assert_eq!(q.samples.len(), 2 * p.samples.len());
    assert_eq!(q.samples[p.samples.len()].setup, 4);
    let extra: Vec<String> = (0..4).map(|k| format!("e{k}")).collect();
    for seed in 0..6 {
        let base = SetupSplit::new(&p, 1, 1, seed).unwrap();
        let with = SetupSplit::with_train_only(&q, 1, 1, seed, &extra).unwrap();
        assert_eq!((&with.test, &with.val), (&base.test, &base.val));
        let mut want = [base.train.clone(), extra.clone()].concat();
        want.sort();
        assert_eq!(with.train, want);
        // Without the flag the extra set-ups would enter the shuffle.
        assert_eq!(SetupSplit::new(&q, 1, 1, seed).unwrap().train.len(), 6);
    }
    let refusal = |p: &Prepared, name: &str| {
        SetupSplit::with_train_only(p, 1, 1, 0, &[name.to_string()])
            .unwrap_err()
            .to_string()
    };
    assert!(refusal(&q, "nope").contains("'nope' is not in the data"));
    let mut u = synthetic();
    u.append(extra_setups("u", true)).unwrap();
    assert!(refusal(&u, "u2").contains("unseen"));
    let mut twice = synthetic();
    assert!(
        twice
            .append(synthetic())
            .unwrap_err()
            .to_string()
            .contains("'s0' is in both")
    );
    let mut moved = extra_setups("m", false);
    moved.rest_m[3][2] += 1e-6;
    assert!(
        twice
            .append(moved)
            .unwrap_err()
            .to_string()
            .contains("another top surface")
    );
    assert_eq!(
        twice.samples.len(),
        p.samples.len(),
        "a refused append adds nothing"
    );
}

/// An engine may be fine-tuned with more training set-ups than it was trained on, not with
/// fewer, and the extra samples reach the optimiser.
#[test]
fn fine_tuning_takes_more_training_setups() {
    let p = synthetic();
    let src = fit(&p, &small_fit(4)).unwrap();
    let path = saved(&src, "more");
    let mut q = synthetic();
    q.append(extra_setups("e", false)).unwrap();
    let extra: Vec<String> = (0..4).map(|k| format!("e{k}")).collect();
    let more = fit(
        &q,
        &FitOptions {
            epochs: 1,
            init_from: Some(path.clone()),
            train_only: extra.clone(),
            ..small_fit(4)
        },
    )
    .unwrap();
    assert_eq!(more.train_samples, src.train_samples + p.samples.len());
    assert_eq!(
        (&more.split.test, &more.split.val),
        (&src.split.test, &src.split.val)
    );
    // The engine trained with the extra set-ups cannot be fine-tuned on the smaller split.
    let path2 = saved(&more, "more2");
    let fewer = fit(
        &p,
        &FitOptions {
            epochs: 1,
            init_from: Some(path2.clone()),
            ..small_fit(4)
        },
    );
    std::fs::remove_file(&path).ok();
    std::fs::remove_file(&path2).ok();
    assert!(
        fewer
            .as_ref()
            .is_err_and(|e| e.to_string().contains("another split")),
        "{fewer:?}"
    );
}
