//! Fixed-point kinematics against the f64 reference twin.

// Parallel arrays (fixed vs f64, per actuator) read clearest by index.
#![allow(clippy::needless_range_loop)]

use ocm_firmware::fx::{angle_q28_from_rad, angle_q28_to_rad, from_f64, to_f64};
use ocm_firmware::kinematics::{self as k, LoadFx, Model};
use ocm_firmware::maps::OcmMaps;
use ocm_firmware_support::linear::LinearOcm;
use ocm_firmware_support::reference::{self as r, ConfigF64, LoadF64, ModelF64};
use ocm_shared::params::{ManipulatorParams, OcmParams};
use ocm_shared::protocol::{Geometry, Load, MAX_SEGMENTS, Mount, SegmentConfig};
use proptest::prelude::*;

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

fn to_config_f64(c: &SegmentConfig) -> ConfigF64 {
    ConfigF64 {
        backbone_m: to_f64(c.backbone_q24.into(), 24),
        bend_rad: angle_q28_to_rad(c.bend_q28),
        direction_rad: angle_q28_to_rad(c.direction_q28),
    }
}

fn tip_distance_m(a: [i32; 3], b: [f64; 3]) -> f64 {
    let d: Vec<f64> = (0..3).map(|i| to_f64(a[i].into(), 24) - b[i]).collect();
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

#[test]
fn pcc_lengths_round_trip_exactly_as_the_closed_form_says() {
    let g = geometry(1, Mount::Upright);
    let model = Model::new(&g).unwrap();
    let mf = ModelF64::new(&g);
    for (s, th, ph) in [
        (0.12, 0.0, 0.0),
        (0.12, 0.3, 0.0),
        (0.1, 0.5, 2.0),
        (0.15, 0.8, -2.5),
    ] {
        let c = SegmentConfig {
            backbone_q24: from_f64(s, 24),
            bend_q28: angle_q28_from_rad(th),
            direction_q28: angle_q28_from_rad(ph),
        };
        let l = k::lengths_from_pcc(&model, &c);
        let lf = r::lengths_from_pcc(&mf, &to_config_f64(&c));
        for i in 0..3 {
            assert!((to_f64(l[i].into(), 24) - lf[i]).abs() < 1e-7);
        }
        // eq 3.26 theta against the dissertation's symmetric form.
        let l2: Vec<f64> = lf.to_vec();
        let q = l2[0] * l2[0] + l2[1] * l2[1] + l2[2] * l2[2]
            - l2[0] * l2[1]
            - l2[1] * l2[2]
            - l2[0] * l2[2];
        let theta_326 = 2.0 * q.max(0.0).sqrt() / (3.0 * mf.d_m);
        assert!((theta_326 - th).abs() < 1e-9, "{theta_326} vs {th}");
        let back = k::pcc_from_lengths(&model, l);
        assert!((angle_q28_to_rad(back.bend_q28) - th).abs() < 2e-6);
        if th > 0.0 {
            let dphi = angle_q28_to_rad(back.direction_q28) - ph;
            assert!(dphi.sin().abs() < 1e-5 && dphi.cos() > 0.0);
        }
        assert!((to_f64(back.backbone_q24.into(), 24) - s).abs() < 1e-7);
    }
}

#[test]
fn straight_segment_tip_is_on_the_axis_and_bent_tip_matches_arc_geometry() {
    let c = SegmentConfig {
        backbone_q24: from_f64(0.2, 24),
        bend_q28: 0,
        direction_q28: 0,
    };
    let p = k::tip_pose(&[c]);
    assert_eq!(p.p_q24[0], 0);
    assert!((to_f64(p.p_q24[2].into(), 24) - 0.2).abs() < 1e-7);
    // Quarter circle of radius R: tip at (R, 0, R), tip axis along +x.
    let radius = 0.1;
    let c = SegmentConfig {
        backbone_q24: from_f64(radius * core::f64::consts::FRAC_PI_2, 24),
        bend_q28: angle_q28_from_rad(core::f64::consts::FRAC_PI_2),
        direction_q28: 0,
    };
    let p = k::tip_pose(&[c]);
    assert!((to_f64(p.p_q24[0].into(), 24) - radius).abs() < 1e-6);
    assert!((to_f64(p.p_q24[2].into(), 24) - radius).abs() < 1e-6);
    assert!((to_f64(p.r_q30[0][2].into(), 30) - 1.0).abs() < 1e-6);
}

#[test]
fn column_forces_balance_the_load() {
    let g = geometry(2, Mount::Hanging);
    let model = Model::new(&g).unwrap();
    let load = LoadFx::new(
        &Load {
            payload_kg: 0.25,
            force_z_n: 1.0,
            moment_x_newton_m: 0.03,
            moment_y_newton_m: -0.02,
        },
        &model,
    )
    .unwrap();
    for seg in 0..2 {
        let f = k::column_forces(&model, &load, seg).map(|x| to_f64(x.into(), 16));
        let d = 0.06;
        let sum: f64 = f.iter().sum();
        let w = to_f64(model.weight_q16[0].into(), 16) * (2 - seg) as f64;
        assert!((sum - (1.0 + 0.25 * k::GRAVITY + w)).abs() < 1e-4);
        let mx = d * (f[1] - f[2]) * 3f64.sqrt() / 2.0;
        let my = -d * (f[0] - 0.5 * f[1] - 0.5 * f[2]);
        assert!(
            (mx - 0.03).abs() < 1e-5 && (my + 0.02).abs() < 1e-5,
            "{mx} {my}"
        );
    }
}

fn arb_load() -> impl Strategy<Value = Load> {
    (0.0f32..0.5, -3.0f32..3.0, -0.05f32..0.05, -0.05f32..0.05).prop_map(|(m, f, x, y)| Load {
        payload_kg: m,
        force_z_n: f,
        moment_x_newton_m: x,
        moment_y_newton_m: y,
    })
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 400,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x6b69_6e65),
        ..ProptestConfig::default()
    })]

    /// Fixed point and f64 agree within 0.05 mm at the tip over the
    /// pressure workspace (linear-spring OCM maps, exact in both).
    #[test]
    fn forward_tip_fixed_matches_f64(
        segments in 1u32..=3,
        p in proptest::array::uniform9(-20_000.0f64..35_000.0),
        load in arb_load(),
        hanging in any::<bool>(),
    ) {
        let g = geometry(segments, if hanging { Mount::Hanging } else { Mount::Upright });
        let maps = LinearOcm::SOFT;
        let model = Model::new(&g).unwrap();
        let mf = ModelF64::new(&g);
        let lfx = LoadFx::new(&load, &model).unwrap();
        let lf = LoadF64::new(&load, &mf);
        let pq: Vec<i32> = p.iter().map(|&x| from_f64(x, 8)).collect();
        let pf: Vec<f64> = pq.iter().map(|&x| to_f64(x.into(), 8)).collect();
        let cfx = k::forward(&maps, &model, &lfx, &pq).unwrap();
        let mut cf = [ConfigF64::default(); MAX_SEGMENTS];
        let n = r::forward(&maps, &mf, &lf, &pf, &mut cf).unwrap();
        let tip = k::tip_pose(&cfx);
        let tip_f = r::tip_pose(&cf[..n]);
        let err = tip_distance_m(tip.p_q24, tip_f.p);
        prop_assert!(err < 0.05e-3, "tip error {} m", err);
    }

    /// The inverse map (3.36) reproduces the pressures the forward map (3.35)
    /// was run with, in both arithmetics.
    #[test]
    fn inverse_recovers_forward_pressures(
        segments in 1u32..=3,
        p in proptest::array::uniform9(-15_000.0f64..30_000.0),
        load in arb_load(),
    ) {
        let g = geometry(segments, Mount::Upright);
        let maps = LinearOcm::SOFT;
        let model = Model::new(&g).unwrap();
        let lfx = LoadFx::new(&load, &model).unwrap();
        let pq: Vec<i32> = p.iter().map(|&x| from_f64(x, 8)).collect();
        let cfx = k::forward(&maps, &model, &lfx, &pq).unwrap();
        let lo = from_f64(-20_000.0, 8);
        let hi = from_f64(35_000.0, 8);
        let sol = k::inverse(&maps, &model, &lfx, &cfx, lo, hi).unwrap();
        for (a, b) in sol.pressures_q8.iter().zip(&pq) {
            // 5 Pa: strain quantisation (1.5e-5) times the map's 0.7 Pa^-1 * 1e5.
            prop_assert!((to_f64((a - b).into(), 8)).abs() < 5.0, "{} vs {}", a, b);
        }
        let mf = ModelF64::new(&g);
        let lf = LoadF64::new(&load, &mf);
        let target: Vec<ConfigF64> = cfx.iter().map(to_config_f64).collect();
        let mut out = [0.0; 9];
        r::inverse(&maps, &mf, &lf, &target, -20_000.0, 35_000.0, &mut out).unwrap();
        for (a, b) in out.iter().zip(&pq).take(3 * segments as usize) {
            prop_assert!((a - to_f64((*b).into(), 8)).abs() < 5.0, "f64 {:?} vs {:?} targets {:?}", out, pq, target);
        }
    }

    /// Tip-position targets are met by the configurations chosen for them.
    #[test]
    fn tip_targets_are_reached(
        segments in 1u32..=3,
        x in -0.08f64..0.08, y in -0.08f64..0.08, z in 0.08f64..0.3,
    ) {
        let g = geometry(segments, Mount::Upright);
        let model = Model::new(&g).unwrap();
        let p = [from_f64(x, 24), from_f64(y, 24), from_f64(z, 24)];
        let cs = k::configs_for_tip(&model, p).unwrap();
        let tip = k::tip_pose(&cs);
        let err = tip_distance_m(tip.p_q24, [x, y, z]);
        prop_assert!(err < 1e-6, "tip error {} m", err);
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 200,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x7469_7070),
        ..ProptestConfig::default()
    })]

    /// The rotation-free tip position equals the translation of the full pose.
    #[test]
    fn tip_position_matches_tip_pose(
        cfg in proptest::collection::vec((0.05f64..0.3, -1.2f64..1.2, -3.1f64..3.1), 1..=3),
    ) {
        let cs: Vec<SegmentConfig> = cfg
            .iter()
            .map(|&(s, t, p)| SegmentConfig {
                backbone_q24: from_f64(s, 24),
                bend_q28: angle_q28_from_rad(t),
                direction_q28: angle_q28_from_rad(p),
            })
            .collect();
        let full = k::tip_pose(&cs).p_q24;
        let fast = k::tip_position(&cs);
        for i in 0..3 {
            prop_assert!((full[i] - fast[i]).abs() <= 2, "{:?} vs {:?}", full, fast);
        }
    }
}

/// Counts the bending queries that reach the maps.
struct Counting {
    inner: LinearOcm,
    bends: std::cell::Cell<u32>,
}

impl OcmMaps for Counting {
    fn strain(&self, force_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.inner.strain(force_q16, pressure_q8)
    }
    fn force(&self, strain_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.inner.force(strain_q16, pressure_q8)
    }
    fn bend(&self, moment_q24: i32, s_q24: i32, pressure_q8: i32) -> Option<i32> {
        self.bends.set(self.bends.get() + 1);
        self.inner.bend(moment_q24, s_q24, pressure_q8)
    }
}

/// After `prime_bending`, the hinted inverse finds every bending query
/// in the memo, and the memo changes none of its results.
#[test]
fn primed_memo_answers_every_bending_query_of_the_inverse() {
    let maps = Counting {
        inner: LinearOcm::SOFT,
        bends: std::cell::Cell::new(0),
    };
    let model = Model::convert(&ocm_firmware::app::DEFAULT_GEOMETRY);
    let load = k::PreparedLoad::new(&LoadFx {
        fz_q16: -65_536,
        mx_q24: 1 << 20,
        my_q24: -(1 << 19),
    });
    let target = [SegmentConfig {
        backbone_q24: 2_100_000,
        bend_q28: 80_000_000,
        direction_q28: 100_000_000,
    }];
    let limits = (0, 35_000 << 8);
    let hint = [12_345 << 8];
    let plain = k::inverse_prepared(&maps, &model, &load, &target, limits, Some(&hint));
    assert!(plain.is_some());
    let cache = std::cell::Cell::new([None; 3]);
    let memo = ocm_firmware::maps::MemoBend::new(&maps, &cache);
    let unprimed = maps.bends.get();
    k::prime_bending(&memo, &model, &load, &target, &hint);
    let primed = maps.bends.get();
    assert_eq!(primed, unprimed + 1, "priming made no bending query");
    let memoized = k::inverse_prepared(&memo, &model, &load, &target, limits, Some(&hint));
    assert_eq!(maps.bends.get(), primed, "the tick missed the primed memo");
    assert_eq!(memoized, plain);
    // Without a moment, neither priming nor the inverse query the map.
    let calm = k::PreparedLoad::new(&LoadFx::default());
    let before = maps.bends.get();
    k::prime_bending(&memo, &model, &calm, &target, &hint);
    let _ = k::inverse_prepared(&memo, &model, &calm, &target, limits, Some(&hint));
    assert_eq!(maps.bends.get(), before);
}
