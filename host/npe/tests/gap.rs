//! The gap input (`NpeConfig::node_gap`): known gaps under a flat punch, independence of the
//! order of the contact points, the plain kernel against burn, a checkpoint round trip, and
//! configurations written before the input existed.

use ocm_learn::cpu;
use ocm_npe::data::{GAP_REACH_M, NodeLocator, Prepared};
use ocm_npe::model::NpeConfig;
use ocm_npe::{Npe, Surface};

mod common;

const Z_TOP_M: f64 = 2e-3;
const SPACING_M: f64 = 0.25e-3;

/// A 26 x 26 grid of nodes 0.2 mm apart (5 x 5 mm) at z = 2 mm, triangulated.
fn fine_surface() -> Surface {
    common::grid_surface(26, 26, 0.2e-3, Z_TOP_M)
}

/// Contact points of a flat cylindrical punch of radius `r_m` centred at (cx, cy), `depth_m`
/// into the face: the grid points inside its disc, all at the punch's face.
fn punch(cx: f64, cy: f64, r_m: f64, depth_m: f64) -> Vec<[f64; 3]> {
    let mut p = Vec::new();
    for a in -12i32..=12 {
        for b in -12i32..=12 {
            let (x, y) = (cx + f64::from(a) * SPACING_M, cy + f64::from(b) * SPACING_M);
            if (x - cx).hypot(y - cy) <= r_m {
                p.push([x, y, Z_TOP_M - depth_m]);
            }
        }
    }
    p
}

/// Under a flat punch at depth d the gap input is known: nodes under the punch read a point
/// within half a grid diagonal (one near the rim) and the height -d; outside, the distance to the disc of
/// points lies between r - R and r - R + one grid diagonal, also at -d; beyond the reach,
/// (1, 0). The bucketed search also equals a brute-force search over every point.
#[test]
fn flat_punch_gives_the_known_gaps() {
    let s = fine_surface();
    let loc = NodeLocator::new(&s.rest_m);
    let (cx, cy, r, d) = (2.5e-3, 2.5e-3, 1e-3, 0.3e-3);
    let pts = punch(cx, cy, r, d);
    let z_scale = 0.5e-3;
    let mut gap = Vec::new();
    loc.node_gap(&pts, SPACING_M, z_scale, &mut gap);
    assert_eq!(gap.len(), 2 * s.rest_m.len());
    let diag = SPACING_M * std::f64::consts::SQRT_2;
    let (mut inside, mut skirt, mut far) = (0, 0, 0);
    for (v, q) in s.rest_m.iter().enumerate() {
        let dist = f64::from(gap[2 * v]) * GAP_REACH_M;
        let height = f64::from(gap[2 * v + 1]) * z_scale;
        let rad = (q[0] - cx).hypot(q[1] - cy);
        // Brute force: the nearest point, ties to the lower one (all equal here).
        let brute = pts
            .iter()
            .map(|p| (p[0] - q[0]).hypot(p[1] - q[1]))
            .fold(f64::INFINITY, f64::min);
        if brute <= GAP_REACH_M {
            assert!((dist - brute).abs() < 1e-9, "node {v}: {dist} vs {brute}");
            assert!((height + d).abs() < 1e-9, "node {v}: height {height}");
        } else {
            assert_eq!((gap[2 * v], gap[2 * v + 1]), (1.0, 0.0), "node {v}");
        }
        if rad <= r {
            inside += 1;
            // Half a grid diagonal well inside the disc, a full one near its rim.
            let bound = if rad <= r - 0.5 * diag {
                0.5 * diag
            } else {
                diag
            };
            assert!(dist <= bound + 1e-12, "node {v} under the punch: {dist}");
            assert!((height + d).abs() < 1e-9);
        } else if rad - r + diag < GAP_REACH_M {
            skirt += 1;
            assert!(
                dist >= rad - r - 1e-12 && dist <= rad - r + diag + 1e-12,
                "node {v} at {rad}: {dist}"
            );
            assert!((height + d).abs() < 1e-9);
        } else if rad - r > GAP_REACH_M {
            far += 1;
            assert_eq!((gap[2 * v], gap[2 * v + 1]), (1.0, 0.0));
        }
    }
    assert!(
        inside > 50 && skirt > 50 && far > 20,
        "{inside} {skirt} {far}"
    );
    // No points: every node is far.
    let mut none = Vec::new();
    loc.node_gap(&[], SPACING_M, z_scale, &mut none);
    assert!(none.chunks(2).all(|g| g == [1.0, 0.0]));
}

/// A sloped cap (points at several heights): the order of the points changes nothing, and
/// equally near points are decided by the lower one.
#[test]
fn gap_input_ignores_the_order_of_the_points() {
    let s = fine_surface();
    let loc = NodeLocator::new(&s.rest_m);
    let mut pts = Vec::new();
    for a in -6i32..=6 {
        for b in -6i32..=6 {
            let (x, y) = (
                2.4e-3 + f64::from(a) * SPACING_M,
                2.6e-3 + f64::from(b) * SPACING_M,
            );
            let z = Z_TOP_M - 0.4e-3
                + 0.1 * (x - 2.4e-3)
                + ((x - 2.4e-3).powi(2) + (y - 2.6e-3).powi(2)) / 4e-3;
            if z < Z_TOP_M {
                pts.push([x, y, z]);
            }
        }
    }
    let mut a = Vec::new();
    loc.node_gap(&pts, SPACING_M, 0.5e-3, &mut a);
    let mut shuffled = pts.clone();
    shuffled.reverse();
    shuffled.rotate_left(11);
    let mut b = Vec::new();
    loc.node_gap(&shuffled, SPACING_M, 0.5e-3, &mut b);
    assert_eq!(a, b);
    // The search that skips the grid-interior points' far nodes equals the full one (a
    // spacing the points do not lie on turns the shortcut off).
    let mut full = Vec::new();
    loc.node_gap(&pts, 0.3e-3, 0.5e-3, &mut full);
    assert_eq!(a, full);
    // Two points equally near a node: the lower one counts.
    let q = s.rest_m[0];
    let two = [
        [q[0] + 0.3e-3, q[1], Z_TOP_M - 0.1e-3],
        [q[0], q[1] + 0.3e-3, Z_TOP_M - 0.2e-3],
    ];
    for order in [two, [two[1], two[0]]] {
        let mut g = Vec::new();
        loc.node_gap(&order, SPACING_M, 0.5e-3, &mut g);
        assert!((f64::from(g[1]) * 0.5e-3 + 0.2e-3).abs() < 1e-9, "{}", g[1]);
    }
}

fn gap_engine(seed: u64, prior: bool, head: bool) -> Npe {
    let s = fine_surface();
    let mut cfg = NpeConfig::new(Prepared::top_center(&s.rest_m), SPACING_M);
    cfg.layers = 3;
    cfg.width = 16;
    cfg.node_gap = true;
    cfg.contact_prior = prior;
    cfg.contact_head = head;
    cfg.lambda_contact = if head { 1.0 } else { 0.0 };
    let net = cfg.init(&cpu(), seed).unwrap();
    Npe::new(net, cfg, s).unwrap()
}

/// The plain kernel (what `predict` runs) computes what the burn network computes with the
/// gap input; the field does not depend on the order of the points; the gap input changes
/// the field (it reaches the network); a checkpoint round trip keeps it.
#[test]
fn gap_engine_kernel_matches_burn_and_round_trips() {
    let pts = punch(2.4e-3, 2.6e-3, 0.8e-3, 0.25e-3);
    for (prior, head) in [(false, false), (true, false), (true, true)] {
        let npe = gap_engine(7, prior, head);
        assert_eq!(npe.config.global_width(), 16 - 6);
        let (a, ha) = npe.predict_scaled(&pts, 1.0, 0.25e-3).unwrap();
        let (b, hb) = npe.predict_scaled_burn(&pts, 1.0, 0.25e-3).unwrap();
        assert_eq!((a.len(), ha.len()), (b.len(), hb.len()));
        assert!(b.iter().any(|v| v.abs() > 1e-3));
        for (x, y) in a.iter().zip(&b).chain(ha.iter().zip(&hb)) {
            assert!(
                (x - y).abs() <= 1e-4 * (1.0 + y.abs()),
                "prior {prior}: {x} vs {y}"
            );
        }
        if head {
            let (za, zb) = npe.contact_logits_both(&pts, 1.0, 0.25e-3).unwrap();
            for (x, y) in za.unwrap().iter().zip(&zb.unwrap()) {
                assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()), "{x} vs {y}");
            }
        }
        let mut shuffled = pts.clone();
        shuffled.reverse();
        shuffled.rotate_left(9);
        let (c, _) = npe.predict_scaled(&shuffled, 1.0, 0.25e-3).unwrap();
        for (x, y) in a.iter().zip(&c) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
    }
    // The same weights without the gap values in the node states give another field.
    let npe = gap_engine(7, false, false);
    let x = npe.predict_scaled(&pts, 1.0, 0.25e-3).unwrap().0;
    let mut cfg = npe.config.clone();
    cfg.node_gap = false;
    cfg.width = 14;
    let plain = Npe::new(cfg.init(&cpu(), 7).unwrap(), cfg, fine_surface()).unwrap();
    let y = plain.predict_scaled(&pts, 1.0, 0.25e-3).unwrap().0;
    assert_ne!(x, y);
    // Round trip.
    let path = std::env::temp_dir().join(format!("ocm-npe-gap-{}.ckpt", std::process::id()));
    npe.save(&path, serde_json::json!({})).unwrap();
    let back = Npe::load(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert!(back.config.node_gap);
    assert_eq!(back.predict_scaled(&pts, 1.0, 0.25e-3).unwrap().0, x);
}

/// A configuration stored before the gap input existed (no `node_gap` key) reads as an
/// engine without it, with the old layout (h_global = width - 4); one without the input
/// stores no key, so older readers still read it.
#[test]
fn configurations_without_the_gap_input_keep_their_layout() {
    let s = fine_surface();
    let cfg = NpeConfig::new(Prepared::top_center(&s.rest_m), SPACING_M);
    let json = serde_json::to_value(&cfg).unwrap();
    assert!(json.get("node_gap").is_none());
    let back: NpeConfig = serde_json::from_value(json).unwrap();
    assert!(!back.node_gap);
    assert_eq!(back.global_width(), back.width - 4);
    let mut bad = cfg.clone();
    bad.node_gap = true;
    bad.use_geometry = false;
    let e = bad.init(&cpu(), 0).unwrap_err();
    assert!(e.to_string().contains("gap input"), "{e}");
    let mut narrow = cfg;
    narrow.node_gap = true;
    narrow.width = 6;
    assert!(narrow.init(&cpu(), 0).is_err());
}

/// The bucketed nearest-node lookup behind the node's own penetration equals a brute-force
/// search over every node (points at irrational offsets, so no two nodes tie), also for
/// points just outside the face; a NaN coordinate finds no node.
#[test]
fn nearest_node_equals_brute_force() {
    let s = fine_surface();
    let loc = NodeLocator::new(&s.rest_m);
    for k in 0..400 {
        let t = f64::from(k);
        // Spread over the 5 x 5 mm face and 0.1 mm beyond each edge.
        let x = -0.1e-3 + 5.2e-3 * (t * 0.618_033_988_75).fract();
        let y = -0.1e-3 + 5.2e-3 * (t * 0.414_213_562_37 + 0.1).fract();
        let brute = (0..s.rest_m.len())
            .min_by(|&a, &b| {
                let d = |i: usize| (s.rest_m[i][0] - x).hypot(s.rest_m[i][1] - y);
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        assert_eq!(loc.nearest(x, y), Some(brute), "point {k} ({x}, {y})");
    }
    assert_eq!(loc.nearest(f64::NAN, 1e-3), None);
    assert_eq!(loc.nearest(1.0, 1e-3), None);
}
