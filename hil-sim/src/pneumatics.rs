//! Pressure regulators: one per chamber, a first-order lag behind a dead
//! time, with an optional constant offset and a supply cut.
//!
//! Defaults are of the SMC ITV2030 class the dissertation used (Ch. 3.3.6):
//! its data sheet gives a response time of about 0.1 s without load; a
//! 20 ms transport delay plus a 50 ms time constant reach 86 % of a step in
//! 0.12 s, which matches that figure for the small OCM chambers. Their
//! range is the 0-30 kPa the dissertation drives them over (16 steps of
//! 2 kPa, Ch. 3.3.6): a positive-pressure regulator makes no vacuum.

use serde::{Deserialize, Serialize};

/// Regulator parameters, shared by all chambers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegulatorParams {
    /// First-order time constant, seconds.
    pub time_constant_s: f64,
    /// Dead time between command and response, seconds.
    pub dead_time_s: f64,
    /// Lowest output gauge pressure, pascals.
    pub min_pa: f64,
    /// Highest output gauge pressure, pascals.
    pub max_pa: f64,
}

impl Default for RegulatorParams {
    fn default() -> Self {
        Self {
            time_constant_s: 0.05,
            dead_time_s: 0.02,
            min_pa: 0.0,
            max_pa: 30_000.0,
        }
    }
}

/// One chamber's regulator state.
#[derive(Debug, Clone)]
pub struct Regulator {
    params: RegulatorParams,
    /// Commands waiting out the dead time, oldest first (ring buffer).
    queue: Vec<f64>,
    head: usize,
    pressure_pa: f64,
    offset_pa: f64,
    /// `exp(-dt / tau)` for the step `decay_dt_s` it was computed for.
    decay: f64,
    decay_dt_s: f64,
}

impl Regulator {
    /// A regulator stepped every `dt_s`, starting at `initial_pa`.
    pub fn new(params: RegulatorParams, dt_s: f64, initial_pa: f64, offset_pa: f64) -> Self {
        let delay = (params.dead_time_s / dt_s).round().max(0.0) as usize;
        Self {
            params,
            queue: vec![initial_pa; delay.max(1)],
            head: 0,
            pressure_pa: initial_pa.clamp(params.min_pa, params.max_pa),
            offset_pa,
            decay: (-dt_s / params.time_constant_s.max(1e-9)).exp(),
            decay_dt_s: dt_s,
        }
    }

    /// Chamber gauge pressure, pascals.
    pub fn pressure_pa(&self) -> f64 {
        self.pressure_pa
    }

    /// Constant offset between command and output, pascals.
    pub fn offset_pa(&self) -> f64 {
        self.offset_pa
    }

    /// Advances by `dt_s` with `command_pa`; when `connected` is false the
    /// chamber is cut from the regulator and vents towards 0 Pa gauge.
    ///
    /// The lag is integrated exactly for a piecewise-constant input, so the
    /// step response is `1 - exp(-t/tau)` after the dead time at any step.
    pub fn step(&mut self, command_pa: f64, connected: bool, dt_s: f64) {
        let delayed = if self.queue.len() == 1 && self.params.dead_time_s < 0.5 * dt_s {
            command_pa
        } else {
            let out = self.queue[self.head];
            self.queue[self.head] = command_pa;
            // A wrap, not a remainder: an integer division costs tens of
            // cycles, three times a tick.
            self.head += 1;
            if self.head == self.queue.len() {
                self.head = 0;
            }
            out
        };
        let goal = if connected {
            (delayed + self.offset_pa).clamp(self.params.min_pa, self.params.max_pa)
        } else {
            0.0_f64.clamp(self.params.min_pa, self.params.max_pa)
        };
        // The lag's decay over one step, recomputed only when dt changes.
        if dt_s != self.decay_dt_s {
            self.decay = (-dt_s / self.params.time_constant_s.max(1e-9)).exp();
            self.decay_dt_s = dt_s;
        }
        self.pressure_pa = goal + (self.pressure_pa - goal) * self.decay;
    }
}
