//! Pressure control of Fig 3.7: inverse-model feed-forward plus PD feedback
//! per actuator on the configuration error expressed as column-length error.
//!
//! `u = P_ff + Kp e - Kd dl/dt (+ I)`, with the derivative on the measured
//! length (no kick on target steps), first-order filtered; the optional
//! integral integrates only while the output is not pushed further into a
//! limit (conditional integration) and is itself bounded by the pressure
//! span (anti-windup). The output then moves at most `slew` per tick and is
//! clamped to `[min, max]`; the previous output is inside the limits, so the
//! result never leaves them.
//!
//! Units: lengths m Q8.24, pressures Pa Q24.8, gains Pa/m, Pa s/m and
//! Pa/(m s) in Q24.8, time in microseconds.

use ocm_shared::protocol::{Gains, Limits, MAX_ACTUATORS};

use crate::fx::{from_f64, rshift_round, sat};

/// Fixed-point gains.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GainsFx {
    /// Pa per m, Q24.8.
    pub kp_q8: i32,
    /// Pa s per m, Q24.8.
    pub kd_q8: i32,
    /// Pa per (m s), Q24.8.
    pub ki_q8: i32,
    /// Derivative filter time constant, microseconds.
    pub filter_us: u32,
}

impl GainsFx {
    /// Converts and checks wire gains: finite, non-negative, below 10^7 in
    /// their SI units; filter 0..=1 s.
    pub fn new(g: &Gains) -> Option<Self> {
        let ok = |x: f32| x.is_finite() && (0.0..1e7).contains(&x);
        let filter_ok =
            g.derivative_filter_s.is_finite() && (0.0..=1.0).contains(&g.derivative_filter_s);
        if !(ok(g.kp_pa_per_m) && ok(g.kd_pa_s_per_m) && ok(g.ki_pa_per_m_s) && filter_ok) {
            return None;
        }
        Some(Self {
            kp_q8: from_f64(f64::from(g.kp_pa_per_m), 8),
            kd_q8: from_f64(f64::from(g.kd_pa_s_per_m), 8),
            ki_q8: from_f64(f64::from(g.ki_pa_per_m_s), 8),
            filter_us: (f64::from(g.derivative_filter_s) * 1e6) as u32,
        })
    }

    /// Default gains: 1 kPa per mm, 20 Pa per mm/s, no integral, 5 ms filter.
    pub const DEFAULT: Self = Self {
        kp_q8: 1_000_000 * 256,
        kd_q8: 20_000 * 256,
        ki_q8: 0,
        filter_us: 5_000,
    };
}

/// Fixed-point output limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LimitsFx {
    /// Lowest command, Pa Q24.8.
    pub min_q8: i32,
    /// Highest command, Pa Q24.8.
    pub max_q8: i32,
    /// Largest change per second, Pa Q24.8.
    pub slew_q8_per_s: i32,
}

impl LimitsFx {
    /// Default: -20..35 kPa, 200 kPa/s.
    pub const DEFAULT: Self = Self {
        min_q8: -20_000 * 256,
        max_q8: 35_000 * 256,
        slew_q8_per_s: 200_000 * 256,
    };

    /// Converts and checks wire limits: finite, `-100 kPa <= min < max <=
    /// 500 kPa`, `0 < slew <= 10 MPa/s`.
    pub fn new(l: &Limits) -> Option<Self> {
        let fin = l.min_pa.is_finite() && l.max_pa.is_finite() && l.slew_pa_per_s.is_finite();
        if !fin || l.min_pa < -100_000.0 || l.max_pa > 500_000.0 || l.min_pa >= l.max_pa {
            return None;
        }
        if !(l.slew_pa_per_s > 0.0 && l.slew_pa_per_s <= 1e7) {
            return None;
        }
        Some(Self {
            min_q8: from_f64(f64::from(l.min_pa), 8),
            max_q8: from_f64(f64::from(l.max_pa), 8),
            slew_q8_per_s: from_f64(f64::from(l.slew_pa_per_s), 8),
        })
    }

    /// `p` clamped into the limits.
    pub fn clamp(&self, p: i32) -> i32 {
        p.clamp(self.min_q8, self.max_q8)
    }
}

/// Per-actuator controller state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Channel {
    /// Last commanded pressure, Pa Q24.8 (always inside the limits).
    pub output_q8: i32,
    /// Last measured length, m Q8.24 (`None` before the first sample).
    pub last_length_q24: Option<i32>,
    /// Filtered length rate, m/s Q8.24.
    pub rate_q24: i32,
    /// Integral term, Pa Q24.8 with 24 extra fraction bits.
    pub integral_q32: i64,
}

/// The controller of all actuators.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Controller {
    /// Per-actuator state.
    pub channels: [Channel; MAX_ACTUATORS],
}

impl Default for Controller {
    fn default() -> Self {
        Self {
            channels: [Channel::default(); MAX_ACTUATORS],
        }
    }
}

impl Controller {
    /// Forgets rates and integrals (on mode changes); keeps outputs.
    pub fn reset_dynamics(&mut self) {
        for c in &mut self.channels {
            c.last_length_q24 = None;
            c.rate_q24 = 0;
            c.integral_q32 = 0;
        }
    }

    /// Slew-limits `want` relative to the last output, clamps it and stores it.
    fn apply(ch: &mut Channel, want: i64, limits: &LimitsFx, step: i64) -> i32 {
        let prev = i64::from(ch.output_q8);
        let slewed = want.clamp(prev - step, prev + step);
        let out = sat(slewed).clamp(limits.min_q8, limits.max_q8);
        ch.output_q8 = out;
        out
    }

    /// Open loop: drive `i` towards the feed-forward pressure.
    pub fn open_loop(&mut self, i: usize, ff_q8: i32, limits: &LimitsFx, dt_us: u32) -> i32 {
        let k = TickConsts::new(&GainsFx::DEFAULT, limits, dt_us);
        self.open_loop_with(i, ff_q8, limits, &k)
    }

    /// [`Self::open_loop`] with precomputed constants.
    pub fn open_loop_with(
        &mut self,
        i: usize,
        ff_q8: i32,
        limits: &LimitsFx,
        k: &TickConsts,
    ) -> i32 {
        match self.channels.get_mut(i) {
            Some(ch) => Self::apply(ch, i64::from(ff_q8), limits, k.step_q8),
            None => limits.clamp(0),
        }
    }

    /// Closed loop: feed-forward plus PD(+I) on the length error of `i`.
    #[allow(clippy::too_many_arguments)]
    pub fn closed_loop(
        &mut self,
        i: usize,
        ff_q8: i32,
        target_q24: i32,
        measured_q24: i32,
        gains: &GainsFx,
        limits: &LimitsFx,
        dt_us: u32,
    ) -> i32 {
        let k = TickConsts::new(gains, limits, dt_us);
        self.closed_loop_with(i, ff_q8, target_q24, measured_q24, limits, &k)
    }

    /// [`Self::closed_loop`] with precomputed constants.
    pub fn closed_loop_with(
        &mut self,
        i: usize,
        ff_q8: i32,
        target_q24: i32,
        measured_q24: i32,
        limits: &LimitsFx,
        k: &TickConsts,
    ) -> i32 {
        let Some(ch) = self.channels.get_mut(i) else {
            return limits.clamp(0);
        };
        // Derivative on the measurement, first-order low pass.
        if let Some(last) = ch.last_length_q24 {
            let raw_rate = i64::from(sat(
                (i64::from(measured_q24) - i64::from(last)).saturating_mul(k.rate_mul)
            ));
            let rate = i64::from(ch.rate_q24);
            ch.rate_q24 = sat(rate + rshift_round((raw_rate - rate) * k.alpha_q16, 16));
        }
        ch.last_length_q24 = Some(measured_q24);
        let err = i64::from(target_q24) - i64::from(measured_q24);
        let p_term = rshift_round(err.saturating_mul(k.kp_q8), 24);
        let d_term = rshift_round(i64::from(ch.rate_q24).saturating_mul(k.kd_q8), 24);
        let i_term = ch.integral_q32 >> 24;
        let want = i64::from(ff_q8)
            .saturating_add(p_term)
            .saturating_sub(d_term)
            .saturating_add(i_term);
        let out = Self::apply(ch, want, limits, k.step_q8);
        // Conditional integration: not while the output is held at a limit
        // (or by the slew) in the direction the error pushes.
        let held_high = i64::from(out) < want && err > 0;
        let held_low = i64::from(out) > want && err < 0;
        if k.ki_dt_q24 != 0 && !held_high && !held_low {
            let inc = err.saturating_mul(k.ki_dt_q24) >> 16;
            let bound = (i64::from(limits.max_q8) - i64::from(limits.min_q8)) << 24;
            ch.integral_q32 = ch.integral_q32.saturating_add(inc).clamp(-bound, bound);
        }
        out
    }
}

/// Per-tick constants of the control law, computed once per tick so the
/// per-actuator work needs no division.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TickConsts {
    /// Pa per m, Q24.8.
    pub kp_q8: i64,
    /// Pa s per m, Q24.8.
    pub kd_q8: i64,
    /// `Ki dt`, Pa per m, Q40.24.
    pub ki_dt_q24: i64,
    /// Low-pass weight `dt / (tau + dt)`, Q16.
    pub alpha_q16: i64,
    /// `10^6 / dt`: length step to rate.
    pub rate_mul: i64,
    /// Largest output change per tick, Pa Q24.8.
    pub step_q8: i64,
}

impl TickConsts {
    /// Constants for gains, limits and a period `dt_us`.
    pub fn new(g: &GainsFx, l: &LimitsFx, dt_us: u32) -> Self {
        let dt = i64::from(dt_us.max(1));
        Self {
            kp_q8: i64::from(g.kp_q8),
            kd_q8: i64::from(g.kd_q8),
            ki_dt_q24: i64::from(g.ki_q8)
                .saturating_mul(dt)
                .saturating_mul(1 << 16)
                / 1_000_000,
            alpha_q16: (dt << 16) / (dt + i64::from(g.filter_us)),
            rate_mul: 1_000_000 / dt,
            step_q8: (i64::from(l.slew_q8_per_s).saturating_mul(dt) / 1_000_000).max(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_never_leaves_limits_and_respects_slew() {
        let limits = LimitsFx::DEFAULT;
        let mut c = Controller::default();
        let dt = 1_000;
        let step = limits.slew_q8_per_s / 1_000;
        let mut prev = 0;
        for k in 0..2_000 {
            let ff = if k < 1_000 { i32::MAX } else { i32::MIN };
            let out = c.open_loop(0, ff, &limits, dt);
            assert!(out >= limits.min_q8 && out <= limits.max_q8);
            assert!((out - prev).abs() <= step);
            prev = out;
        }
        assert_eq!(prev, limits.min_q8);
    }

    #[test]
    fn proportional_term_matches_hand_computation() {
        let limits = LimitsFx::DEFAULT;
        let gains = GainsFx {
            kp_q8: 1_000_000 * 256,
            kd_q8: 0,
            ki_q8: 0,
            filter_us: 0,
        };
        let mut c = Controller::default();
        // 1 mm short with 1 kPa/mm -> +1 kPa over a 5 kPa feed-forward;
        // the slew allows 200 Pa per ms, so step 30 ms.
        let mut out = 0;
        for _ in 0..40 {
            out = c.closed_loop(0, 5_000 * 256, 16_777, 0, &gains, &limits, 1_000);
        }
        let want = 5_000.0 + 1e6 * (16_777.0 / 16_777_216.0);
        assert!(
            (f64::from(out) / 256.0 - want).abs() < 0.01,
            "{}",
            f64::from(out) / 256.0
        );
    }

    #[test]
    fn derivative_acts_on_measurement_not_on_target_steps() {
        let limits = LimitsFx::DEFAULT;
        let gains = GainsFx {
            kp_q8: 0,
            kd_q8: 1_000 * 256,
            ki_q8: 0,
            filter_us: 0,
        };
        let mut c = Controller::default();
        c.closed_loop(0, 0, 0, 0, &gains, &limits, 1_000);
        // Target jumps, measurement still: no derivative action.
        let out = c.closed_loop(0, 0, 1 << 24, 0, &gains, &limits, 1_000);
        assert_eq!(out, 0);
        // Measurement moves 1 mm in 1 ms = 1 m/s: -1000 Pa (slew-limited).
        let out = c.closed_loop(0, 0, 0, 16_777, &gains, &limits, 1_000);
        assert!(out < 0);
        let rate = f64::from(c.channels[0].rate_q24) / 16_777_216.0;
        assert!((rate - 1.0).abs() < 1e-3, "{rate}");
    }

    #[test]
    fn integral_does_not_wind_up_against_a_limit() {
        let limits = LimitsFx::DEFAULT;
        let gains = GainsFx {
            kp_q8: 0,
            kd_q8: 0,
            ki_q8: 1_000_000 * 256,
            filter_us: 0,
        };
        let mut c = Controller::default();
        for _ in 0..5_000 {
            c.closed_loop(0, 34_000 * 256, 1 << 24, 0, &gains, &limits, 1_000);
        }
        assert_eq!(c.channels[0].output_q8, limits.max_q8);
        let frozen = c.channels[0].integral_q32;
        for _ in 0..100 {
            c.closed_loop(0, 34_000 * 256, 1 << 24, 0, &gains, &limits, 1_000);
        }
        assert_eq!(c.channels[0].integral_q32, frozen);
        // The integral stopped within one increment (1 kPa) of the 1 kPa headroom.
        assert!((frozen >> 24) <= 2_000 * 256, "{}", frozen >> 24);
        // Reversing the error unwinds within the two increments it overshot.
        let mut out = limits.max_q8;
        for _ in 0..3 {
            out = c.closed_loop(0, 34_000 * 256, 0, 1 << 24, &gains, &limits, 1_000);
        }
        assert!(out < limits.max_q8);
    }

    #[test]
    fn wire_values_are_checked() {
        assert!(
            GainsFx::new(&Gains {
                kp_pa_per_m: f32::NAN,
                kd_pa_s_per_m: 0.0,
                ki_pa_per_m_s: 0.0,
                derivative_filter_s: 0.0
            })
            .is_none()
        );
        assert!(
            LimitsFx::new(&Limits {
                min_pa: 10.0,
                max_pa: 5.0,
                slew_pa_per_s: 1.0
            })
            .is_none()
        );
        let l = LimitsFx::new(&Limits {
            min_pa: -20_000.0,
            max_pa: 35_000.0,
            slew_pa_per_s: 200_000.0,
        })
        .unwrap();
        assert_eq!(l, LimitsFx::DEFAULT);
    }
}
