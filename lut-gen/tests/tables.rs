//! Tables and LUT images: accuracy of the fixed-point inverses against the
//! f64 model, round trips, and rejection of corrupt images.

use ocm_lutgen::tables::{TableConfig, build_tables, check_accuracy};
use ocm_lutgen::{OcmModel, OcmParams};
use ocm_shared::lut::{LUT_CAPACITY, LutError, LutImage};
use ocm_shared::params::ParamPreset;

fn default_image() -> (OcmModel, Vec<u8>) {
    // The image users flash: the default parameter preset and the default table grid.
    let model = OcmModel::new(ParamPreset::default().ocm()).unwrap();
    let tables = build_tables(&model, &TableConfig::default(), &|_, _| {}).unwrap();
    assert_eq!(
        tables.raised_samples, 0,
        "the default design has monotone rows"
    );
    let bytes = tables.encode(&model).unwrap();
    (model, bytes)
}

#[test]
fn default_image_meets_budget_and_accuracy() {
    let (model, bytes) = default_image();
    assert!(
        bytes.len() <= LUT_CAPACITY,
        "image is {} bytes, the boards hold {LUT_CAPACITY}",
        bytes.len()
    );
    let acc = check_accuracy(&model, &bytes, 2000).unwrap();
    assert!(acc.crc_ok);
    // The spec's goals (0.1 % FS mean, 0.5 % FS max)...
    assert!(acc.axial_err_mean_pct_fs <= 0.1, "{acc:?}");
    assert!(acc.axial_err_max_pct_fs <= 0.5, "{acc:?}");
    assert!(acc.bending_err_mean_pct_fs <= 0.1, "{acc:?}");
    assert!(acc.bending_err_max_pct_fs <= 0.5, "{acc:?}");
    // ...and regression bounds at about 3x what the image measures today (README: axial
    // 0.0004 / 0.0013 % FS, bending 0.014 / 0.051 % FS), so a loss of accuracy shows.
    assert!(acc.axial_err_mean_pct_fs <= 0.0015, "{acc:?}");
    assert!(acc.axial_err_max_pct_fs <= 0.005, "{acc:?}");
    assert!(acc.bending_err_mean_pct_fs <= 0.045, "{acc:?}");
    assert!(acc.bending_err_max_pct_fs <= 0.15, "{acc:?}");
}

#[test]
fn coarse_tables_are_measurably_worse() {
    // The accuracy check must be able to fail: a 9-point strain grid
    // and 3 length levels cannot meet the goals.
    let model = OcmModel::new(OcmParams::TABLE_3_1).unwrap();
    let cfg = TableConfig {
        n_eps: 5,
        n_s: 2,
        n_u: 5,
        ..TableConfig::default()
    };
    let bytes = build_tables(&model, &cfg, &|_, _| {})
        .unwrap()
        .encode(&model)
        .unwrap();
    let acc = check_accuracy(&model, &bytes, 500).unwrap();
    assert!(
        acc.axial_err_max_pct_fs > 0.5 || acc.bending_err_max_pct_fs > 0.5,
        "{acc:?}"
    );
}

#[test]
fn image_round_trips_the_sampled_forward_values() {
    let model = OcmModel::new(OcmParams::TABLE_3_1).unwrap();
    let cfg = TableConfig::default();
    let tables = build_tables(&model, &cfg, &|_, _| {}).unwrap();
    let bytes = tables.encode(&model).unwrap();
    let image = LutImage::parse(&bytes).unwrap();
    assert_eq!(image.param_hash(), model.params().hash());
    for j in (0..cfg.n_p).step_by(5) {
        for i in (0..cfg.n_eps).step_by(16) {
            let eps = cfg.strain(i);
            let p = cfg.pressure_pa(j);
            let stored = image.axial_force_f64(eps, p).unwrap().value;
            let exact = model.axial_force_n(eps, p);
            assert!(
                (stored - exact).abs() < 1e-4,
                "F({eps},{p}) {stored} vs {exact}"
            );
            // And the inverse of a stored value returns the grid strain.
            let back = image.axial_strain_f64(exact, p).unwrap().value;
            assert!((back - eps).abs() < 1e-4, "{back} vs {eps}");
        }
    }
    for k in (0..cfg.n_s).step_by(4) {
        let s = cfg.length_m(&model, k);
        let eps0 = model.strain_of_arc_length(s);
        let phi = 0.5 * model.max_bend_angle_rad(eps0);
        for p in [0.0, 30e3] {
            let stored = image.bending_moment_f64(phi, s, p).unwrap().value;
            let exact = model.bending_moment_nm(phi, eps0, p);
            assert!(
                (stored - exact).abs() < 1e-3 * exact.abs() + 1e-6,
                "{stored} vs {exact}"
            );
        }
    }
}

#[test]
fn corrupt_images_are_rejected_each_with_its_own_error() {
    let (_, bytes) = default_image();
    let mut bad = bytes.clone();
    bad[0] ^= 0xff;
    assert!(matches!(
        LutImage::parse(&bad),
        Err(LutError::BadMagic { .. })
    ));
    let mut bad = bytes.clone();
    bad[8] = bad[8].wrapping_add(1);
    assert!(matches!(
        LutImage::parse(&bad),
        Err(LutError::UnsupportedVersion { .. })
    ));
    for cut in [0, 7, 40, bytes.len() / 2, bytes.len() - 1] {
        assert!(
            matches!(
                LutImage::parse(&bytes[..cut]),
                Err(LutError::Truncated { .. })
            ),
            "cut at {cut}"
        );
    }
    let mut bad = bytes.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 0x10;
    assert!(matches!(
        LutImage::parse(&bad),
        Err(LutError::CrcMismatch { .. })
    ));
}

#[test]
fn invalid_grids_are_named() {
    let model = OcmModel::new(OcmParams::TABLE_3_1).unwrap();
    for cfg in [
        TableConfig {
            n_eps: 1,
            ..TableConfig::default()
        },
        TableConfig {
            eps_max: 3.0,
            ..TableConfig::default()
        },
        TableConfig {
            p_min_kpa: f64::NAN,
            ..TableConfig::default()
        },
        TableConfig {
            eps0_min: 0.7,
            ..TableConfig::default()
        },
    ] {
        let err = build_tables(&model, &cfg, &|_, _| {}).unwrap_err();
        assert!(err.to_string().starts_with("table grid"), "{err}");
    }
}

#[test]
fn image_for_other_parameters_is_refused_by_the_check() {
    let (_, bytes) = default_image();
    let other = OcmModel::new(OcmParams {
        hinge_stiffness_n_per_m: 0.2,
        ..OcmParams::TABLE_3_1
    })
    .unwrap();
    let err = check_accuracy(&other, &bytes, 10).unwrap_err();
    assert!(err.to_string().contains("parameter hash"), "{err}");
}
