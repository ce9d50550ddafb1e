//! Sensor models: a Hall sensor per column read by an ADS1115, and an IMU
//! quaternion on the plate (Ch. 3.3.7, App. C).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::pcc::{Config, Turn, quat_from_rotvec, quat_mul};

/// ADS1115 full-scale range at PGA gain 2/3, volts (LSB = 187.5 uV).
pub const ADS1115_FSR_V: f64 = 6.144;

/// `x` rounded half away from zero (as [`f64::round`]), as an integer
/// saturated to `i64`, NaN giving 0: what `x.round() as i64` gives, without
/// the library call that `round` is on baseline x86-64 (the lab rounds
/// about ten values per tick).
#[inline]
pub fn round_ties_away(x: f64) -> i64 {
    // From 2^52 on every f64 is an integer; `as` saturates and maps NaN to 0.
    if x.is_nan() || x.abs() >= 4_503_599_627_370_496.0 {
        return x as i64;
    }
    let t = x as i64;
    // Exact: `x` and its truncation share their exponent range. Flags,
    // not branches: the fraction is noise a CPU cannot predict.
    let frac = x - t as f64;
    t + i64::from(frac >= 0.5) - i64::from(frac <= -0.5)
}

/// Hall sensor and ADC parameters.
///
/// The magnet and the sensor sit at the two ends of one OCM of each column,
/// so the sensor sees the straight-line magnet distance: the chord of the
/// OCM's arc, shorter than the arc by `s (1 - sinc(phi/2))`. That is the
/// error that grows with tilt (App. C measured 0.131 mm on average over the
/// bending range); `tilt_error_gain` scales it (1 = pure geometry).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HallParams {
    /// Output at `center_distance_m`, volts.
    pub center_v: f64,
    /// Magnet distance at `center_v`, metres.
    pub center_distance_m: f64,
    /// Sensitivity, volts per metre (linear, App. C Fig. C.1-B).
    pub sensitivity_v_per_m: f64,
    /// Gaussian output noise, volts RMS.
    pub noise_v: f64,
    /// Scale of the chord-versus-arc tilt error.
    pub tilt_error_gain: f64,
}

impl Default for HallParams {
    fn default() -> Self {
        // 0.5 .. 4.5 V over an OCM length of 16 .. 64 mm (strain -0.6 .. 0.6).
        Self {
            center_v: 2.5,
            center_distance_m: 0.040,
            sensitivity_v_per_m: 4.0 / 0.048,
            noise_v: 0.002,
            tilt_error_gain: 1.0,
        }
    }
}

impl HallParams {
    /// Noise-free voltage at a magnet distance, volts.
    pub fn voltage(&self, distance_m: f64) -> f64 {
        self.center_v + self.sensitivity_v_per_m * (distance_m - self.center_distance_m)
    }

    /// ADC code of a voltage (rounded, saturated to `i16`).
    pub fn code(voltage_v: f64) -> i16 {
        let lsb = ADS1115_FSR_V / 32_768.0;
        round_ties_away(voltage_v / lsb).clamp(-32_768, 32_767) as i16
    }

    /// Magnet distance read back from a code (the inverse of the nominal,
    /// noise-free chain), metres.
    pub fn distance_of_code(&self, code: i16) -> f64 {
        let v = f64::from(code) * ADS1115_FSR_V / 32_768.0;
        self.center_distance_m + (v - self.center_v) / self.sensitivity_v_per_m
    }

    /// Magnet distance of a column of `ocms` OCMs of length `column_m` bent
    /// by `theta_rad` in all: the chord of one OCM's arc.
    pub fn distance(&self, column_m: f64, theta_rad: f64, ocms: f64) -> f64 {
        let chord = crate::pcc::sinc(0.5 * theta_rad / ocms);
        self.distance_with_chord(column_m, chord, ocms)
    }

    /// [`Self::distance`] with the chord factor `sinc(theta / (2 ocms))`
    /// already known (it is the same for the three columns).
    fn distance_with_chord(&self, column_m: f64, chord: f64, ocms: f64) -> f64 {
        let s = column_m / ocms;
        let chord_loss = s * (1.0 - chord);
        s - self.tilt_error_gain * chord_loss
    }
}

/// IMU parameters: a constant bias rotation and white rotation noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuParams {
    /// Bias rotation magnitude (random axis, drawn once), radians.
    pub bias_rad: f64,
    /// White noise per axis, radians RMS.
    pub noise_rad: f64,
}

impl Default for ImuParams {
    fn default() -> Self {
        Self {
            bias_rad: 0.005,
            noise_rad: 0.002,
        }
    }
}

/// One sample of the simulated sensors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorSample {
    /// ADS1115 codes of the three Hall sensors.
    pub hall_codes: [i16; 3],
    /// Plate orientation `[w, x, y, z]`.
    pub imu_quat: [f64; 4],
    /// Measured chamber pressures, pascals.
    pub pressures_pa: [f64; 3],
}

/// The sensor suite with its seeded noise source.
#[derive(Debug, Clone)]
pub struct Sensors {
    hall: HallParams,
    imu: ImuParams,
    bias: [f64; 4],
    rng: ChaCha8Rng,
    d_m: f64,
    ocms: f64,
}

impl Sensors {
    /// A suite for a segment of radius `d_m` with `ocms` OCMs per column;
    /// `rng` is consumed for the IMU bias and then for the noise.
    pub fn new(hall: HallParams, imu: ImuParams, d_m: f64, ocms: f64, mut rng: ChaCha8Rng) -> Self {
        let axis: [f64; 3] = std::array::from_fn(|_| rng.sample::<f64, _>(StandardNormal));
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2])
            .sqrt()
            .max(1e-12);
        let bias = quat_from_rotvec(axis.map(|a| a / n * imu.bias_rad));
        Self {
            hall,
            imu,
            bias,
            rng,
            d_m,
            ocms,
        }
    }

    /// Hall parameters.
    pub fn hall(&self) -> &HallParams {
        &self.hall
    }

    /// Samples the sensors at configuration `q` and chamber pressures.
    pub fn sample(&mut self, q: &Config, pressures_pa: [f64; 3]) -> SensorSample {
        self.sample_with(q, &q.turn(), pressures_pa)
    }

    /// [`Self::sample`] with the [`Turn`] of `q` already known.
    pub fn sample_with(&mut self, q: &Config, turn: &Turn, pressures_pa: [f64; 3]) -> SensorSample {
        let l = q.column_lengths(self.d_m);
        let th = turn.theta_rad;
        // Every column bends by the same angle: one chord factor for all.
        let chord = crate::pcc::sinc(0.5 * th / self.ocms);
        let hall_codes = std::array::from_fn(|i| {
            let x = self.hall.distance_with_chord(l[i], chord, self.ocms);
            let n: f64 = self.rng.sample(StandardNormal);
            HallParams::code(self.hall.voltage(x) + self.hall.noise_v * n)
        });
        let noise: [f64; 3] =
            std::array::from_fn(|_| self.imu.noise_rad * self.rng.sample::<f64, _>(StandardNormal));
        let imu_quat = quat_mul(
            quat_mul(q.quaternion_with(turn), self.bias),
            quat_from_rotvec(noise),
        );
        SensorSample {
            hall_codes,
            imu_quat,
            pressures_pa,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::round_ties_away;

    #[test]
    fn rounding_matches_the_standard_library() {
        let mut vals = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.499_999_999_999_999_94,
            -0.499_999_999_999_999_94,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            9_007_199_254_740_993.0,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN_POSITIVE,
        ];
        let mut x = 0.123_456_789_f64;
        for _ in 0..10_000 {
            // A spread of magnitudes and signs, ties included.
            x = (x * 7.3 + 0.11).fract();
            vals.push((x - 0.5) * 1e5);
            vals.push(((x - 0.5) * 1e4).round() + 0.5);
        }
        for v in vals {
            assert_eq!(round_ties_away(v), v.round() as i64, "{v}");
        }
        assert_eq!(round_ties_away(f64::NAN), 0);
    }
}
