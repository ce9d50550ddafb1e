//! Sensor models invert within their noise.

use ocm_hilsim::pcc::{Config, quaternion_error_rad};
use ocm_hilsim::sensors::{HallParams, ImuParams, Sensors};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[test]
fn hall_code_inverts_to_the_column_length() {
    let hall = HallParams::default();
    let imu = ImuParams::default();
    let mut s = Sensors::new(hall, imu, 0.06, 3.0, ChaCha8Rng::seed_from_u64(5));
    let lsb_m = 6.144 / 32_768.0 / hall.sensitivity_v_per_m;
    let sigma_m = hall.noise_v / hall.sensitivity_v_per_m;
    for len in [0.07, 0.10, 0.13, 0.16] {
        let q = Config::from_polar(len, 0.0, 0.0);
        let n = 400;
        let mut sum = 0.0;
        let mut worst: f64 = 0.0;
        for _ in 0..n {
            let sample = s.sample(&q, [0.0; 3]);
            for c in sample.hall_codes {
                let e = 3.0 * hall.distance_of_code(c) - len;
                sum += e;
                worst = worst.max(e.abs());
            }
        }
        let mean = sum / (3 * n) as f64;
        // Mean within 5 standard errors plus half an LSB; single reads within 5 sigma.
        assert!(
            mean.abs() < 3.0 * (5.0 * sigma_m / ((3 * n) as f64).sqrt() + lsb_m),
            "{len}: bias {mean}"
        );
        assert!(
            worst < 3.0 * (5.0 * sigma_m + lsb_m),
            "{len}: worst {worst}"
        );
    }
}

#[test]
fn hall_error_grows_with_tilt_as_the_chord() {
    let hall = HallParams {
        noise_v: 0.0,
        ..HallParams::default()
    };
    let mut s = Sensors::new(
        hall,
        ImuParams {
            bias_rad: 0.0,
            noise_rad: 0.0,
        },
        0.06,
        3.0,
        ChaCha8Rng::seed_from_u64(1),
    );
    let mut last = 0.0;
    for th in [0.0, 0.3, 0.6, 0.9] {
        let q = Config::from_polar(0.12, th, 0.0);
        let l = q.column_lengths(0.06);
        let sample = s.sample(&q, [0.0; 3]);
        // Column 2 is on the convex side; every column is bent by th / 3 per OCM.
        let read = 3.0 * hall.distance_of_code(sample.hall_codes[1]);
        let s_ocm = l[1] / 3.0;
        let chord = 3.0 * s_ocm * ocm_hilsim::pcc::sinc(th / 6.0);
        let lsb_m = 3.0 * 6.144 / 32_768.0 / hall.sensitivity_v_per_m;
        assert!(
            (read - chord).abs() <= lsb_m,
            "theta {th}: read {read}, chord {chord}"
        );
        let err = l[1] - read;
        assert!(err >= last - lsb_m, "error must grow with tilt");
        last = err;
    }
    assert!(last > 1e-4, "0.9 rad tilt gives a visible error: {last}");
}

#[test]
fn imu_noise_and_bias_stay_at_their_magnitudes() {
    let imu = ImuParams {
        bias_rad: 0.01,
        noise_rad: 0.002,
    };
    let mut s = Sensors::new(
        HallParams::default(),
        imu,
        0.06,
        3.0,
        ChaCha8Rng::seed_from_u64(9),
    );
    let q = Config::from_polar(0.11, 0.4, 1.0);
    let mut errs = Vec::new();
    for _ in 0..500 {
        let sample = s.sample(&q, [0.0; 3]);
        let n: f64 = sample.imu_quat.iter().map(|v| v * v).sum();
        assert!((n - 1.0).abs() < 1e-12, "unit quaternion");
        errs.push(quaternion_error_rad(sample.imu_quat, q.quaternion()));
    }
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    // Bias 0.01 rad plus 3-axis noise of 0.002 rad: mean near the bias.
    assert!((mean - 0.01).abs() < 0.004, "mean error {mean}");
    assert!(
        errs.iter().all(|e| *e < 0.01 + 6.0 * 0.002),
        "max {:?}",
        errs.iter().cloned().fold(0.0, f64::max)
    );
}

#[test]
fn pcc_round_trips() {
    for p in [[0.0, 0.0, 0.11], [0.03, 0.0, 0.1], [-0.02, 0.025, 0.09]] {
        let c = Config::from_position(p).expect("reachable");
        let back = c.position();
        for k in 0..3 {
            assert!((back[k] - p[k]).abs() < 1e-12, "{p:?} -> {back:?}");
        }
        let l = c.column_lengths(0.06);
        let c2 = Config::from_column_lengths(l, 0.06);
        assert!((c2.backbone_m - c.backbone_m).abs() < 1e-12);
        assert!((c2.bend_x_rad - c.bend_x_rad).abs() < 1e-12);
        assert!((c2.bend_y_rad - c.bend_y_rad).abs() < 1e-12);
    }
    assert!(Config::from_position([0.0, 0.0, -0.1]).is_none());
    assert!(Config::from_position([f64::NAN, 0.0, 0.1]).is_none());
}

#[test]
fn position_jacobian_matches_central_differences() {
    for q in [
        Config::from_polar(0.11, 0.0, 0.0),
        Config::from_polar(0.1, 2e-4, 0.3),
        Config::from_polar(0.13, 0.4, -2.0),
        Config::from_polar(0.09, 1.1, 1.0),
    ] {
        let j = ocm_hilsim::plant::position_jacobian(&q);
        let a = q.to_array();
        for k in 0..3 {
            let h = 1e-6;
            let (mut ap, mut am) = (a, a);
            ap[k] += h;
            am[k] -= h;
            let (pp, pm) = (
                Config::from_array(ap).position(),
                Config::from_array(am).position(),
            );
            for r in 0..3 {
                let fd = (pp[r] - pm[r]) / (2.0 * h);
                assert!(
                    (j[r][k] - fd).abs() < 1e-7,
                    "{q:?} d p{r}/d q{k}: {} vs {fd}",
                    j[r][k]
                );
            }
        }
    }
}
