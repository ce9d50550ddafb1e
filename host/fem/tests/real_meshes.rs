//! The real meshes of the project parse to their documented sizes.

use ocm_fem::mesh::{stl, surface, vtk};
use std::path::PathBuf;

fn data(rel: &str) -> Option<PathBuf> {
    ocm_datadir::test_data(rel)
}

#[test]
fn bellows_manipulator_vtk() {
    let Some(p) = data("bellows-manipulator/ManipulatorWhole25.vtk") else {
        return;
    };
    let m = vtk::read_path(p).unwrap();
    assert_eq!(m.points.len(), 2176);
    assert_eq!(m.tets.len(), 8883);
    let (lo, hi) = m.bounds();
    eprintln!(
        "bounds {lo:?} {hi:?} tris {} skipped {:?}",
        m.triangles.len(),
        m.skipped
    );
    // 176.5 mm tall, in millimetres.
    assert!((hi[2] - lo[2] - 176.5).abs() < 1.0 || (hi[1] - lo[1] - 176.5).abs() < 1.0);
}

#[test]
fn bellows_cavity_stl_matches_the_vtk_cavity_walls() {
    let (Some(p), Some(v)) = (
        data("bellows-manipulator/Cavity_sim25.stl"),
        data("bellows-manipulator/ManipulatorWhole25.vtk"),
    ) else {
        return;
    };
    // The STL is one cavity template (centred on the axis); the VTK carries three placed copies.
    let c = stl::read_path(p).unwrap();
    assert_eq!(surface::components(&c.triangles).len(), 1);
    assert_eq!(surface::open_edges(&c.triangles), 0, "closed surface");
    let v_stl = surface::enclosed_volume(&c.points, &c.triangles).abs();
    let m = vtk::read_path(v).unwrap();
    let comps = surface::components(&m.triangles);
    assert_eq!(comps.len(), 4, "skin + three cavity walls");
    let mut cavity_volumes: Vec<f64> = comps
        .iter()
        .map(|k| {
            surface::enclosed_volume(
                &m.points,
                &k.iter().map(|&t| m.triangles[t]).collect::<Vec<_>>(),
            )
            .abs()
        })
        .collect();
    cavity_volumes.sort_by(f64::total_cmp);
    for v in &cavity_volumes[..3] {
        assert!(
            (v - v_stl).abs() / v_stl < 0.05,
            "cavity {v} mm^3 vs STL {v_stl} mm^3"
        );
    }
}

#[test]
fn digit_meshes() {
    if let Some(p) = data("digit/DIGIT_v8.vtk") {
        let m = vtk::read_path(p).unwrap();
        assert_eq!(m.points.len(), 10_061);
        assert_eq!(m.tets.len(), 43_150);
        assert_eq!(m.triangles.len(), 11_804);
        let (lo, hi) = m.bounds();
        assert!(
            (hi[2] - lo[2] - 0.002).abs() < 1e-4,
            "2 mm thick, in metres: {lo:?} {hi:?}"
        );
    }
    if let Some(p) = data("digit/DIGIT_remesh2.vtk") {
        let m = vtk::read_path(p).unwrap();
        assert_eq!(m.points.len(), 441);
        assert_eq!(m.tets.len(), 1217);
    }
}
