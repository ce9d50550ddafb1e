//! The DIGIT gel (the coarse mesh; the fine one where named) pressed by the real indenter STLs
//! of the set-up files, and the errors for bad inputs.

use ocm_datadir::test_data;
use ocm_tactile::TactileError;
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::indent::{IndentOptions, Indentation, Placement};
use ocm_tactile::indenter::Indenter;
use ocm_tactile::mask::{Grid, Mask};
use ocm_tactile::setup::{Setup, digit_setups, read_setups};
use std::path::PathBuf;

fn digit_dir() -> Option<PathBuf> {
    test_data("digit/indenter_settings.json").map(|p| p.parent().unwrap().to_path_buf())
}

/// All 70 set-ups resolve to closed indenter STLs.
#[test]
fn setups_resolve_to_closed_indenters() {
    let Some(dir) = digit_dir() else { return };
    let setups = digit_setups(&dir).unwrap();
    assert_eq!(setups.len(), 70);
    assert_eq!(setups.iter().filter(|s| s.unseen).count(), 8);
    let mut seen = std::collections::BTreeSet::new();
    for s in &setups {
        if seen.insert(s.stl.clone()) {
            let ind = Indenter::from_stl(&s.stl).unwrap();
            let (lo, hi) = ind.bounds;
            // Every indenter is a few millimetres to 3 cm across once in metres.
            assert!(
                hi[0] - lo[0] > 1e-3 && hi[0] - lo[0] < 0.04,
                "{}: {lo:?} {hi:?}",
                s.name
            );
            assert!(ind.volume() > 0.0);
        }
    }
}

/// One STL touches itself, along an edge shared by four triangles: the unseen `id4` (the two
/// such edges of `stamp.stl` bound a sliver of two triangles that welding removes). The edge
/// lies at id4's lowest point, so that is where it first presses the gel (the set-up presses it
/// unrotated) and where its FEM stops at the first step.
#[test]
fn self_touching_edges_are_found_where_id4_first_presses() {
    let Some(dir) = digit_dir() else { return };
    let setups = digit_setups(&dir).unwrap();
    let mut pinched = std::collections::BTreeMap::new();
    let mut seen = std::collections::BTreeSet::new();
    for s in &setups {
        if seen.insert(s.stl.clone()) {
            let ind = Indenter::from_stl(&s.stl).unwrap();
            if !ind.pinch_edges.is_empty() {
                pinched.insert(ind.name.to_lowercase(), ind.pinch_edges.len());
            }
        }
    }
    let expected: std::collections::BTreeMap<String, usize> = [("id4".to_string(), 1)].into();
    assert_eq!(pinched, expected);
    let id4 = setups.iter().find(|s| s.name == "id4").unwrap();
    assert_eq!(id4.placement.euler_deg, [0.0; 3]);
    let ind = Indenter::from_stl(&id4.stl).unwrap();
    let lowest = ind.pinch_edges[0][0].z.min(ind.pinch_edges[0][1].z);
    assert!(
        lowest - ind.z_min < 0.05e-3,
        "the pinch reaches {lowest} m, the tip {} m",
        ind.z_min
    );
}

/// The coarse gel and the set-up `name` with its indenter, when the data are here.
fn on_coarse_gel(name: &str) -> Option<(Gel, Setup, Indenter)> {
    let (dir, mesh) = (digit_dir()?, test_data("digit/DIGIT_remesh2.vtk")?);
    let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let s = digit_setups(&dir)
        .unwrap()
        .into_iter()
        .find(|s| s.name == name)
        .unwrap();
    let ind = Indenter::from_stl(&s.stl).unwrap();
    Some((gel, s, ind))
}

/// The sphere set-up `sphere1` on the coarse gel for 20 steps (0.2 mm): every step converges
/// with the penetration within tolerance, the force grows with depth, and the contact mask sits
/// under the indenter.
#[test]
fn sphere_on_coarse_gel() {
    let Some((gel, s, ind)) = on_coarse_gel("sphere1") else {
        return;
    };
    let mut o = IndentOptions::protocol(gel.material.young_pa);
    o.steps = 20;
    let mut run = Indentation::new(&s.name, &gel, &ind, s.placement, o).unwrap();
    let out = run.run(|_| {}).unwrap();
    let mut last_f = 0.0;
    for st in &out {
        assert!(st.max_penetration_m <= o.contact.penetration_tol_m);
        assert!(st.indenter_force_n[2] >= last_f, "step {}", st.step);
        last_f = st.indenter_force_n[2];
    }
    assert!(last_f > 0.0);
    let grid = Grid::for_gel(&gel);
    let m = Mask::from_displacement(&gel, &grid, &out.last().unwrap().displacement);
    let st = m.stats();
    assert!(st.area_m2 > 0.0);
    let d = ((st.centroid_m[0] - s.placement.xy_m[0]).powi(2)
        + (st.centroid_m[1] - s.placement.xy_m[1]).powi(2))
    .sqrt();
    // The coarse gel's top is convex: the sphere first touches off its tip, towards the apex.
    assert!(
        d < 2e-3,
        "mask centroid {:?} is {d} m from the set-up",
        st.centroid_m
    );
}

/// The unseen `id4` on the coarse gel, 20 steps of 50 um (the data sets' protocol): the
/// closest-point law alone stops at step 10, where nodes caught between its bumps are pushed
/// by one face at a time; with the held-plane retry (the default) every step converges, the
/// steps from the retry on under held planes, each within the held law's tolerance (5 % of a
/// step), and the force grows with depth.
#[test]
fn id4_converges_on_held_planes_where_closest_points_stall() {
    let Some((gel, s, ind)) = on_coarse_gel("id4") else {
        return;
    };
    let mut o = IndentOptions::protocol(gel.material.young_pa);
    o.steps = 20;
    o.step_m = 50e-6;
    o.held_plane_retry = false;
    let mut run = Indentation::new(&s.name, &gel, &ind, s.placement, o).unwrap();
    match run.run(|_| {}) {
        Err(TactileError::NoConvergence { step, .. }) => assert_eq!(step, 10),
        other => panic!("the closest-point law alone: {:?}", other.map(|v| v.len())),
    }
    o.held_plane_retry = true;
    let mut run = Indentation::new(&s.name, &gel, &ind, s.placement, o).unwrap();
    let out = run.run(|_| {}).unwrap();
    assert_eq!(out.len(), 20);
    let first_held = out.iter().position(|st| st.held_planes).unwrap();
    assert_eq!(out[first_held].step, 10);
    assert!(out[first_held..].iter().all(|st| st.held_planes));
    let mut last_f = 0.0;
    for st in &out {
        let tol = if st.held_planes {
            o.held_penetration_tol_m()
        } else {
            o.contact.penetration_tol_m
        };
        assert!(
            st.max_penetration_m <= tol,
            "step {}: {} m",
            st.step,
            st.max_penetration_m
        );
        assert!(st.indenter_force_n[2] >= last_f, "step {}", st.step);
        last_f = st.indenter_force_n[2];
    }
    assert!((out[19].depth_m - 1e-3).abs() < 1e-12);
    assert!((o.held_penetration_tol_m() - 2.5e-6).abs() < 1e-15);
}

/// The flat square punch `square1` on DIGIT_v8, as the data set presses it (20 steps of 50 um):
/// from about 0.8 mm the gel crushed under the punch's edges has an indefinite tangent, where
/// LU's Newton step climbed the contact potential and the run stopped at 0.85 mm (0.852 under
/// held planes). Shifted to a positive definite tangent, every step converges to 1 mm under
/// the closest-point law, within its tolerance, with a force that grows with depth.
#[test]
fn square_punch_converges_through_indefinite_tangents() {
    let (Some(dir), Some(mesh)) = (digit_dir(), test_data("digit/DIGIT_v8.vtk")) else {
        return;
    };
    let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let s = digit_setups(&dir)
        .unwrap()
        .into_iter()
        .find(|s| s.name == "square1")
        .unwrap();
    let ind = Indenter::from_stl(&s.stl).unwrap();
    let mut o = IndentOptions::protocol(gel.material.young_pa);
    o.steps = 20;
    o.step_m = 50e-6;
    let mut run = Indentation::new(&s.name, &gel, &ind, s.placement, o).unwrap();
    let out = run.run(|_| {}).unwrap();
    assert_eq!(out.len(), 20);
    assert!((out[19].depth_m - 1e-3).abs() < 1e-12);
    let shifted: usize = out.iter().map(|st| st.shifted_solves).sum();
    assert!(shifted > 0, "no indefinite tangent on the way to 1 mm");
    let mut last_f = 0.0;
    for st in &out {
        assert!(!st.held_planes, "step {} needed held planes", st.step);
        assert!(
            st.max_penetration_m <= o.contact.penetration_tol_m,
            "step {}: {} m",
            st.step,
            st.max_penetration_m
        );
        assert!(st.indenter_force_n[2] > last_f, "step {}", st.step);
        last_f = st.indenter_force_n[2];
    }
}

/// A set-up naming a missing indenter, an open STL, and an indenter placed off the gel each give
/// an error that says what and where.
#[test]
fn bad_inputs_give_clear_errors() {
    let (Some(dir), Some(mesh)) = (digit_dir(), test_data("digit/DIGIT_remesh2.vtk")) else {
        return;
    };
    let tmp = std::env::temp_dir().join(format!("ocm-tactile-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let json = tmp.join("setups.json");
    std::fs::write(
        &json,
        r#"[{"name": "ghost1", "filename_stl": "Indenter/ghost.STL", "translation": [0, 10, 2.05], "orientation": [0, 0, 0]}]"#,
    )
    .unwrap();
    let e = read_setups(&json, &dir.join("indenters"), false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ghost1") && e.contains("ghost.STL"), "{e}");

    // An STL with one facet dropped is open.
    let bytes = std::fs::read(dir.join("indenters/edge.stl")).unwrap();
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    let mut cut = bytes[..84 + 50 * (n - 1)].to_vec();
    cut[80..84].copy_from_slice(&((n - 1) as u32).to_le_bytes());
    let open = tmp.join("open.stl");
    std::fs::write(&open, cut).unwrap();
    let e = Indenter::from_stl(&open).unwrap_err().to_string();
    assert!(e.contains("not closed"), "{e}");

    let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let ind = Indenter::from_stl(dir.join("indenters/sphere.stl")).unwrap();
    let off = Placement {
        xy_m: [0.03, 0.05],
        euler_deg: [0.0; 3],
    };
    let o = IndentOptions::protocol(gel.material.young_pa);
    let e = Indentation::new("far", &gel, &ind, off, o).err().unwrap();
    assert!(matches!(e, TactileError::OffGel { .. }), "{e}");
    assert!(e.to_string().contains("far") && e.to_string().contains("touches no"));
    std::fs::remove_dir_all(&tmp).ok();
}

/// The DIGIT_v8 gel that `compare-real` crowns (14 mm, apex at the top's centre) keeps its
/// plateau, where the crown is capped, deeper below the apex than the protocol's deepest step:
/// a pressed indenter meets the dome, never the plateau's flat rim at once.
#[test]
fn the_protocol_stays_off_the_crowns_plateau() {
    let Some(mesh) = test_data("digit/DIGIT_v8.vtk") else {
        return;
    };
    let flat = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let (lo, hi) = flat.top_bounds();
    let crown = ocm_tactile::gel::Crown {
        radius_m: 14e-3,
        apex_m: [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])],
    };
    let gel = Gel::digit_crowned(&mesh, GelMaterial::default(), Some(&crown)).unwrap();
    // the same nodes in both (one mesh file): the flat top's
    let deepest = flat
        .top
        .iter()
        .map(|&i| flat.mesh.points[i][2] - gel.mesh.points[i][2])
        .fold(0.0, f64::max);
    let o = IndentOptions::protocol(gel.material.young_pa);
    let protocol_m = o.steps as f64 * o.step_m;
    // the 15 x 20 mm top reaches the cap at 14 mm (5.4 mm from the apex)
    let cap =
        ocm_tactile::gel::CROWN_MAX_DROP_SHARE * (flat.z_top - ocm_tactile::gel::DIGIT_BASE_Z_M);
    assert!((deepest - cap).abs() < 1e-9, "{deepest} {cap}");
    assert!(
        deepest > protocol_m,
        "plateau {deepest} m, protocol {protocol_m} m"
    );
}

/// Out-of-range numbers are refused with the parameter's name and value, before any solve:
/// friction, penalties, the material and a depth that would reach the held base (these once ran:
/// a friction of -1 or infinity changed the force, 2 steps of 1e9 um "converged" at 0 N).
#[test]
fn out_of_range_parameters_are_refused() {
    let (Some(dir), Some(mesh)) = (digit_dir(), test_data("digit/DIGIT_remesh2.vtk")) else {
        return;
    };
    let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let setups = digit_setups(&dir).unwrap();
    let s = setups.iter().find(|s| s.name == "edge6").unwrap();
    let ind = Indenter::from_stl(&s.stl).unwrap();
    let refused = |o: IndentOptions| -> String {
        Indentation::new(&s.name, &gel, &ind, s.placement, o)
            .err()
            .expect("refused")
            .to_string()
    };
    let base = IndentOptions::protocol(gel.material.young_pa);
    for f in [-1.0, f64::NAN, f64::INFINITY] {
        let mut o = base;
        o.contact.friction = f;
        let e = refused(o);
        assert!(e.contains("friction") && e.contains(&format!("{f}")), "{e}");
    }
    let mut o = base;
    o.contact.normal_penalty_pa_m = 0.0;
    assert!(refused(o).contains("normal penalty"));
    let mut o = base;
    o.contact.penetration_tol_m = f64::NAN;
    assert!(refused(o).contains("penetration tolerance"));
    let mut o = base;
    o.steps = 2;
    o.step_m = 1e3;
    let e = refused(o);
    assert!(e.contains("edge6") && e.contains("held base"), "{e}");
    // the whole protocol (1 mm) stays well above the base
    assert!(Indentation::new(&s.name, &gel, &ind, s.placement, base).is_ok());
    for (young_pa, poisson, what) in [
        (-5.0, 0.45, "Young's modulus"),
        (f64::NAN, 0.45, "Young's modulus"),
        (0.3e6, 0.5, "Poisson's ratio"),
        (0.3e6, f64::NAN, "Poisson's ratio"),
    ] {
        let e = Gel::digit(&mesh, GelMaterial::new(young_pa, poisson))
            .expect_err("refused")
            .to_string();
        assert!(e.contains(what), "{e}");
    }
}
