//! Parsing and every lookup are total: arbitrary bytes, arbitrary
//! CRC-valid headers and tables, and extreme inputs never panic, and the
//! answers stay inside the tables' ranges.

mod common;

use common::{Grids, Tables, fix_crc};
use fixed::types::{I8F24, I16F16, I24F8};
use ocm_shared::lut::{Clamp, LutImage, MAGIC};
use proptest::prelude::*;
use std::sync::OnceLock;

fn default_image() -> &'static [u8] {
    static IMAGE: OnceLock<Vec<u8>> = OnceLock::new();
    IMAGE.get_or_init(|| Tables::sample(Grids::DEFAULT).encode(3))
}

/// Runs every lookup with the given raw inputs and checks the answers lie in
/// the ranges the image describes.
fn exercise(lut: &LutImage, eps: i32, force: i32, p: i32, phi: i32, s: i32, m: i32) {
    let a = lut.axial_grid();
    let b = lut.bending_grid();
    let (eps, force, p) = (
        I16F16::from_bits(eps),
        I16F16::from_bits(force),
        I24F8::from_bits(p),
    );
    let (phi, s, m) = (
        I16F16::from_bits(phi),
        I8F24::from_bits(s),
        I8F24::from_bits(m),
    );
    let _ = lut.axial_force(eps, p);
    if let Ok(r) = lut.axial_strain(force, p) {
        assert!(
            r.value >= a.eps_min && r.value <= a.eps_max,
            "strain {} outside grid",
            r.value
        );
    }
    let _ = lut.bending_moment(phi, s, p);
    if let Ok(r) = lut.bending_angle(m, s, p) {
        let top = (0..b.n_s).filter_map(|k| lut.phi_max_at(k)).max().unwrap();
        assert!(
            r.value.abs() <= top,
            "angle {} beyond phi_max {top}",
            r.value
        );
        if r.clamp == Clamp::Inside {
            assert_eq!(r.value < 0, m < 0 && r.value != 0);
        }
    }
    for j in [0, a.n_p.saturating_sub(1), a.n_p, u16::MAX] {
        let _ = a.pressure_at(j);
        let _ = a.strain_at(j);
        let _ = lut.axial_force_at(j, j);
        let _ = b.length_at(j);
        let _ = b.u_at(j);
        let _ = lut.phi_max_at(j);
        let _ = lut.moment_at_zero_pressure_at(j, 0);
        let _ = lut.moment_per_pascal_f64_at(0, j);
    }
}

/// Edge values of `i32` mixed with arbitrary ones.
fn raw() -> impl Strategy<Value = i32> {
    prop_oneof![
        Just(i32::MIN),
        Just(i32::MAX),
        Just(0),
        Just(-1),
        Just(1),
        any::<i32>(),
        -(1i32 << 20)..(1i32 << 20),
    ]
}

/// Edge values of `f64` mixed with arbitrary ones.
fn real() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(f64::MAX),
        Just(f64::MIN_POSITIVE),
        Just(-0.0),
        any::<f64>(),
        -1.0e5..1.0e5f64,
        -1.0..1.0f64,
    ]
}

/// A grid point count: mostly valid, sometimes empty or too large.
fn points() -> impl Strategy<Value = u16> {
    prop_oneof![
        48 => 2u16..=6,
        1 => Just(0u16),
        1 => Just(1u16),
        1 => Just(4097u16),
        1 => any::<u16>(),
    ]
}

/// Grid bounds: mostly ordered, sometimes equal or swapped, any magnitude.
fn bounds() -> impl Strategy<Value = (i32, i32)> {
    prop_oneof![
        24 => (raw(), raw()).prop_map(|(a, b)| (a.min(b), a.max(b))),
        1 => (raw(), raw()),
        1 => raw().prop_map(|a| (a, a)),
    ]
}

/// A descriptor's binary point: mostly the allowed one, sometimes anything.
fn frac_bits(valid: impl Strategy<Value = u8> + 'static) -> BoxedStrategy<u8> {
    prop_oneof![24 => valid, 1 => any::<u8>()].boxed()
}

/// A header with random grids and descriptors, random tables after it, and a
/// valid CRC: the parser must judge every field, not just the checksum.
fn crc_valid_image() -> impl Strategy<Value = Vec<u8>> {
    (
        proptest::array::uniform4(points()),
        proptest::array::uniform3(bounds()),
        (
            frac_bits(Just(16)),
            frac_bits(Just(16)),
            frac_bits(Just(24)),
            frac_bits(16u8..=62),
        ),
        proptest::collection::vec(raw(), 1..200),
        prop_oneof![24 => Just(true), 1 => Just(false)],
        prop_oneof![24 => Just(true), 1 => Just(false)],
    )
        .prop_map(|(n, grid_bounds, frac, values, contiguous, positive_phi)| {
            let [n_eps, n_p, n_s, n_u] = n;
            let frac = [frac.0, frac.1, frac.2, frac.3];
            let counts = [
                u32::from(n_p) * u32::from(n_eps),
                u32::from(n_s),
                u32::from(n_s) * u32::from(n_u),
                u32::from(n_s) * u32::from(n_u),
            ];
            let mut body = vec![0u8; 112];
            body[..8].copy_from_slice(&MAGIC);
            body[8..10].copy_from_slice(&1u16.to_le_bytes());
            body[10..12].copy_from_slice(&112u16.to_le_bytes());
            for (i, (lo, hi)) in grid_bounds.iter().enumerate() {
                let at = [28, 40, 48][i];
                body[at..at + 4].copy_from_slice(&lo.to_le_bytes());
                body[at + 4..at + 8].copy_from_slice(&hi.to_le_bytes());
            }
            body[36..38].copy_from_slice(&n_eps.to_le_bytes());
            body[38..40].copy_from_slice(&n_p.to_le_bytes());
            body[56..58].copy_from_slice(&n_s.to_le_bytes());
            body[58..60].copy_from_slice(&n_u.to_le_bytes());
            let mut at = 112u32;
            let mut starts = [0usize; 4];
            for t in 0..4 {
                let d = 64 + 12 * t;
                let count = if contiguous { counts[t] } else { counts[t] / 2 };
                body[d..d + 4].copy_from_slice(&at.to_le_bytes());
                body[d + 4..d + 8].copy_from_slice(&count.to_le_bytes());
                body[d + 8] = frac[t];
                body[d + 9] = 1;
                starts[t] = at as usize;
                at = at.saturating_add(count.saturating_mul(4));
            }
            // Tables from the random values, cycled; capped so huge grids stay cheap.
            let table_len = (at as usize - 112).min(1 << 16);
            body.extend(
                values
                    .iter()
                    .cycle()
                    .flat_map(|v| v.to_le_bytes())
                    .take(table_len),
            );
            if positive_phi {
                for k in 0..usize::from(n_s) {
                    let at = starts[1] + 4 * k;
                    if let Some(slot) = body.get_mut(at..at + 4) {
                        let v = i32::from_le_bytes(slot.try_into().unwrap());
                        let positive = v.unsigned_abs().clamp(1, i32::MAX as u32) as i32;
                        slot.copy_from_slice(&positive.to_le_bytes());
                    }
                }
            }
            let total = (body.len() + 4) as u32;
            body[12..16].copy_from_slice(&total.to_le_bytes());
            body.extend([0u8; 4]);
            fix_crc(&mut body);
            body
        })
}

#[test]
fn the_random_image_generator_reaches_the_lookups() {
    use proptest::strategy::ValueTree;
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = crc_valid_image();
    let parsed = (0..400)
        .filter(|_| {
            let image = strategy.new_tree(&mut runner).unwrap().current();
            LutImage::parse(&image).is_ok()
        })
        .count();
    // Most images carry some fault, but a good share must parse so that the
    // property below runs the lookups on strange but valid tables.
    assert!(parsed >= 100, "only {parsed} of 400 random images parsed");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        prop_assert!(LutImage::parse(&bytes).is_err() || bytes.starts_with(&MAGIC));
    }

    #[test]
    fn arbitrary_bytes_behind_a_valid_prefix_never_panic(
        tail in proptest::collection::vec(any::<u8>(), 0..600),
        total in prop_oneof![Just(None), (0u32..800).prop_map(Some)],
    ) {
        let mut bytes = MAGIC.to_vec();
        bytes.extend(1u16.to_le_bytes());
        bytes.extend(tail);
        if bytes.len() >= 16 {
            let total = total.unwrap_or(bytes.len() as u32);
            bytes[12..16].copy_from_slice(&total.to_le_bytes());
            if total as usize <= bytes.len() && total >= 4 {
                fix_crc(&mut bytes[..total as usize]);
            }
        }
        if let Ok(lut) = LutImage::parse(&bytes) {
            exercise(&lut, 0, 0, 0, 0, 0, 0);
        }
    }

    #[test]
    fn crc_valid_random_images_parse_or_fail_cleanly_and_lookups_stay_in_range(
        image in crc_valid_image(),
        inputs in proptest::array::uniform6(raw()),
    ) {
        if let Ok(lut) = LutImage::parse(&image) {
            let [eps, force, p, phi, s, m] = inputs;
            exercise(&lut, eps, force, p, phi, s, m);
            // Inside the grids too, where the arithmetic actually runs.
            let a = lut.axial_grid();
            let b = lut.bending_grid();
            let mid = |lo: i32, hi: i32| ((i64::from(lo) + i64::from(hi)) / 2) as i32;
            exercise(
                &lut,
                mid(a.eps_min.to_bits(), a.eps_max.to_bits()),
                force,
                mid(a.p_min.to_bits(), a.p_max.to_bits()),
                phi,
                mid(b.s_min.to_bits(), b.s_max.to_bits()),
                m,
            );
        }
    }

    #[test]
    fn extreme_inputs_on_a_real_image_never_panic(
        fixed_inputs in proptest::array::uniform6(raw()),
        reals in proptest::array::uniform4(real()),
    ) {
        let lut = LutImage::parse(default_image()).unwrap();
        let [eps, force, p, phi, s, m] = fixed_inputs;
        exercise(&lut, eps, force, p, phi, s, m);
        let [x, y, z, w] = reals;
        let a = lut.axial_grid();
        if let Ok(r) = lut.axial_strain_f64(x, y) {
            prop_assert!(r.value >= a.eps_min.to_num::<f64>() && r.value <= a.eps_max.to_num::<f64>());
        }
        let _ = lut.axial_force_f64(x, y);
        let _ = lut.bending_moment_f64(x, z, w);
        if let Ok(r) = lut.bending_angle_f64(x, z, w) {
            prop_assert!(r.value.abs() <= 0.9 + 1e-4);
        }
    }

    #[test]
    fn single_byte_edits_with_a_fixed_crc_never_panic(
        at in 0usize..25_984,
        value in any::<u8>(),
        inputs in proptest::array::uniform6(raw()),
    ) {
        let mut bytes = default_image().to_vec();
        bytes[at] = value;
        fix_crc(&mut bytes);
        if let Ok(lut) = LutImage::parse(&bytes) {
            let [eps, force, p, phi, s, m] = inputs;
            exercise(&lut, eps, force, p, phi, s, m);
        }
    }
}
