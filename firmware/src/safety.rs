//! Link watchdog and sensor plausibility (Ch. 3.3.7 sensors; issue 3 §5).
//!
//! Faults latch as [`ocm_shared::protocol::fault`] flags; the app puts the
//! outputs into the configured safe state while any is set.

use ocm_shared::protocol::{MAX_ACTUATORS, SafeAction, SafetyConfig, SensorFrame, fault};

use crate::calibration::HallMap;

/// Default safety settings: 100 ms link timeout, hold, 200 stuck ticks.
pub const DEFAULT_SAFETY: SafetyConfig = SafetyConfig {
    link_timeout_us: 100_000,
    action: SafeAction::Hold,
    stuck_ticks: 200,
};

/// Accepted squared quaternion norm, Q4.28 (0.8..1.2 of unit length squared).
const QUAT_NORM2_MIN: i64 = (1 << 28) * 8 / 10;
const QUAT_NORM2_MAX: i64 = (1 << 28) * 12 / 10;
/// Chamber pressure plausibility margin beyond the command limits, Pa Q24.8.
pub const PRESSURE_MARGIN_Q8: i32 = 15_000 * 256;
/// Command movement that makes a frozen Hall code suspicious, Pa Q24.8.
pub const STUCK_PRESSURE_Q8: i64 = 2_000 * 256;

/// Whether the link has been silent for longer than the timeout.
pub fn link_lost(now_us: u32, last_rx_us: u32, timeout_us: u32) -> bool {
    now_us.wrapping_sub(last_rx_us) > timeout_us
}

/// Stuck-sensor tracking of one Hall channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StuckTracker {
    last_code: Option<i16>,
    same_ticks: u16,
    command_at_freeze_q8: i32,
    max_move_q8: i64,
}

impl StuckTracker {
    /// Feeds one sample and the current command; true when the code has not
    /// changed for `limit` ticks while the command moved by more than
    /// [`STUCK_PRESSURE_Q8`].
    pub fn update(&mut self, code: i16, command_q8: i32, limit: u16) -> bool {
        if self.last_code == Some(code) {
            self.same_ticks = self.same_ticks.saturating_add(1);
            let moved = (i64::from(command_q8) - i64::from(self.command_at_freeze_q8)).abs();
            self.max_move_q8 = self.max_move_q8.max(moved);
        } else {
            self.last_code = Some(code);
            self.same_ticks = 0;
            self.command_at_freeze_q8 = command_q8;
            self.max_move_q8 = 0;
        }
        limit > 0 && self.same_ticks >= limit && self.max_move_q8 > STUCK_PRESSURE_Q8
    }
}

/// Checks one sensor frame; returns the fault flags it raises.
/// `maps[i]` is the calibration of actuator `i` if any.
pub fn check_frame(
    frame: &SensorFrame,
    actuators: usize,
    maps: &[Option<HallMap>; MAX_ACTUATORS],
    pressure_window_q8: (i32, i32),
    use_imu: bool,
) -> u16 {
    let mut faults = 0;
    if frame.hall_codes.len() != actuators || frame.pressures_pa.len() != actuators {
        return fault::SENSOR_SHAPE;
    }
    for (i, &code) in frame.hall_codes.iter().enumerate() {
        let bad = match maps.get(i).copied().flatten() {
            Some(m) => !m.plausible(code),
            None => code == i16::MIN || code == i16::MAX,
        };
        if bad {
            faults |= fault::HALL_RANGE;
        }
    }
    if use_imu {
        let n2: i64 = frame
            .imu_quat_q14
            .iter()
            .map(|&q| i64::from(q) * i64::from(q))
            .sum();
        if !(QUAT_NORM2_MIN..=QUAT_NORM2_MAX).contains(&n2) {
            faults |= fault::IMU_INVALID;
        }
    }
    let lo = i64::from(pressure_window_q8.0) - i64::from(PRESSURE_MARGIN_Q8);
    let hi = i64::from(pressure_window_q8.1) + i64::from(PRESSURE_MARGIN_Q8);
    for &p in &frame.pressures_pa {
        let q8 = i64::from(p) * 256;
        if q8 < lo || q8 > hi {
            faults |= fault::PRESSURE_RANGE;
        }
    }
    faults
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(codes: &[i16], quat: [i16; 4], p: &[i32]) -> SensorFrame {
        SensorFrame {
            hall_codes: codes.iter().copied().collect(),
            imu_quat_q14: quat,
            pressures_pa: p.iter().copied().collect(),
        }
    }

    #[test]
    fn watchdog_handles_clock_wrap() {
        assert!(!link_lost(1_000, 0, 100_000));
        assert!(link_lost(200_001, 100_000, 100_000));
        assert!(!link_lost(50, u32::MAX - 50, 100_000));
    }

    #[test]
    fn plausibility_flags_each_fault() {
        let maps = [None; MAX_ACTUATORS];
        let ok = frame(&[100, 200, 300], [16_384, 0, 0, 0], &[0, 1_000, 30_000]);
        let win = (-20_000 * 256, 35_000 * 256);
        assert_eq!(check_frame(&ok, 3, &maps, win, true), 0);
        assert_eq!(check_frame(&ok, 6, &maps, win, true), fault::SENSOR_SHAPE);
        let sat = frame(&[i16::MAX, 200, 300], [16_384, 0, 0, 0], &[0, 0, 0]);
        assert_eq!(check_frame(&sat, 3, &maps, win, true), fault::HALL_RANGE);
        let q = frame(&[1, 2, 3], [0, 0, 0, 0], &[0, 0, 0]);
        assert_eq!(check_frame(&q, 3, &maps, win, true), fault::IMU_INVALID);
        assert_eq!(check_frame(&q, 3, &maps, win, false), 0);
        let p = frame(&[1, 2, 3], [16_384, 0, 0, 0], &[0, 0, 60_000]);
        assert_eq!(check_frame(&p, 3, &maps, win, true), fault::PRESSURE_RANGE);
    }

    #[test]
    fn stuck_needs_both_frozen_code_and_moving_command() {
        let mut t = StuckTracker::default();
        // Frozen code at a steady command: fine (a plant at rest).
        for _ in 0..500 {
            assert!(!t.update(42, 1_000, 200));
        }
        // Command moves by 3 kPa while the code stays frozen: stuck.
        let mut hit = false;
        for k in 0..300 {
            hit |= t.update(42, 1_000 + k * 256 * 10, 200);
        }
        assert!(hit);
        // A changing code resets it.
        assert!(!t.update(43, 0, 200));
    }
}
