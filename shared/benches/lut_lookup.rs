//! One inverse axial and one inverse bending lookup on the default-sized
//! image (axial 16 x 129, bending 17 x 129 x 2), plus parsing the image
//! (the CRC pass the firmware pays once at load).

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Grids, Tables, force_n, moment_nm};
use criterion::{Criterion, criterion_main};
use fixed::types::{I8F24, I16F16, I24F8};
use ocm_shared::lut::LutImage;
use std::hint::black_box;

fn lookups(c: &mut Criterion) {
    let bytes = Tables::sample(Grids::DEFAULT).encode(0);
    let lut = LutImage::parse(&bytes).expect("default image parses");

    // Off-grid points inside the tables.
    let p = I24F8::from_num(13_337.5);
    let force = I16F16::from_num(force_n(0.237, 13_337.5));
    let s = I8F24::from_num(0.0431);
    let moment = I8F24::from_num(moment_nm(0.41, 0.0431, 13_337.5));

    c.bench_function("lut inverse axial (axial_strain)", |b| {
        b.iter(|| lut.axial_strain(black_box(force), black_box(p)))
    });
    c.bench_function("lut inverse bending (bending_angle)", |b| {
        b.iter(|| lut.bending_angle(black_box(moment), black_box(s), black_box(p)))
    });
    c.bench_function("lut parse default image (CRC + checks)", |b| {
        b.iter(|| LutImage::parse(black_box(&bytes)).map(|l| l.crc()))
    });
}

// `criterion_group!` generates a public function without a doc comment.
#[allow(missing_docs)]
mod group {
    criterion::criterion_group!(benches, super::lookups);
}
criterion_main!(group::benches);
