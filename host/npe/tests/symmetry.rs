//! Turned and mirrored indentations: the node permutation, the mapped sample against the
//! analytic field of the mapped indentation, and training on the augmented set.

use ocm_npe::Surface;
use ocm_npe::data::{NodeLocator, Prepared, Sample};
use ocm_npe::fit::{FitOptions, fit};
use ocm_npe::model::NpeConfig;
use ocm_npe::symmetry::{self, Symmetry};

mod common;

/// A 9 x 7 grid of nodes 0.5 mm apart at z = 2 mm (centre (2, 1.5) mm), with one diagonal per
/// cell (so the x and y mirrors change the triangulation and the half turn keeps it).
fn grid(shift_node: Option<usize>) -> (Vec<[f64; 3]>, Vec<[usize; 2]>) {
    let Surface {
        rest_m: mut rest,
        edges,
    } = common::grid_surface(9, 7, 0.5e-3, 2e-3);
    if let Some(k) = shift_node {
        rest[k][0] += 0.1e-3;
    }
    (rest, edges)
}

/// An elliptical dent centred at `c` with its long axis along `axis` (unit x-y vector): an
/// in-plane flow towards the centre along the axis and across it with different weights, a
/// vertical dent, nodal forces, contact points and a tilted resultant. Every part is a
/// function of the offset from `c` that turns and mirrors with it, so the image of the sample
/// at `c` under a symmetry S is the sample at S(c) with S(axis).
fn dent(rest: &[[f64; 3]], c: [f64; 2], axis: [f64; 2], depth_m: f64, setup: usize) -> Sample {
    let scales = NpeConfig::new([0.0; 3], 0.25e-3).scales;
    let normal = [-axis[1], axis[0]];
    let field = |x: f64, y: f64| {
        let (dx, dy) = (x - c[0], y - c[1]);
        let a = dx * axis[0] + dy * axis[1];
        let b = dx * normal[0] + dy * normal[1];
        let e = (-(a * a) / 1.0e-6 - (b * b) / 0.25e-6).exp();
        let (ua, ub) = (-0.3 * a * e, -0.7 * b * e);
        [
            ua * axis[0] + ub * normal[0],
            ua * axis[1] + ub * normal[1],
            -depth_m * e,
        ]
    };
    let mut target = Vec::new();
    for p in rest {
        let u = field(p[0], p[1]);
        target.extend(u.map(|v| (v / scales.displacement_m) as f32));
        target.extend(u.map(|v| (v * 300.0 / scales.nodal_force_n) as f32));
    }
    let mut points_m = Vec::new();
    for s in -3i32..=3 {
        for t in -1i32..=1 {
            let (a, b) = (f64::from(s) * 0.25e-3, f64::from(t) * 0.25e-3);
            points_m.push([
                c[0] + a * axis[0] + b * normal[0],
                c[1] + a * axis[1] + b * normal[1],
                2e-3 - depth_m + 100.0 * (a * a + 3.0 * b * b),
            ]);
        }
    }
    Sample {
        setup,
        depth_m,
        force_n: [0.4 * axis[0], 0.4 * axis[1], 5000.0 * depth_m],
        points_m,
        target,
    }
}

fn prepared(rest: Vec<[f64; 3]>, edges: Vec<[usize; 2]>, samples: Vec<Sample>) -> Prepared {
    let setups = samples.iter().map(|s| s.setup).max().map_or(0, |m| m + 1);
    Prepared {
        setup_names: (0..setups).map(|k| format!("s{k}")).collect(),
        setup_unseen: vec![false; setups],
        samples,
        without_points: 0,
        locator: NodeLocator::new(&rest),
        rest_m: rest,
        edges,
        spacing_m: 0.25e-3,
    }
}

fn close(a: &Sample, b: &Sample) {
    let tol = 1e-5;
    assert_eq!(a.target.len(), b.target.len());
    for (k, (x, y)) in a.target.iter().zip(&b.target).enumerate() {
        assert!(
            (x - y).abs() <= tol * (1.0 + y.abs()),
            "value {k}: {x} against {y}"
        );
    }
    for k in 0..3 {
        assert!((a.force_n[k] - b.force_n[k]).abs() < 1e-12);
    }
    // As sets: a mirror reverses the order across the dent's axis.
    assert_eq!(a.points_m.len(), b.points_m.len());
    for p in &a.points_m {
        let found = b
            .points_m
            .iter()
            .any(|q| (0..3).all(|k| (p[k] - q[k]).abs() < 1e-12));
        assert!(found, "point {p:?} has no counterpart");
    }
}

#[test]
fn images_are_the_mapped_indentations() {
    let (rest, edges) = grid(None);
    let s = 0.6f64.sin_cos();
    let (c, axis) = ([1.2e-3, 1.0e-3], [s.1, s.0]);
    let p = prepared(rest.clone(), edges, vec![dent(&rest, c, axis, 0.3e-3, 0)]);
    let centre = [2e-3, 1.5e-3];
    // Each map by hand: node (i, j) of the 9 x 7 grid goes to (8 - i, 6 - j), (8 - i, j) or
    // (i, 6 - j), and a point 1 mm right of and 0.5 mm above the centre accordingly.
    type NodeMap = fn(usize, usize) -> (usize, usize);
    let by_hand: [(Symmetry, NodeMap, [f64; 2]); 3] = [
        (Symmetry::Rot180, |i, j| (8 - i, 6 - j), [1e-3, 1e-3]),
        (Symmetry::MirrorX, |i, j| (8 - i, j), [1e-3, 2e-3]),
        (Symmetry::MirrorY, |i, j| (i, 6 - j), [3e-3, 1e-3]),
    ];
    for (sym, node, point) in by_hand {
        let perm = symmetry::permutation(&p.rest_m, sym).unwrap();
        for (k, &image) in perm.iter().enumerate() {
            let (i, j) = node(k % 9, k / 9);
            assert_eq!(image, j * 9 + i, "{sym}: node {k}");
        }
        let q = sym.point(centre, [3e-3, 2e-3, 1.9e-3]);
        assert!(
            (q[0] - point[0]).abs() < 1e-15 && (q[1] - point[1]).abs() < 1e-15,
            "{sym}"
        );
        assert_eq!(q[2], 1.9e-3);
    }
    for sym in Symmetry::ALL {
        let perm = symmetry::permutation(&p.rest_m, sym).unwrap();
        // An involution: applied twice, every node comes back.
        assert!((0..perm.len()).all(|i| perm[perm[i]] == i), "{sym}");
        assert!((0..perm.len()).any(|i| perm[i] != i), "{sym} moved no node");
        let image = symmetry::map_sample(&p.samples[0], sym, centre, &perm);
        let c2 = sym.point(centre, [c[0], c[1], 0.0]);
        let a2 = sym.vector([axis[0], axis[1], 0.0]);
        // The normal of a mirrored axis turns the other way: the dent's weights are even in
        // the normal coordinate, so the analytic sample is the same with either sign.
        let expected = dent(&rest, [c2[0], c2[1]], [a2[0], a2[1]], 0.3e-3, 0);
        close(&image, &expected);
        let back = symmetry::map_sample(&image, sym, centre, &perm);
        close(&back, &p.samples[0]);
    }
}

#[test]
fn asymmetric_faces_and_unknown_names_are_refused() {
    let (rest, edges) = grid(Some(3));
    let p = prepared(
        rest.clone(),
        edges,
        vec![dent(&rest, [1e-3, 1e-3], [1.0, 0.0], 1e-4, 0)],
    );
    for sym in Symmetry::ALL {
        let e = symmetry::permutation(&p.rest_m, sym)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not symmetric") && e.contains(sym.name()), "{e}");
    }
    assert_eq!("rot180".parse::<Symmetry>(), Ok(Symmetry::Rot180));
    assert_eq!("mirror-y".parse::<Symmetry>(), Ok(Symmetry::MirrorY));
    let e = "rot90".parse::<Symmetry>().unwrap_err();
    assert!(e.contains("rot90") && e.contains("mirror-x"), "{e}");
}

#[test]
fn augmented_training_adds_the_images_of_the_training_set_ups_only() {
    let (rest, edges) = grid(None);
    let mut samples = Vec::new();
    for (k, (c, t)) in [
        ([1.0e-3, 1.0e-3], 0.3),
        ([2.5e-3, 1.2e-3], 1.1),
        ([1.5e-3, 2.0e-3], 2.0),
        ([3.0e-3, 2.2e-3], 2.6),
        ([2.0e-3, 0.8e-3], 0.9),
    ]
    .into_iter()
    .enumerate()
    {
        for step in 1..=4 {
            let axis = [f64::cos(t), f64::sin(t)];
            samples.push(dent(&rest, c, axis, f64::from(step) * 0.1e-3, k));
        }
    }
    let p = prepared(rest, edges, samples);
    let opts = FitOptions {
        epochs: 2,
        batch_size: 4,
        test_setups: 1,
        val_setups: 1,
        width: 12,
        layers: 2,
        ..FitOptions::default()
    };
    let plain = fit(&p, &opts).unwrap();
    assert_eq!(plain.train_samples, 12);
    let with = fit(
        &p,
        &FitOptions {
            symmetries: vec![Symmetry::Rot180, Symmetry::MirrorX, Symmetry::Rot180],
            ..opts.clone()
        },
    )
    .unwrap();
    // Three training set-ups of four samples, each with two distinct images; the split is the
    // same, and the validation loss is taken on measured samples only.
    assert_eq!(with.train_samples, 36);
    assert_eq!(with.split, plain.split);
    assert!(with.curve.iter().all(|r| r.val_loss.is_finite()));
    let (q, added) = symmetry::augmented(&p, &[0, 5], &[Symmetry::MirrorY]).unwrap();
    assert_eq!(added, vec![20, 21]);
    assert_eq!(q.samples[21].setup, 1);
    assert!(symmetry::augmented(&p, &[99], &[Symmetry::MirrorY]).is_err());
}

/// Largest difference between the outputs of sample `at[0]` of batch `a` (6 per node,
/// node-major) and those of its image, sample `at[1]` of batch `b`, under `sym` (node `perm[v]`
/// mapped), over the largest output.
fn equivariance_gap(
    a: &(Vec<f32>, Option<Vec<f32>>),
    b: &(Vec<f32>, Option<Vec<f32>>),
    batch: [usize; 2],
    at: [usize; 2],
    sym: Symmetry,
    perm: &[usize],
) -> f64 {
    let (ba, bb) = (batch[0], batch[1]);
    let (j, k) = (at[0], at[1]);
    let mut gap = 0.0f64;
    let mut scale = 0.0f64;
    for (v, &w) in perm.iter().enumerate() {
        for off in [0, 3] {
            let x = [0, 1, 2].map(|q| f64::from(a.0[(v * ba + j) * 6 + off + q]));
            let y = sym.vector([0, 1, 2].map(|q| f64::from(b.0[(w * bb + k) * 6 + off + q])));
            for q in 0..3 {
                gap = gap.max((x[q] - y[q]).abs());
                scale = scale.max(x[q].abs());
            }
        }
        if let (Some(la), Some(lb)) = (&a.1, &b.1) {
            let (x, y) = (f64::from(la[v * ba + j]), f64::from(lb[w * bb + k]));
            gap = gap.max((x - y).abs());
            scale = scale.max(x.abs());
        }
    }
    gap / scale.max(1e-12)
}

/// Test-time symmetrisation (`eval::Symmetrised`, `ocm npe eval --symmetrise`): averaged over
/// the whole group the engine answers a mirrored or turned indentation with the mirrored or
/// turned field and contact logits, for any weights (here untrained ones on a face whose
/// triangulation the mirrors change); one map alone buys that map's equivariance only; the
/// plain engine has none; a batch scores each sample as alone.
#[test]
fn symmetrised_engine_is_equivariant_under_the_whole_group() {
    use ocm_npe::eval::Symmetrised;

    let (rest, edges) = grid(None);
    let mut samples = Vec::new();
    for (k, (c, t)) in [([1.2e-3, 1.0e-3], 0.6), ([2.6e-3, 2.1e-3], 2.2)]
        .into_iter()
        .enumerate()
    {
        samples.push(dent(&rest, c, [f64::cos(t), f64::sin(t)], 0.25e-3, k));
    }
    let p = prepared(rest.clone(), edges.clone(), samples);
    let npe = common::small_engine(
        Surface {
            rest_m: rest,
            edges,
        },
        2,
        3,
        |cfg| {
            cfg.contact_prior = true;
            cfg.node_gap = true;
            cfg.contact_head = true;
        },
    );
    let centre = Prepared::top_center(&p.rest_m);
    let run = |maps: &[Symmetry], q: &Prepared, idx: &[usize]| {
        let x = q.inputs(&npe.config, idx);
        Symmetrised::new(q, maps)
            .unwrap()
            .forward(&[&npe], q, idx, &x)
    };
    let both = [0, 1];
    let whole = run(&Symmetry::ALL, &p, &both);
    assert!(
        whole.1.is_some(),
        "the contact head's logits are averaged too"
    );
    for sym in Symmetry::ALL {
        let perm = symmetry::permutation(&p.rest_m, sym).unwrap();
        let images = Prepared {
            samples: p
                .samples
                .iter()
                .map(|s| symmetry::map_sample(s, sym, [centre[0], centre[1]], &perm))
                .collect(),
            ..p.without_samples()
        };
        // The images alone, one at a time: batch 2 against batch 1 crosses the node-major layout.
        for j in 0..2 {
            let image_whole = run(&Symmetry::ALL, &images, &[j]);
            let gap = equivariance_gap(&whole, &image_whole, [2, 1], [j, 0], sym, &perm);
            assert!(gap < 1e-5, "{sym}, sample {j}: symmetrised gap {gap:.3e}");
            let plain = equivariance_gap(
                &run(&[], &p, &both),
                &run(&[], &images, &[j]),
                [2, 1],
                [j, 0],
                sym,
                &perm,
            );
            assert!(
                plain > 1e-3,
                "{sym}, sample {j}: the plain engine's gap is {plain:.3e}"
            );
        }
        let under_sym = |maps: &[Symmetry]| {
            let (a, b) = (run(maps, &p, &both), run(maps, &images, &both));
            equivariance_gap(&a, &b, [2, 2], [1, 1], sym, &perm)
        };
        let own = under_sym(&[sym]);
        assert!(own < 1e-5, "{sym} alone: gap {own:.3e} under {sym}");
        let other = if sym == Symmetry::Rot180 {
            Symmetry::MirrorX
        } else {
            Symmetry::Rot180
        };
        let wrong = under_sym(&[other]);
        assert!(
            wrong > 1e-3,
            "{other} alone is equivariant under {sym}: {wrong:.3e}"
        );
    }
    let e = Symmetrised::new(
        &prepared(grid(Some(3)).0, grid(Some(3)).1, Vec::new()),
        &[Symmetry::MirrorY],
    );
    assert!(e.is_err(), "an asymmetric face is refused");
}
