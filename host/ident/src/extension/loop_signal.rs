//! The signals of the extensions inside the dynamics, evaluated step by step from the model's
//! own output and velocity (a stop operator, friction's terms, stiffening powers).

/// A signal of the model's own output that enters the dynamics where an input force does;
/// evaluated step by step, so that the in-loop fit ([`super::in_loop`]) can feed the extended
/// model's output back into it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum LoopSignal {
    /// Stop operator of half-width `r`, normalised: `(y - play_r(y)) / r` (an
    /// elastic-perfectly-plastic element; the weight is its force when sliding).
    Stop(f64),
    /// Smoothed sign of the velocity, `tanh(v / v0)` (Coulomb friction).
    Sign(f64),
    /// Velocity over a scale, `v / vs` (viscous friction).
    Viscous(f64),
    /// Stribeck peak, `tanh(v / v0) exp(-(v / vs)^2)`.
    Stribeck(f64, f64),
    /// Power of the centred output, `((y - m) / r)^p`.
    Power(f64, f64, i32),
    /// Mixed term of output and velocity, `((y - m) / r)^p (v / vs)^q`.
    Mixed(f64, f64, f64, i32, i32),
}

impl LoopSignal {
    /// The signal at output `y` and velocity `v`; `play` is the stop operator's state.
    pub(super) fn eval(&self, y: f64, v: f64, play: &mut f64) -> f64 {
        match *self {
            LoopSignal::Stop(r) => {
                *play = play.clamp(y - r, y + r);
                (y - *play) / r
            }
            LoopSignal::Sign(v0) => (v / v0).tanh(),
            LoopSignal::Viscous(vs) => v / vs,
            LoopSignal::Stribeck(v0, vs) => (v / v0).tanh() * Self::stribeck_decay(v, vs),
            LoopSignal::Power(m, r, p) => ((y - m) / r).powi(p),
            LoopSignal::Mixed(m, r, vs, p, q) => ((y - m) / r).powi(p) * (v / vs).powi(q),
        }
    }

    /// The Stribeck peak's decay with speed, `exp(-(v / vs)^2)`.
    pub(super) fn stribeck_decay(v: f64, vs: f64) -> f64 {
        (-(v / vs).powi(2)).exp()
    }

    /// For a Stribeck peak at `signals[q]`, the index of an earlier Coulomb sign of the same
    /// `v0`: its value `tanh(v / v0)` is the peak's first factor, computed once per step.
    pub(super) fn shared_sign(signals: &[LoopSignal], q: usize) -> Option<usize> {
        match signals[q] {
            LoopSignal::Stribeck(v0, _) => signals[..q]
                .iter()
                .position(|s| matches!(*s, LoopSignal::Sign(u) if u == v0)),
            _ => None,
        }
    }

    /// Whether the signal is a dissipative force whose weight has a known sign: a stop
    /// operator (elastic-plastic element), Coulomb friction and its Stribeck peak oppose the
    /// motion, so their force acts against the displacement or the velocity. Viscous and
    /// stiffening terms stay free (the refitted linear dynamics share them).
    pub(super) fn dissipative(&self) -> bool {
        matches!(
            self,
            LoopSignal::Stop(_) | LoopSignal::Sign(_) | LoopSignal::Stribeck(..)
        )
    }
}
