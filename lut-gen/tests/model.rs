//! Energy model checks: derivatives against central differences, geometric
//! invariants of the layer, and the physical identities the model must obey.

use ocm_lutgen::energy::LayerEnergy;
use ocm_lutgen::geometry::{
    BARS, FACETS, HINGES, NODES, SIDES, enclosed_volume, mid, norm, ring1, ring2, ring3, sub,
};
use ocm_lutgen::{ModelError, OcmModel, OcmParams};

fn model() -> OcmModel {
    OcmModel::new(OcmParams::TABLE_3_1).expect("Table 3.1 parameters are valid")
}

fn strains() -> Vec<f64> {
    (0..=24).map(|i| -0.9 + 0.1 * i as f64).collect()
}

/// Relative closeness with an absolute floor.
fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

#[test]
fn element_counts_match_table_3_1() {
    let m = model();
    let t = &m.layer().topology;
    assert_eq!((NODES, BARS, HINGES, FACETS), (16, 40, 32, 24));
    assert_eq!(t.bars.len(), 40);
    assert_eq!(t.hinges.len(), 32);
    // Every node is used by some bar, no bar is degenerate or repeated.
    let mut used = [false; NODES];
    for (i, [p, q]) in t.bars.iter().enumerate() {
        assert_ne!(p, q);
        used[*p] = true;
        used[*q] = true;
        for [r, s] in &t.bars[..i] {
            assert!(
                !((p == r && q == s) || (p == s && q == r)),
                "bar {i} repeated"
            );
        }
    }
    assert!(used.iter().all(|u| *u));
}

#[test]
fn surface_with_caps_is_closed_and_consistently_oriented() {
    // Each directed edge of the lateral facets must be matched by its
    // reverse in another facet, except the bottom and top ring edges, which
    // the caps close.
    let m = model();
    let facets = &m.layer().topology.facets;
    for f in facets {
        for e in 0..3 {
            let (a, b) = (f[e], f[(e + 1) % 3]);
            let reverse = facets
                .iter()
                .flat_map(|g| (0..3).map(move |k| (g[k], g[(k + 1) % 3])))
                .filter(|&(p, q)| p == b && q == a)
                .count();
            let same = facets
                .iter()
                .flat_map(|g| (0..3).map(move |k| (g[k], g[(k + 1) % 3])))
                .filter(|&(p, q)| p == a && q == b)
                .count();
            assert_eq!(same, 1, "edge {a}->{b} used twice in one direction");
            let on_cap_ring = (a < SIDES && b < SIDES)
                || ((2 * SIDES..3 * SIDES).contains(&a) && (2 * SIDES..3 * SIDES).contains(&b));
            assert_eq!(reverse, usize::from(!on_cap_ring), "edge {a}->{b}");
        }
    }
}

#[test]
fn kinematic_constraints_hold_over_the_whole_strain_range() {
    // Ring edges keep the base side L and the diagonal creases keep their
    // flat-pattern length L / (2 cos theta_d), at every strain.
    let m = model();
    let p = m.params();
    let g = m.layer().geometry;
    let diag = p.base_side_m / (2.0 * p.side_angle_rad.cos());
    for e in strains() {
        let x = g.positions::<f64>(m.layer_height_m(e), 0.0);
        for k in 0..SIDES {
            for (a, b, len) in [
                (ring1(k), ring1(k + 1), p.base_side_m),
                (ring3(k), ring3(k + 1), p.base_side_m),
                (ring1(k), ring2(k), diag),
                (ring1(k + 1), ring2(k), diag),
                (ring3(k), ring2(k), diag),
                (ring3(k + 1), ring2(k), diag),
            ] {
                let l = norm(sub(x[b], x[a]));
                assert!(
                    close(l, len, 1e-12, 0.0),
                    "eps {e}: bar {a}-{b} is {l}, want {len}"
                );
            }
            // Mid nodes sit at the middle of the middle-ring edges.
            let half = norm(sub(x[mid(k)], x[ring2(k)]));
            let other = norm(sub(x[ring2(k + 1)], x[mid(k)]));
            assert!(close(half, other, 1e-12, 0.0));
        }
        // Layer height is what the strain says.
        let h = x[ring3(0)][2] - x[ring1(0)][2];
        assert!(close(h, m.layer_height_m(e), 1e-12, 0.0));
    }
    // The rest lengths stored in the model are those of the rest layer.
    let rest = &m.layer().rest;
    let x0 = g.positions::<f64>(g.rest_height_m, 0.0);
    for ([a, b], l0) in m.layer().topology.bars.iter().zip(rest.bar_length_m) {
        assert!(close(norm(sub(x0[*b], x0[*a])), l0, 1e-14, 0.0));
    }
}

#[test]
fn volume_is_positive_and_vanishes_when_folded_flat() {
    let m = model();
    let g = m.layer().geometry;
    let facets = &m.layer().topology.facets;
    let mut last = 0.0;
    for e in strains() {
        let x = g.positions::<f64>(m.layer_height_m(e), 0.0);
        let v = enclosed_volume(&x, facets);
        assert!(v > 0.0, "eps {e}: volume {v}");
        // Origin independence of the divergence-theorem sum is another
        // closure check.
        let shifted: Vec<[f64; 3]> = x
            .iter()
            .map(|p| [p[0] + 0.3, p[1] - 0.2, p[2] + 0.1])
            .collect();
        assert!(close(enclosed_volume(&shifted, facets), v, 1e-9, 0.0));
        if e <= 0.0 {
            assert!(v > last, "volume grows with height on the lower branch");
        }
        last = v;
    }
    let flat = g.positions::<f64>(1e-12, 0.0);
    assert!(enclosed_volume(&flat, facets).abs() < 1e-14);
}

/// Shoelace area of the section through the midpoints of the lateral edges
/// between the bottom and middle rings (a polygon at quarter height).
fn quarter_section_area(x: &[[f64; 3]; NODES]) -> f64 {
    let mut pts: Vec<[f64; 2]> = Vec::new();
    for k in 0..SIDES {
        for (a, b) in [
            (ring1(k), ring2(k)),
            (ring1(k + 1), ring2(k)),
            (ring1(k + 1), mid(k)),
        ] {
            pts.push([0.5 * (x[a][0] + x[b][0]), 0.5 * (x[a][1] + x[b][1])]);
        }
    }
    pts.sort_by(|p, q| p[1].atan2(p[0]).total_cmp(&q[1].atan2(q[0])));
    let n = pts.len();
    (0..n)
        .map(|i| {
            let (p, q) = (pts[i], pts[(i + 1) % n]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum::<f64>()
        * 0.5
}

#[test]
fn volume_matches_the_prismatoid_formula() {
    // Each half layer has all its vertices in two parallel planes, so its
    // volume is exactly (h/6)(A_bottom + 4 A_mid + A_top): an independent
    // check of the tetrahedral decomposition.
    let m = model();
    let g = m.layer().geometry;
    for e in strains() {
        let h = m.layer_height_m(e);
        let x = g.positions::<f64>(h, 0.0);
        let r2 = g.middle_radius(h);
        let a_ring = 2.0 * g.outer_radius_m.powi(2);
        let a_mid_ring = 2.0 * r2 * r2;
        let a_quarter = quarter_section_area(&x);
        let v_half = (0.5 * h / 6.0) * (a_ring + 4.0 * a_quarter + a_mid_ring);
        let v = enclosed_volume(&x, &m.layer().topology.facets);
        assert!(
            close(v, 2.0 * v_half, 1e-10, 0.0),
            "eps {e}: {v} vs {}",
            2.0 * v_half
        );
    }
}

#[test]
fn strain_limits_come_from_the_crease_height() {
    let m = model();
    let p = m.params();
    let (lo, hi) = m.strain_limits();
    assert_eq!(lo, -1.0);
    let h_star = p.base_side_m * p.side_angle_rad.tan();
    assert!(close(
        hi,
        p.layers as f64 * h_star / p.rest_length_m - 1.0,
        1e-12,
        0.0
    ));
    assert!(hi > 0.6, "the table range must be reachable");
    assert!(matches!(
        m.bend_config(0.0, hi + 0.01),
        Err(ModelError::OutOfRange { .. })
    ));
    assert!(matches!(
        m.bend_config(0.0, f64::NAN),
        Err(ModelError::OutOfRange { .. })
    ));
    assert!(m.strain_for_force(0.0, 0.0, (-1.5, 0.5)).is_err());
}

#[test]
fn zero_force_and_moment_at_rest_without_pressure() {
    let m = model();
    assert!(m.axial_force_n(0.0, 0.0).abs() < 1e-12);
    for e0 in [-0.5, 0.0, 0.5] {
        for p in [0.0, 20e3] {
            assert!(m.bending_moment_nm(0.0, e0, p).abs() < 1e-12);
        }
    }
    assert!(m.energy_j(0.0, 0.0, 0.0).abs() < 1e-18);
}

#[test]
fn axial_force_is_the_energy_derivative() {
    let m = model();
    let l0 = m.params().rest_length_m;
    for e in strains() {
        for p in [0.0, 12e3, 30e3] {
            let d = 1e-6;
            let fd = (m.energy_j(e + d, 0.0, p) - m.energy_j(e - d, 0.0, p)) / (2.0 * d * l0);
            let f = m.axial_force_n(e, p);
            assert!(close(f, fd, 1e-6, 1e-7), "eps {e} P {p}: {f} vs {fd}");
            let k_fd = (m.axial_force_n(e + d, p) - m.axial_force_n(e - d, p)) / (2.0 * d * l0);
            let k = m.axial_stiffness_n_per_m(e, p);
            assert!(close(k, k_fd, 1e-5, 1e-4), "eps {e} P {p}: {k} vs {k_fd}");
        }
    }
}

#[test]
fn bending_moment_is_the_energy_derivative() {
    let m = model();
    for e0 in [-0.6, -0.2, 0.0, 0.3, 0.6] {
        let phi_max = m.max_bend_angle_rad(e0);
        for u in [0.05, 0.3, 0.6, 0.95] {
            let phi = u * phi_max;
            for p in [0.0, 25e3] {
                let d = 1e-6;
                let fd = (m.energy_j(e0, phi + d, p) - m.energy_j(e0, phi - d, p)) / (2.0 * d);
                let mm = m.bending_moment_nm(phi, e0, p);
                assert!(
                    close(mm, fd, 1e-6, 1e-10),
                    "e0 {e0} phi {phi}: {mm} vs {fd}"
                );
                let k_fd = (m.bending_moment_nm(phi + d, e0, p)
                    - m.bending_moment_nm(phi - d, e0, p))
                    / (2.0 * d);
                let k = m.bending_stiffness_nm_per_rad(phi, e0, p);
                assert!(
                    close(k, k_fd, 1e-5, 1e-9),
                    "e0 {e0} phi {phi}: {k} vs {k_fd}"
                );
            }
        }
    }
}

#[test]
fn force_and_moment_derive_from_one_potential() {
    // Maxwell relation: d(F)/d(phi) = d(M)/d(l).
    let m = model();
    let l0 = m.params().rest_length_m;
    let (d, p) = (1e-4, 15e3);
    for (e, phi) in [(0.0, 0.5), (0.4, 1.2), (-0.4, 0.3)] {
        let df_dphi = (m.energy_j(e + d, phi + d, p)
            - m.energy_j(e + d, phi - d, p)
            - m.energy_j(e - d, phi + d, p)
            + m.energy_j(e - d, phi - d, p))
            / (4.0 * d * d * l0);
        let dm_dl = (m.bending_moment_nm(phi, e + d, p) - m.bending_moment_nm(phi, e - d, p))
            / (2.0 * d * l0);
        assert!(close(df_dphi, dm_dl, 1e-4, 1e-6), "{df_dphi} vs {dm_dl}");
    }
}

#[test]
fn pressure_work_is_linear_in_pressure() {
    // eq 3.7: the pressure term is P times the volume change, so the force
    // is affine in P with slope -dV/dl.
    let m = model();
    let layer: &LayerEnergy = m.layer();
    let n = m.params().layers as f64;
    for e in strains() {
        let (f0, f1, f2) = (
            m.axial_force_n(e, 0.0),
            m.axial_force_n(e, 10e3),
            m.axial_force_n(e, 20e3),
        );
        assert!(close(f2 - f1, f1 - f0, 1e-9, 1e-12));
        let t = m.axial_terms(e);
        let h = m.layer_height_m(e);
        let d = 1e-9;
        let dv = (layer.parts(h + d, 0.0).volume - layer.parts(h - d, 0.0).volume) / (2.0 * d);
        assert!(close(t.pressure_n_per_pa, -dv, 1e-5, 1e-12));
        let e_pv = m.energy_j(e, 0.0, 10e3) - m.energy_j(e, 0.0, 0.0);
        assert!(close(
            e_pv,
            -10e3 * n * layer.parts(h, 0.0).volume,
            1e-9,
            1e-15
        ));
    }
}

#[test]
fn bending_is_odd_in_the_angle() {
    let m = model();
    for e0 in [-0.5, 0.0, 0.5] {
        for phi in [0.1, 0.7, 1.1] {
            for p in [0.0, 30e3] {
                let a = m.bending_moment_nm(phi, e0, p);
                let b = m.bending_moment_nm(-phi, e0, p);
                assert!(close(a, -b, 1e-9, 1e-14), "{a} vs {b}");
                assert!(a > 0.0);
            }
        }
    }
}

#[test]
fn bending_keeps_the_neutral_axis_and_feasible_range_grows_with_strain() {
    let m = model();
    let mut last = 0.0;
    for e0 in [-0.6, -0.3, 0.0, 0.3, 0.6] {
        let full = m.bend_config(0.0, e0).unwrap();
        assert!(close(full.arc_length_m, m.arc_length_m(e0), 1e-12, 0.0));
        let phi_max = m.max_bend_angle_rad(e0);
        assert!(phi_max > last);
        last = phi_max;
        let h = m.layer_height_m(e0);
        for frac in [0.1, 0.5, 0.9] {
            // delta_l ranges up to about half the layer height (eq 3.11 discussion).
            let c = m.bend_config(frac * 0.5 * h, e0).unwrap();
            assert!(close(c.arc_length_m, m.arc_length_m(e0), 1e-12, 0.0));
            assert!(close(
                c.radius_m * c.bend_angle_rad,
                c.arc_length_m,
                1e-12,
                0.0
            ));
            assert!(close(c.curvature_per_m * c.radius_m, 1.0, 1e-12, 0.0));
            assert!(c.bend_angle_rad <= phi_max * 1.0001);
            // The geometric delta_l matches the bent nodal positions.
            let x = m
                .layer()
                .geometry
                .positions::<f64>(h, c.bend_angle_rad / m.params().layers as f64);
            let dz = 0.5 * (x[ring2(2)][2] - x[ring2(0)][2]);
            assert!(
                close(dz, c.delta_l_m, 1e-9, 1e-15),
                "{dz} vs {}",
                c.delta_l_m
            );
        }
    }
}

#[test]
fn inverse_maps_round_trip() {
    let m = model();
    for e in [-0.55, -0.2, 0.0, 0.33, 0.58] {
        for p in [0.0, 14e3, 30e3] {
            let f = m.axial_force_n(e, p);
            let back = m.strain_for_force(f, p, (-0.6, 0.6)).unwrap();
            assert!((back - e).abs() < 1e-10, "{back} vs {e}");
        }
    }
    for e0 in [-0.4, 0.0, 0.5] {
        let phi = 0.6 * m.max_bend_angle_rad(e0);
        for p in [0.0, 30e3] {
            let mm = m.bending_moment_nm(phi, e0, p);
            assert!((m.bend_angle_for_moment(mm, e0, p).unwrap() - phi).abs() < 1e-10);
            assert!((m.bend_angle_for_moment(-mm, e0, p).unwrap() + phi).abs() < 1e-10);
        }
    }
    assert!(matches!(
        m.strain_for_force(1e6, 0.0, (-0.6, 0.6)),
        Err(ModelError::Unreachable { .. })
    ));
}

#[test]
fn invalid_parameters_are_named() {
    // 100 mm layers cannot be folded from 30 mm creases.
    let p = OcmParams {
        rest_length_m: 1.0,
        ..OcmParams::TABLE_3_1
    };
    match OcmModel::new(p) {
        Err(ModelError::InvalidParameter { name, .. }) => assert_eq!(name, "rest_length_m"),
        other => panic!("unexpected {other:?}"),
    }
    let p = OcmParams {
        bar_stiffness_n_per_m: f64::NAN,
        ..OcmParams::TABLE_3_1
    };
    assert!(matches!(
        OcmModel::new(p),
        Err(ModelError::InvalidParameter {
            name: "bar_stiffness_n_per_m",
            ..
        })
    ));
    let p = OcmParams {
        layers: 0,
        ..OcmParams::TABLE_3_1
    };
    assert!(OcmModel::new(p).is_err());
}
