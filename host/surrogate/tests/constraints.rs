//! Grouped constraints (eq 4.23-4.24): no commanded, projected or optimised posture violates them.

use nalgebra::Vector3;
mod common;
use common::chain;
use ocm_surrogate::chain::{GROUPS, N_JOINTS, Posture};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::mapping::{MatchConfig, match_tcp};
use proptest::prelude::*;

fn posture() -> impl Strategy<Value = Posture> {
    proptest::array::uniform11(-0.5f64..0.5)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn projected_commands_are_feasible_and_feasible_ones_unchanged(q in posture()) {
        let lim = Limits::default();
        let p = lim.project(&q).unwrap();
        prop_assert!(lim.check(&p).is_ok(), "{:?}", lim.check(&p));
        prop_assert_eq!(lim.project(&p).unwrap(), p);
    }

    #[test]
    fn increments_cover_exactly_the_feasible_set(z in posture()) {
        let lim = Limits::default();
        let q = lim.from_increments(&z);
        prop_assert!(lim.check(&q).is_ok());
        let back = lim.from_increments(&lim.to_increments(&q));
        for j in 0..N_JOINTS {
            prop_assert!((back[j] - q[j]).abs() < 1e-15);
        }
    }

    #[test]
    fn optimised_postures_are_feasible(
        x in -0.08f64..0.08, y in -0.08f64..0.08, z in 0.14f64..0.24, init in posture()
    ) {
        let (g, lim) = (chain(), Limits::default());
        let m = match_tcp(&g, &lim, &Vector3::new(x, y, z), &init, &MatchConfig::default()).unwrap();
        prop_assert!(lim.check(&m.posture).is_ok(), "{:?}", lim.check(&m.posture));
        prop_assert!((g.tcp(&m.posture) - Vector3::new(x, y, z)).norm() - m.error_m < 1e-12);
    }
}

#[test]
fn reachable_targets_are_reached() {
    // Targets made by the chain itself from feasible postures: Algorithm 1 must find them.
    let (g, lim) = (chain(), Limits::default());
    for k in 0..20 {
        let t = k as f64 / 20.0;
        let z: Posture = std::array::from_fn(|j| {
            let b = lim.increment_bounds()[j];
            b.0 + (b.1 - b.0) * (0.5 + 0.45 * (1.7 * t + j as f64).sin())
        });
        let target = g.tcp(&lim.from_increments(&z));
        let m = match_tcp(&g, &lim, &target, &[0.0; N_JOINTS], &MatchConfig::default()).unwrap();
        assert!(m.error_m < 1e-6, "target {k}: {} m", m.error_m);
    }
}

#[test]
fn clear_errors_for_bad_commands_and_limits() {
    let lim = Limits::default();
    let mut q = [0.0; N_JOINTS];
    q[2] = 0.03;
    let e = lim.check(&q).unwrap_err().to_string();
    assert!(e.contains("joint 2") && e.contains("outside"), "{e}");
    let mut q = [0.0; N_JOINTS];
    q[GROUPS[0][1]] = 0.05;
    let e = lim.check(&q).unwrap_err().to_string();
    assert!(e.contains("eq 4.23"), "{e}");
    q[0] = f64::INFINITY;
    assert!(
        lim.project(&q)
            .unwrap_err()
            .to_string()
            .contains("not finite")
    );
    let bad = Limits {
        delta_x_rad: -1.0,
        ..Limits::default()
    };
    assert!(bad.validate().is_err());
    let e = match_tcp(
        &chain(),
        &lim,
        &Vector3::new(f64::NAN, 0.0, 0.2),
        &[0.0; N_JOINTS],
        &MatchConfig::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("not finite"), "{e}");
}
