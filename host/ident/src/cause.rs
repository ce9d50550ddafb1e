//! The fixed vocabulary of discrepancy causes.

use serde::{Deserialize, Serialize};

/// What a model gets wrong, by mechanism. The names (and only these) appear in reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cause {
    /// The residual is consistent with measurement noise: no extension earns its keep.
    None,
    /// Rate-independent memory: the response depends on the direction of travel and on the
    /// extrema since the last reversal, so loading and unloading trace different loops.
    Hysteresis,
    /// Viscoelastic behaviour: the response depends on how fast the input moves, the output
    /// creeps or relaxes while the input is held.
    RateDependence,
    /// Stiffness falls with accumulated cycles or with the largest deformation seen so far
    /// (crease wear, Mullins-like damage).
    Softening,
    /// The measured response lags the model's response, by a dead time, a first-order lag or both.
    Latency,
    /// A constant bias in a channel (an output sensor or an input channel).
    Offset,
    /// A proportional scale error in a channel or actuator (an input that is really `g * u`).
    Gain,
    /// A static input-output mismatch that none of the others explain, such as stiffening that
    /// grows with pressure or strain.
    Nonlinearity,
    /// Dry friction on a moving part: a force that flips with the direction of the velocity
    /// (Coulomb), grows with speed (viscous) and peaks at breakaway (Stribeck).
    Friction,
    /// The model is wrong by many times the noise and no candidate explains it: a verdict, not
    /// a candidate.
    Unexplained,
}

impl Cause {
    /// Every verdict, `None` first.
    pub const ALL: [Cause; 10] = [
        Cause::None,
        Cause::Hysteresis,
        Cause::RateDependence,
        Cause::Softening,
        Cause::Latency,
        Cause::Offset,
        Cause::Gain,
        Cause::Nonlinearity,
        Cause::Friction,
        Cause::Unexplained,
    ];

    /// The causes tried on every record (friction joins them where a record has a position to
    /// take the velocity of, see `Prepared::candidates`).
    pub const CANDIDATES: [Cause; 7] = [
        Cause::Hysteresis,
        Cause::RateDependence,
        Cause::Softening,
        Cause::Latency,
        Cause::Offset,
        Cause::Gain,
        Cause::Nonlinearity,
    ];

    /// The report name (snake case).
    pub fn name(self) -> &'static str {
        match self {
            Cause::None => "none",
            Cause::Hysteresis => "hysteresis",
            Cause::RateDependence => "rate_dependence",
            Cause::Softening => "softening",
            Cause::Latency => "latency",
            Cause::Offset => "offset",
            Cause::Gain => "gain",
            Cause::Nonlinearity => "nonlinearity",
            Cause::Friction => "friction",
            Cause::Unexplained => "unexplained",
        }
    }

    /// One-sentence definition, printed in reports.
    pub fn definition(self) -> &'static str {
        match self {
            Cause::None => "the residual is consistent with noise",
            Cause::Hysteresis => {
                "rate-independent memory: loading and unloading follow different, direction-dependent loops"
            }
            Cause::RateDependence => {
                "viscoelastic: the response depends on the input rate, with creep and relaxation under holds"
            }
            Cause::Softening => {
                "stiffness falls with accumulated cycles or with the largest past deformation"
            }
            Cause::Latency => {
                "the response lags the input, by a dead time and/or a first-order lag"
            }
            Cause::Offset => "a constant bias in an output or input channel",
            Cause::Gain => "a proportional scale error in an input channel or actuator",
            Cause::Nonlinearity => {
                "a static mismatch the others do not explain, e.g. pressure-dependent stiffening"
            }
            Cause::Friction => {
                "dry friction: a force that flips with the direction of motion (Coulomb, viscous, Stribeck)"
            }
            Cause::Unexplained => {
                "the model misses by many times the noise and no candidate explains it"
            }
        }
    }

    /// The model extension fitted for this cause.
    pub fn extension(self) -> &'static str {
        match self {
            Cause::None => "none",
            Cause::Hysteresis => {
                "Prandtl-Ishlinskii play operators on each drive (non-negative weights)"
            }
            Cause::RateDependence => "Prony series on each drive (non-negative moduli)",
            Cause::Softening => {
                "damage variable: stiffness scaled by cycle count and peak deformation"
            }
            Cause::Latency => "dead time plus first-order lag on the model output",
            Cause::Offset => "affine channel correction: output bias plus input-channel biases",
            Cause::Gain => "input-channel scale factors",
            Cause::Nonlinearity => "low-order (complete cubic) polynomial correction in the inputs",
            Cause::Friction => {
                "Coulomb level per direction (smoothed sign of the velocity), viscous and Stribeck terms"
            }
            Cause::Unexplained => "none",
        }
    }

    /// Parses a report name.
    pub fn from_name(name: &str) -> Option<Cause> {
        Cause::ALL.into_iter().find(|c| c.name() == name)
    }
}

impl std::fmt::Display for Cause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_the_issue_vocabulary() {
        let names: Vec<&str> = Cause::ALL.iter().map(|c| c.name()).collect();
        assert_eq!(
            names,
            [
                "none",
                "hysteresis",
                "rate_dependence",
                "softening",
                "latency",
                "offset",
                "gain",
                "nonlinearity",
                "friction",
                "unexplained"
            ]
        );
        for c in Cause::ALL {
            assert_eq!(Cause::from_name(c.name()), Some(c));
            assert_eq!(
                serde_json::to_string(&c).unwrap(),
                format!("\"{}\"", c.name())
            );
        }
    }
}
