//! Identification of a 100k-row record (goal: at most 10 s on 2 cores).
// criterion's macros generate undocumented items
#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use ocm_ident::synth::{Spec, generate};
use ocm_ident::{Cause, Config, Kind, identify};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("ident_100k");
    group.sample_size(10);
    for (kind, cause) in [
        (Kind::Axial, Cause::Hysteresis),
        (Kind::Series, Cause::Latency),
        (Kind::Pose, Cause::Hysteresis),
    ] {
        let g = generate(&Spec {
            kind,
            effects: vec![cause],
            seed: 7,
            rows: 100_000,
            ratio: (4.0, 4.0),
        });
        group.bench_function(format!("{}_{}", kind.name(), cause.name()), |b| {
            b.iter(|| identify(&g.record, &Config::default()).expect("valid record"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
