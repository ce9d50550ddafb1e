//! Simulated seconds per wall second of the plant with the oracle at 1 kHz,
//! and of the plant alone.

use criterion::{Criterion, criterion_main};
use ocm_hilsim::mcu::{GroundTruth, McuInput, Oracle, PressureLimits};
use ocm_hilsim::plant::{Plant, PlantParams, PlateLoad};
use ocm_hilsim::reference::Path;
use ocm_hilsim::sensors::SensorSample;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let params = PlantParams::default();
    let plant = Plant::new(params, 1).expect("plant");
    // The lab's circle: the middle of the calibrated plant's workspace.
    let path = Path::Circle {
        center_m: [0.0, 0.0, 0.155],
        radius_m: 0.03,
        period_s: 10.0,
        start_s: 0.0,
    };
    let load = PlateLoad::default();
    let q0 = path.config_at(0.0);
    let p0 = plant.pressures_for(&q0, &load, [0.0; 3]).expect("inverse");
    let limits = PressureLimits {
        min_pa: params.regulator.min_pa,
        max_pa: params.regulator.max_pa,
    };
    let sample = SensorSample {
        hall_codes: [0; 3],
        imu_quat: [1.0, 0.0, 0.0, 0.0],
        pressures_pa: [0.0; 3],
    };
    // One simulated second per iteration: criterion's time per iteration is
    // wall seconds per simulated second, whose inverse is the realtime factor.
    c.bench_function("plant_1s_at_1khz", |b| {
        b.iter(|| {
            let mut s = plant.state_at(q0, p0, load);
            for _ in 0..1000 {
                plant.step(&mut s, black_box(p0));
            }
            s.q
        })
    });
    c.bench_function("plant_oracle_1s_at_1khz", |b| {
        b.iter(|| {
            let mut s = plant.state_at(q0, p0, load);
            let mut oracle = Oracle::new(plant.clone(), limits);
            for k in 0..1000 {
                let input = McuInput {
                    time_s: k as f64 * 1e-3,
                    sensors: &sample,
                    reference: &path,
                    target: path.config_at(k as f64 * 1e-3),
                    expected_load: load,
                };
                let truth = GroundTruth {
                    load,
                    hysteresis_n: [0.0; 3],
                };
                let cmd = oracle.tick_with_truth(&input, &truth).expect("oracle");
                plant.step(&mut s, cmd);
            }
            s.q
        })
    });
    #[cfg(feature = "firmware")]
    {
        use ocm_hilsim::firmware::{FirmwareMcu, LUT_CAPACITY, lut_image};
        use ocm_hilsim::{SimConfig, run_with_mcu};
        let cfg = SimConfig {
            short: true,
            log_every: 1_000_000,
            ..SimConfig::default()
        };
        let image = lut_image(&cfg.plant, &cfg.limits).expect("lut");
        let mut buf = vec![0u8; LUT_CAPACITY];
        let mut group = c.benchmark_group("sil");
        group.sample_size(10);
        // One short circle (13 simulated seconds) per iteration.
        group.bench_function("firmware_cl_circle_13s", |b| {
            b.iter(|| {
                let mut fw =
                    FirmwareMcu::in_process(&mut buf, &image, &cfg, true).expect("firmware");
                run_with_mcu("circle", &cfg, &mut fw).expect("run").rmse_mm
            })
        });
        // SIL throughput on 2 cores: two closed-loop circles (26 simulated
        // seconds) on two threads.
        group.bench_function("firmware_cl_circle_2x13s_2threads", |b| {
            b.iter(|| {
                std::thread::scope(|s| {
                    let runs: Vec<_> = (0..2)
                        .map(|_| {
                            s.spawn(|| {
                                let mut buf = vec![0u8; LUT_CAPACITY];
                                let mut fw = FirmwareMcu::in_process(&mut buf, &image, &cfg, true)
                                    .expect("firmware");
                                run_with_mcu("circle", &cfg, &mut fw).expect("run").rmse_mm
                            })
                        })
                        .collect();
                    runs.into_iter()
                        .map(|h| h.join().expect("run thread"))
                        .sum::<f64>()
                })
            })
        });
        // The lab's own unit of work on 2 cores: firmware OL and CL (26
        // simulated seconds in all) on two threads, the oracle beside them,
        // LUT build included.
        group.bench_function("firmware_ol_cl_oracle_circle_2x13s", |b| {
            b.iter(|| {
                ocm_hilsim::firmware::run_scenario_with_firmware("circle", &cfg)
                    .expect("run")
                    .realtime_factor
            })
        });
        group.finish();
    }
}

/// The benchmark group (written out: `criterion_group!` emits an
/// undocumented public function).
fn benches() {
    let mut c = Criterion::default().configure_from_args();
    bench(&mut c);
}

criterion_main!(benches);
