//! Kinematics on real LUT images: fixed point against the f64 twin on the
//! default physics image (the one users flash), over the pressures at which
//! that image keeps the OCMs inside its strain range; the LUT path against
//! an exact formula on the closed-form bring-up image.

// Parallel arrays (fixed vs f64, per actuator) read clearest by index.
#![allow(clippy::needless_range_loop)]

use ocm_firmware::fx::{angle_q28_to_rad, from_f64, to_f64};
use ocm_firmware::kinematics::{self as k, LoadFx, Model};
use ocm_firmware::maps::OcmMaps;
use ocm_firmware_support::bringup;
use ocm_firmware_support::maps_f64::OcmMapsF64;
use ocm_firmware_support::physics;
use ocm_firmware_support::reference::{self as r, ConfigF64, LoadF64, ModelF64};
use ocm_shared::lut::{LUT_CAPACITY, LutImage, PRESSURE_MARGIN_PA};
use ocm_shared::params::{ManipulatorParams, OcmParams};
use ocm_shared::protocol::{Geometry, Load, MAX_SEGMENTS, Mount};
use proptest::prelude::*;
use std::sync::OnceLock;

/// The closed-form image, whose maps are known exactly.
fn bringup_image() -> &'static [u8] {
    static IMG: OnceLock<Vec<u8>> = OnceLock::new();
    IMG.get_or_init(|| {
        let mut buf = vec![0u8; LUT_CAPACITY];
        let n = bringup::write_image(&OcmParams::TABLE_3_1, &mut buf).unwrap();
        buf.truncate(n);
        buf
    })
}

/// The default physics image.
fn image() -> &'static [u8] {
    physics::default_image()
}

/// The pressures, Pa, the image answers for: its grid plus the margin the
/// reader extrapolates over.
fn accepted_pa() -> (f64, f64) {
    let g = LutImage::parse(image()).unwrap().axial_grid();
    let margin = f64::from(PRESSURE_MARGIN_PA);
    (
        g.p_min.to_num::<f64>() - margin,
        g.p_max.to_num::<f64>() + margin,
    )
}

/// Pressures, Pa, at which an unloaded OCM of the physics image sits at
/// strain -0.45 and +0.45, kept 2 kPa inside what the image answers for: a
/// workspace inside the table's strain range whatever parameter set the
/// default image is built for.
fn workspace_pa() -> (f64, f64) {
    static W: OnceLock<(f64, f64)> = OnceLock::new();
    *W.get_or_init(|| {
        let lut = LutImage::parse(image()).unwrap();
        let g = lut.axial_grid();
        let (lo, hi) = (g.p_min.to_num::<f64>(), g.p_max.to_num::<f64>());
        let a = lut.pressure_for_f64(-0.45, 0.0, lo, hi).unwrap();
        let b = lut.pressure_for_f64(0.45, 0.0, lo, hi).unwrap();
        let (min, max) = accepted_pa();
        (a.min(b).max(min + 2_000.0), a.max(b).min(max - 2_000.0))
    })
}

/// Command limits for the inverse: the workspace widened by half its width
/// on each side, inside what the image answers for.
fn limits_q8() -> (i32, i32) {
    let (min, max) = accepted_pa();
    (
        from_f64(at(-0.5).max(min), 8),
        from_f64(at(1.5).min(max), 8),
    )
}

/// A pressure in the workspace at fraction `u` in 0..1.
fn at(u: f64) -> f64 {
    let (lo, hi) = workspace_pa();
    lo + u * (hi - lo)
}

fn geometry(segments: u32, mount: Mount) -> Geometry {
    Geometry {
        manipulator: ManipulatorParams {
            segments,
            ..ManipulatorParams::TABLE_3_1
        },
        ocm: OcmParams::TABLE_3_1,
        mount,
    }
}

#[test]
fn lut_maps_match_the_closed_form_model() {
    let lut = LutImage::parse(bringup_image()).unwrap();
    for &(eps, p) in &[(0.1, 5_000.0), (-0.3, 20_000.0), (0.45, 33_000.0)] {
        let f = bringup::axial_force_n(eps, p);
        let back = lut.strain_f64(f, p).unwrap();
        assert!((back - eps).abs() < 2e-3, "{back} vs {eps}");
        let fq = lut.force(from_f64(eps, 16), from_f64(p, 8)).unwrap();
        assert!((to_f64(fq.into(), 16) - f).abs() < 0.02);
    }
    let m = bringup::bending_moment_nm(0.2, 0.04, 10_000.0, 0.04);
    let phi = lut.bend_f64(m, 0.04, 10_000.0).unwrap();
    assert!((phi - 0.2).abs() < 2e-3, "{phi}");
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 300,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x6c75_7431),
        ..ProptestConfig::default()
    })]

    /// Tip within 0.05 mm between fixed point and f64 over the pressure
    /// workspace, loads and 1..3 segments.
    #[test]
    fn tip_fixed_matches_f64_over_workspace(
        segments in 1u32..=3,
        u in proptest::array::uniform9(0.0f64..1.0),
        payload in 0.0f32..0.3,
        mx in -0.05f32..0.05,
        my in -0.05f32..0.05,
        hanging in any::<bool>(),
    ) {
        let lut = LutImage::parse(image()).unwrap();
        let p = u.map(at);
        let g = geometry(segments, if hanging { Mount::Hanging } else { Mount::Upright });
        let load = Load { payload_kg: payload, force_z_n: 0.0, moment_x_newton_m: mx, moment_y_newton_m: my };
        let model = Model::new(&g).unwrap();
        let mf = ModelF64::new(&g);
        let lfx = LoadFx::new(&load, &model).unwrap();
        let lf = LoadF64::new(&load, &mf);
        let pq: Vec<i32> = p.iter().map(|&x| from_f64(x, 8)).collect();
        let pf: Vec<f64> = pq.iter().map(|&x| to_f64(x.into(), 8)).collect();
        let cfx = k::forward(&lut, &model, &lfx, &pq).unwrap();
        let mut cf = [ConfigF64::default(); MAX_SEGMENTS];
        let n = r::forward(&lut, &mf, &lf, &pf, &mut cf).unwrap();
        let a = k::tip_pose(&cfx).p_q24;
        let b = r::tip_pose(&cf[..n]).p;
        let err = (0..3).map(|i| (to_f64(a[i].into(), 24) - b[i]).powi(2)).sum::<f64>().sqrt();
        prop_assert!(err < 0.05e-3, "tip error {} m", err);
        for (c, d) in cfx.iter().zip(&cf[..n]) {
            prop_assert!((angle_q28_to_rad(c.bend_q28) - d.bend_rad).abs() < 1e-3);
        }
    }

    /// Inverse (3.36) of the forward (3.35) returns the pressures.
    #[test]
    fn inverse_returns_forward_pressures(
        segments in 1u32..=3,
        u in proptest::array::uniform9(0.05f64..0.95),
        mx in -0.03f32..0.03,
        my in -0.03f32..0.03,
    ) {
        let lut = LutImage::parse(image()).unwrap();
        let p = u.map(at);
        let g = geometry(segments, Mount::Upright);
        let model = Model::new(&g).unwrap();
        let load = Load { payload_kg: 0.1, force_z_n: 0.0, moment_x_newton_m: mx, moment_y_newton_m: my };
        let lfx = LoadFx::new(&load, &model).unwrap();
        let pq: Vec<i32> = p.iter().map(|&x| from_f64(x, 8)).collect();
        let cfx = k::forward(&lut, &model, &lfx, &pq).unwrap();
        let (lo, hi) = limits_q8();
        let sol = k::inverse(&lut, &model, &lfx, &cfx, lo, hi).unwrap();
        // Strain quantisation and the bending map's pressure pass, as a
        // share of the workspace (the physics image's dF/dP sets its width):
        // measured at most 5.5e-5 of it (2.2 Pa of 41 kPa) over 2,000 cases.
        let tol = 2.5e-4 * (at(1.0) - at(0.0));
        for (a, b) in sol.pressures_q8.iter().zip(&pq) {
            prop_assert!(to_f64((a - b).into(), 8).abs() < tol, "{} vs {}", to_f64((*a).into(), 8), to_f64((*b).into(), 8));
        }
    }
}

#[test]
fn fast_pressure_solve_matches_the_image_forward_map() {
    use ocm_firmware::maps::{FastLut, MemoBend};
    let img = LutImage::parse(image()).unwrap();
    let fast = FastLut::new(img);
    let (lo, hi) = limits_q8();
    let span = at(1.0) - at(0.0);
    let mut worst = 0.0f64;
    for k in 0..200 {
        let eps = -0.55 + 1.1 * f64::from(k) / 199.0;
        let p_true = at(f64::from(k) / 199.0);
        // The image's own forward map is affine in P (eq 3.7): the solve
        // must return the pressure it was evaluated at.
        let f = img.force_f64(eps, p_true).unwrap();
        let (e, fq) = (from_f64(eps, 16), from_f64(f, 16));
        // Reference: the trait's secant on the image's own forward lookups.
        let slow = OcmMaps::pressure_for(&img, e, fq, lo, hi).unwrap();
        let quick = fast.pressure_for(e, fq, lo, hi).unwrap();
        worst = worst.max(to_f64((slow - quick).into(), 8).abs());
        // Measured at most 1.7e-6 of the workspace (0.07 Pa).
        assert!(
            (to_f64(quick.into(), 8) - p_true).abs() < 1e-5 * span,
            "eps {eps}: {} vs {p_true}",
            to_f64(quick.into(), 8)
        );
    }
    // Both are exact for an affine map up to table quantisation.
    assert!(
        worst < 2.0,
        "fast and slow pressure solves differ by {worst} Pa"
    );
    // The bending memo returns what the map returns, and follows key changes.
    let cache = core::cell::Cell::new([None; 3]);
    let memo = MemoBend::new(&fast, &cache);
    for &(m, p) in &[
        (0.02, 0.0),
        (0.02, 0.0),
        (0.03, 5_000.0),
        (0.02, 0.0),
        (0.01, 1_000.0),
        (0.05, 9_000.0),
        (0.02, 0.0),
    ] {
        let (mq, s, pq) = (from_f64(m, 24), from_f64(0.04, 24), from_f64(p, 8));
        assert_eq!(memo.bend(mq, s, pq), fast.bend(mq, s, pq));
    }
}
