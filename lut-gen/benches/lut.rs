//! Building the default LUT image and one inverse lookup through it.
#![allow(missing_docs)] // criterion_group! generates an undocumented public function

use criterion::{Criterion, criterion_group, criterion_main};
use ocm_lutgen::tables::{TableConfig, build_tables};
use ocm_lutgen::{OcmModel, OcmParams};
use ocm_shared::lut::{ForceN, LengthM, LutImage, MomentNm, PressurePa};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let model = OcmModel::new(OcmParams::TABLE_3_1).expect("defaults are valid");
    let cfg = TableConfig::default();
    c.bench_function("build_default_lut", |b| {
        b.iter(|| {
            let t = build_tables(&model, &cfg, &|_, _| {}).expect("builds");
            black_box(t.encode(&model).expect("encodes"))
        })
    });
    let bytes = build_tables(&model, &cfg, &|_, _| {})
        .unwrap()
        .encode(&model)
        .unwrap();
    let image = LutImage::parse(&bytes).unwrap();
    let force = ForceN::from_num(-12.5);
    let p = PressurePa::from_num(17_000);
    c.bench_function("inverse_axial_lookup", |b| {
        b.iter(|| black_box(image.axial_strain(black_box(force), black_box(p))))
    });
    let m = MomentNm::from_num(0.012);
    let s = LengthM::from_num(0.043);
    c.bench_function("inverse_bending_lookup", |b| {
        b.iter(|| black_box(image.bending_angle(black_box(m), black_box(s), black_box(p))))
    });
    c.bench_function("f64_model_axial_force", |b| {
        b.iter(|| black_box(model.axial_force_n(black_box(0.23), black_box(17e3))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
