//! Encode -> parse -> lookups against the closed-form synthetic OCM.

mod common;

use common::{Grids, Rng, Tables, force_n, moment_nm, phi_max_rad, solve_increasing};
use fixed::types::{I8F24, I16F16, I24F8};
use ocm_shared::lut::{
    Clamp, LookupError, LutImage, MomentNm, PRESSURE_MARGIN_PA, Quantity, defaults, encoded_len,
};
use ocm_shared::params::OcmParams;

const LSB16: f64 = 1.0 / 65_536.0;
const LSB24: f64 = 1.0 / 16_777_216.0;

fn default_image() -> Vec<u8> {
    Tables::sample(Grids::DEFAULT).encode(OcmParams::TABLE_3_1.hash())
}

#[test]
fn default_image_fits_the_budget_and_carries_hash_and_crc() {
    let tables = Tables::sample(Grids::DEFAULT);
    assert_eq!(tables.grids.eps.2, defaults::N_EPS);
    assert_eq!(tables.grids.p_pa.2, defaults::N_P);
    assert_eq!(tables.grids.s_m.2, defaults::N_S);
    let len = encoded_len(&tables.axial(), &tables.bending());
    // Header 112 + 4 bytes x (16 x 129 + 17 + 2 x 17 x 129) + CRC 4.
    assert_eq!(len, 112 + 4 * (16 * 129 + 17 + 2 * 17 * 129) + 4);
    assert_eq!(len, defaults::IMAGE_LEN);
    assert!(
        len <= ocm_shared::lut::LUT_CAPACITY,
        "default image is {len} bytes"
    );

    let bytes = tables.encode(OcmParams::TABLE_3_1.hash());
    let lut = LutImage::parse(&bytes).expect("valid image");
    assert_eq!(lut.size_bytes(), len);
    assert_eq!(lut.param_hash(), OcmParams::TABLE_3_1.hash());
    let trailer = u32::from_le_bytes(bytes[len - 4..].try_into().unwrap());
    assert_eq!(lut.crc(), trailer);
    // An independent CRC-32 (bitwise, reflected polynomial 0xEDB88320).
    let mut crc = 0xFFFF_FFFFu32;
    for &b in &bytes[..len - 4] {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    assert_eq!(!crc, trailer);

    let axial = lut.axial_grid();
    assert_eq!(axial.n_eps, 129);
    assert_eq!(axial.n_p, 16);
    assert_eq!(axial.pressure_at(1), Some(I24F8::from_num(2000)));
    assert_eq!(axial.pressure_at(16), None);
    let (lo, hi) = axial.pressure_window();
    assert_eq!(lo, I24F8::from_num(-PRESSURE_MARGIN_PA));
    assert_eq!(hi, I24F8::from_num(30_000 + PRESSURE_MARGIN_PA));
    let bending = lut.bending_grid();
    assert_eq!((bending.n_s, bending.n_u), (17, 129));
}

#[test]
fn image_with_padding_parses_to_the_declared_length() {
    let mut bytes = default_image();
    let len = bytes.len();
    bytes.extend(std::iter::repeat_n(0xFF, 300));
    let lut = LutImage::parse(&bytes).expect("padded image");
    assert_eq!(lut.size_bytes(), len);
    assert_eq!(lut.as_bytes().len(), len);
}

#[test]
fn stored_values_match_the_model_within_half_an_lsb() {
    let tables = Tables::sample(Grids::DEFAULT);
    let bytes = tables.encode(7);
    let lut = LutImage::parse(&bytes).unwrap();
    let a = lut.axial_grid();
    for j in 0..a.n_p {
        for i in 0..a.n_eps {
            let stored: f64 = lut.axial_force_at(j, i).unwrap().to_num();
            let model = tables.force_n[usize::from(j) * 129 + usize::from(i)];
            assert!((stored - model).abs() <= 0.5 * LSB16, "F[{j}][{i}]");
        }
    }
    let b = lut.bending_grid();
    // The slopes are below 1e-6 N*m/Pa, so the writer must pick a binary point
    // that leaves them at least 2^30 counts of headroom.
    assert!(b.m1_frac_bits >= 50, "m1_frac_bits {}", b.m1_frac_bits);
    for k in 0..b.n_s {
        let top: f64 = lut.phi_max_at(k).unwrap().to_num();
        assert!((top - tables.phi_max_rad[usize::from(k)]).abs() <= 0.5 * LSB16);
        for i in 0..b.n_u {
            let at = usize::from(k) * 129 + usize::from(i);
            let m0: f64 = lut.moment_at_zero_pressure_at(k, i).unwrap().to_num();
            assert!((m0 - tables.m0_nm[at]).abs() <= 0.5 * LSB24);
            let m1 = lut.moment_per_pascal_f64_at(k, i).unwrap();
            let lsb = (-f64::from(b.m1_frac_bits)).exp2();
            assert!((m1 - tables.m1_nm_per_pa[at]).abs() <= 0.5 * lsb);
        }
    }
}

#[test]
fn lookups_at_exact_grid_points_return_the_stored_bits() {
    let tables = Tables::sample(Grids::EXACT);
    let bytes = tables.encode(1);
    let lut = LutImage::parse(&bytes).unwrap();
    let a = lut.axial_grid();
    for j in 0..a.n_p {
        let p = a.pressure_at(j).unwrap();
        for i in 0..a.n_eps {
            let eps = a.strain_at(i).unwrap();
            let f = lut.axial_force(eps, p).unwrap();
            assert_eq!(f.clamp, Clamp::Inside);
            assert_eq!(
                f.value,
                lut.axial_force_at(j, i).unwrap(),
                "F at ({j}, {i})"
            );
        }
    }
    let b = lut.bending_grid();
    for k in 0..b.n_s {
        let s = b.length_at(k).unwrap();
        let top = lut.phi_max_at(k).unwrap();
        for i in 0..b.n_u {
            let phi = top / 128 * I16F16::from_num(i);
            let m = lut.bending_moment(phi, s, I24F8::ZERO).unwrap();
            assert_eq!(
                m.value,
                lut.moment_at_zero_pressure_at(k, i).unwrap(),
                "M at ({k}, {i})"
            );
            // At 10 kPa the lookup adds P * M1 of the stored slope.
            let p = 10_000.0;
            let m = lut.bending_moment(phi, s, I24F8::from_num(p)).unwrap();
            let expected = lut
                .moment_at_zero_pressure_at(k, i)
                .unwrap()
                .to_num::<f64>()
                + p * lut.moment_per_pascal_f64_at(k, i).unwrap();
            assert!((m.value.to_num::<f64>() - expected).abs() <= LSB24);
        }
    }
}

#[test]
fn inverse_of_forward_returns_the_input() {
    let tables = Tables::sample(Grids::DEFAULT);
    let bytes = tables.encode(2);
    let lut = LutImage::parse(&bytes).unwrap();
    let mut rng = Rng::new(11);
    for _ in 0..2000 {
        let eps = I16F16::from_num(rng.uniform(-0.6, 0.6));
        let p = I24F8::from_num(rng.uniform(-20_000.0, 35_000.0));
        let f = lut.axial_force(eps, p).unwrap();
        let back = lut.axial_strain(f.value, p).unwrap();
        assert_eq!(back.clamp, Clamp::Inside);
        let err = (back.value - eps).abs();
        assert!(
            err <= I16F16::from_bits(3),
            "eps {eps} p {p}: back {}",
            back.value
        );
    }
    let b = lut.bending_grid();
    for _ in 0..2000 {
        let k = (rng.uniform(0.0, 17.0) as u16).min(16);
        let s = b.length_at(k).unwrap();
        let top: f64 = lut.phi_max_at(k).unwrap().to_num();
        let phi = I16F16::from_num(rng.uniform(-top, top));
        let p = I24F8::from_num(rng.uniform(-20_000.0, 35_000.0));
        let m = lut.bending_moment(phi, s, p).unwrap();
        let back = lut.bending_angle(m.value, s, p).unwrap();
        assert_eq!(back.clamp, Clamp::Inside);
        let err = (back.value - phi).abs();
        assert!(
            err <= I16F16::from_bits(3),
            "phi {phi} s {s} p {p}: back {}",
            back.value
        );
    }
    // Between length levels the forward map interpolates M at fixed phi and
    // the inverse phi at fixed M, so the round trip is close, not exact: each
    // direction may miss the model by up to 0.1% of full scale (0.9 rad).
    let mut worst: f64 = 0.0;
    for _ in 0..2000 {
        let s_m = rng.uniform(0.02, 0.06);
        let phi_rad = rng.uniform(0.0, 0.98 * phi_max_rad(s_m));
        let p_pa = rng.uniform(0.0, 30_000.0);
        let m = lut.bending_moment_f64(phi_rad, s_m, p_pa).unwrap();
        let back = lut.bending_angle_f64(m.value, s_m, p_pa).unwrap();
        worst = worst.max((back.value - phi_rad).abs());
    }
    assert!(
        worst < 0.002 * 0.9,
        "worst round trip between levels {worst} rad"
    );
}

/// Mean and maximum absolute error of `n` samples.
fn stats(errors: &[f64]) -> (f64, f64) {
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let max = errors.iter().fold(0.0f64, |a, &b| a.max(b));
    (mean, max)
}

#[test]
fn inverse_lookups_off_grid_meet_the_accuracy_goal() {
    let bytes = default_image();
    let lut = LutImage::parse(&bytes).unwrap();
    let mut rng = Rng::new(2026);

    // Axial: full scale is the strain range, 1.2.
    let fs_eps = 1.2;
    let mut errors = Vec::new();
    for _ in 0..5000 {
        let eps = rng.uniform(-0.6, 0.6);
        let p_pa = rng.uniform(0.0, 30_000.0);
        let found = lut.axial_strain_f64(force_n(eps, p_pa), p_pa).unwrap();
        errors.push((found.value - eps).abs() / fs_eps);
    }
    let (mean, max) = stats(&errors);
    eprintln!(
        "axial inverse: mean {:.5}% FS, max {:.5}% FS",
        100.0 * mean,
        100.0 * max
    );
    assert!(mean <= 0.001 && max <= 0.005, "axial mean {mean} max {max}");

    // Same through extrapolated pressures of the firmware's window.
    errors.clear();
    for _ in 0..2000 {
        let eps = rng.uniform(-0.6, 0.6);
        let p_pa = if rng.uniform(0.0, 1.0) < 0.5 {
            rng.uniform(-20_000.0, 0.0)
        } else {
            rng.uniform(30_000.0, 35_000.0)
        };
        let found = lut.axial_strain_f64(force_n(eps, p_pa), p_pa).unwrap();
        errors.push((found.value - eps).abs() / fs_eps);
    }
    let (mean, max) = stats(&errors);
    eprintln!(
        "axial inverse, extrapolated P: mean {:.5}% FS, max {:.5}% FS",
        100.0 * mean,
        100.0 * max
    );
    assert!(
        mean <= 0.001 && max <= 0.005,
        "extrapolated axial mean {mean} max {max}"
    );

    // Bending: full scale is the largest phi_max, 0.9 rad; the exact inverse
    // solves the model at the off-grid length itself.
    let fs_phi = phi_max_rad(0.06);
    errors.clear();
    for _ in 0..5000 {
        let s_m = rng.uniform(0.02, 0.06);
        let top = phi_max_rad(s_m);
        let phi = rng.uniform(-0.98 * top, 0.98 * top);
        let p_pa = rng.uniform(0.0, 30_000.0);
        let moment = moment_nm(phi, s_m, p_pa);
        let found = lut.bending_angle_f64(moment, s_m, p_pa).unwrap();
        let exact = solve_increasing(|x| moment_nm(x, s_m, p_pa), moment, -top, top);
        assert!((exact - phi).abs() < 1e-9);
        errors.push((found.value - phi).abs() / fs_phi);
    }
    let (mean, max) = stats(&errors);
    eprintln!(
        "bending inverse: mean {:.5}% FS, max {:.5}% FS",
        100.0 * mean,
        100.0 * max
    );
    assert!(
        mean <= 0.001 && max <= 0.005,
        "bending mean {mean} max {max}"
    );
}

#[test]
fn forces_beyond_the_row_saturate_and_say_so() {
    let bytes = default_image();
    let lut = LutImage::parse(&bytes).unwrap();
    let a = lut.axial_grid();
    let p = 10_000.0;
    let top = force_n(0.6, p);
    let bottom = force_n(-0.6, p);
    let r = lut.axial_strain_f64(top + 1.0, p).unwrap();
    assert_eq!(r.clamp, Clamp::AboveRange);
    assert!(r.is_saturated());
    assert_eq!(r.value, a.eps_max.to_num::<f64>());
    let r = lut.axial_strain_f64(bottom - 1.0, p).unwrap();
    assert_eq!(r.clamp, Clamp::BelowRange);
    assert_eq!(r.value, a.eps_min.to_num::<f64>());
    let r = lut.axial_strain(I16F16::MAX, I24F8::ZERO).unwrap();
    assert_eq!((r.value, r.clamp), (a.eps_max, Clamp::AboveRange));
    let r = lut.axial_strain(I16F16::MIN, I24F8::ZERO).unwrap();
    assert_eq!((r.value, r.clamp), (a.eps_min, Clamp::BelowRange));

    // Forward: strains beyond the grid are held to its ends.
    let r = lut.axial_force_f64(0.9, p).unwrap();
    assert_eq!(r.clamp, Clamp::AboveRange);
    assert!((r.value - top).abs() < 1e-3);
    let r = lut.axial_force_f64(-0.9, p).unwrap();
    assert_eq!(r.clamp, Clamp::BelowRange);

    // Bending: beyond M(phi_max) the angle is phi_max, mirrored for -M.
    let s = lut.bending_grid().length_at(4).unwrap();
    let top_phi = lut.phi_max_at(4).unwrap();
    let r = lut
        .bending_angle(MomentNm::from_num(5), s, I24F8::ZERO)
        .unwrap();
    assert_eq!((r.value, r.clamp), (top_phi, Clamp::AboveRange));
    let r = lut
        .bending_angle(MomentNm::from_num(-5), s, I24F8::ZERO)
        .unwrap();
    assert_eq!((r.value, r.clamp), (-top_phi, Clamp::BelowRange));
    let r = lut.bending_angle(MomentNm::MIN, s, I24F8::ZERO).unwrap();
    assert_eq!((r.value, r.clamp), (-top_phi, Clamp::BelowRange));
    let r = lut
        .bending_moment(I16F16::from_num(3), s, I24F8::ZERO)
        .unwrap();
    assert_eq!(r.clamp, Clamp::AboveRange);
    assert_eq!(r.value, lut.moment_at_zero_pressure_at(4, 128).unwrap());
}

#[test]
fn bending_is_odd_in_angle_and_moment() {
    let bytes = default_image();
    let lut = LutImage::parse(&bytes).unwrap();
    let mut rng = Rng::new(5);
    for _ in 0..500 {
        let s = I8F24::from_num(rng.uniform(0.02, 0.06));
        let p = I24F8::from_num(rng.uniform(-20_000.0, 50_000.0));
        let phi = I16F16::from_num(rng.uniform(0.0, 1.0));
        let plus = lut.bending_moment(phi, s, p).unwrap();
        let minus = lut.bending_moment(-phi, s, p).unwrap();
        assert_eq!(minus.value, -plus.value);
        let m = I8F24::from_num(rng.uniform(0.0, 0.2));
        let plus = lut.bending_angle(m, s, p).unwrap();
        let minus = lut.bending_angle(-m, s, p).unwrap();
        assert_eq!(minus.value, -plus.value);
    }
    let zero = lut
        .bending_angle(I8F24::ZERO, I8F24::from_num(0.03), I24F8::ZERO)
        .unwrap();
    assert_eq!((zero.value, zero.clamp), (I16F16::ZERO, Clamp::Inside));
}

#[test]
fn inverses_are_monotone_in_their_target() {
    let bytes = default_image();
    let lut = LutImage::parse(&bytes).unwrap();
    let p = I24F8::from_num(17_321);
    let mut previous = I16F16::MIN;
    for raw in (-40i32..=40).map(|n| n * 65_536 / 2) {
        let eps = lut.axial_strain(I16F16::from_bits(raw), p).unwrap().value;
        assert!(eps >= previous);
        previous = eps;
    }
    let s = I8F24::from_num(0.047);
    let mut previous = I16F16::MIN;
    for n in -300..=300 {
        let m = I8F24::from_num(f64::from(n) * 0.001);
        let phi = lut.bending_angle(m, s, p).unwrap().value;
        assert!(phi >= previous);
        previous = phi;
    }
}

#[test]
fn inputs_outside_the_tables_are_errors_naming_them() {
    let bytes = default_image();
    let lut = LutImage::parse(&bytes).unwrap();
    // Pressure window -20..50 kPa: edges answer, beyond is an error.
    assert!(lut.axial_strain_f64(1.0, -20_000.0).is_ok());
    assert!(lut.axial_strain_f64(1.0, 50_000.0).is_ok());
    match lut.axial_strain_f64(1.0, 50_001.0) {
        Err(LookupError::PressureOutOfRange { pressure, min, max }) => {
            assert_eq!(pressure, I24F8::from_num(50_001));
            assert_eq!(
                (min, max),
                (I24F8::from_num(-20_000), I24F8::from_num(50_000))
            );
        }
        other => panic!("expected PressureOutOfRange, got {other:?}"),
    }
    assert!(matches!(
        lut.bending_angle_f64(0.01, 0.03, -20_001.0),
        Err(LookupError::PressureOutOfRange { .. })
    ));
    assert!(matches!(
        lut.bending_moment_f64(0.1, 0.061, 0.0),
        Err(LookupError::LengthOutOfRange { .. })
    ));
    assert!(matches!(
        lut.bending_angle_f64(0.01, 0.019, 0.0),
        Err(LookupError::LengthOutOfRange { .. })
    ));
    assert!(matches!(
        lut.axial_strain_f64(f64::NAN, 0.0),
        Err(LookupError::NotRepresentable {
            quantity: Quantity::Force,
            ..
        })
    ));
    assert!(matches!(
        lut.axial_force_f64(0.0, f64::INFINITY),
        Err(LookupError::NotRepresentable {
            quantity: Quantity::Pressure,
            ..
        })
    ));
    assert!(matches!(
        lut.bending_angle_f64(200.0, 0.03, 0.0),
        Err(LookupError::NotRepresentable {
            quantity: Quantity::Moment,
            ..
        })
    ));
    assert!(matches!(
        lut.bending_moment_f64(0.1, 1e9, 0.0),
        Err(LookupError::NotRepresentable {
            quantity: Quantity::Length,
            ..
        })
    ));
}

#[test]
fn hinted_bending_inverse_agrees_with_the_bisection() {
    use ocm_shared::lut::BendHint;
    let bytes = default_image();
    let lut = LutImage::parse(&bytes).unwrap();
    let mut rng = Rng::new(11);
    let mut hint = BendHint::NONE;
    let mut reused = 0;
    for _ in 0..2_000 {
        // Stored pressures: the rows increase there, so the hinted search
        // must give the bisection's answer bit for bit.
        let s = I8F24::from_num(rng.uniform(0.02, 0.06));
        let p = I24F8::from_num(rng.uniform(0.0, 30_000.0));
        let m = I8F24::from_num(rng.uniform(-0.2, 0.2));
        let plain = lut.bending_angle(m, s, p).unwrap();
        let (near, next) = lut.bending_angle_near(m, s, p, hint).unwrap();
        assert_eq!(near, plain, "M {m} s {s} P {p}");
        // A nearby query (as a control loop makes) starting from this one.
        let p2 = p + I24F8::from_num(rng.uniform(-500.0, 500.0));
        let (again, _) = lut.bending_angle_near(m, s, p2, next).unwrap();
        assert_eq!(again, lut.bending_angle(m, s, p2).unwrap());
        reused += usize::from(next == hint);
        hint = next;
    }
    // Random queries rarely share cells: the test covers both paths.
    assert!(reused < 2_000);
}
