//! Extensions inside the dynamics of the state-space baseline: a hysteretic restoring force, dry
//! friction and stiffening act where the input force does, so each enters as a signal computed
//! from the baseline's free-run output and filtered by the baseline's own response to that
//! input (`B_k`, `C`, `D_k`). The filtered columns stay linear in the extension's weights, so
//! they are fitted jointly with the output map by least squares on the free-run error.

use super::features::{Features, PLAY_WIDTHS};
use super::loop_signal::LoopSignal;
use super::prepared::{Prepared, span};
use crate::cause::Cause;
use crate::signal;
use crate::statespace::StateSpace;

/// Half-width of dry friction's pre-sliding stop operator inside the dynamics, as a fraction of
/// the output's range: the displacement over which a sticking contact's force builds up
/// before it slides (micrometres in metal contacts, a fraction of a millimetre in seals; a
/// few tenths of a percent of a stroke). It is the boundary between the two classes of
/// rate-independent loops: a force that saturates within it is friction's, one that goes on
/// growing over wider excursions (the stops of `PLAY_WIDTHS`, 0.5-28 %) is hysteresis'; see
/// the README ("Telling friction from hysteresis").
const PRESLIDING: f64 = 0.0025;

/// Friction's most flexible variant: narrower pre-sliding stops beside `PRESLIDING` (a stiffer
/// contact, down to a Coulomb force that reverses at once), still inside friction's class.
const FLEXIBLE_PRESLIDING: [f64; 2] = [0.0005, 0.001];

/// The factor that turns a dissipative signal into a force of non-negative weight acting at
/// input `k`: `-sign(G_k)`, with `G_k` the direction in which that input moves the output. A
/// force opposing the output's motion enters against it. `G_k` is the median of the
/// baseline's step response from input `k` over the first `horizon` samples (a quarter of the
/// record's longest trial), not its static gain `C (I - A)^-1 B_k + D_k`: that limit lies beyond the
/// record, and a slow pole fitted from it does not pin it down. A chamber record's baseline had
/// a pole at 0.99996 (a time constant of 240 s against a 20 s record) and a static gain of
/// -2e-7 m/Pa, while its step response stayed between +3.6e-7 and +4.4e-7 over the record:
/// every hysteresis weight stayed at the bound zero, and the fit with free signs explained
/// 66 % of the error. Another chamber baseline had a pole at 1.004, and its step response,
/// +3e-7..4e-7 over the first third of the record, diverged to -1e-4 at its end: the slowest
/// modes are the ones the record determines least, so the horizon is a quarter of it (two to
/// ten periods of the battery's oscillators), and the median ignores the first samples'
/// transient. The covariance of input and output is no substitute either: on a two-mass record
/// driven near its resonance it pointed the wrong way. `None` when the gain is zero or not
/// finite (the weight stays free).
pub(super) fn restoring_sign(
    ss: &StateSpace,
    c_row: &[f64],
    d_k: f64,
    k: usize,
    horizon: usize,
) -> Option<f64> {
    let n = ss.order();
    let mut x = StateSpace::force_entry(&ss.a, &ss.b, ss.entry_lag)
        .columns(k, 1)
        .into_owned();
    let mut step = d_k;
    let mut steps = Vec::with_capacity(horizon.max(1));
    for _ in 0..horizon.max(1) {
        steps.push(step);
        step += (0..n).map(|j| c_row[j] * x[j]).sum::<f64>();
        x = &ss.a * x;
    }
    let mid = steps.len() / 2;
    let (_, g, _) = steps.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    (g.is_finite() && *g != 0.0).then(|| -g.signum())
}

impl Prepared<'_> {
    /// The signals of `cause` inside the dynamics of channel `c`, with their names, or `None`
    /// when the cause acts at the output.
    pub(super) fn loop_signals(&self, cause: Cause, c: usize) -> Option<Vec<(LoopSignal, String)>> {
        if cause == Cause::Nonlinearity && self.actuator_pole.get().is_some() {
            // the actuator variant acts on the inputs, outside the loop (see `features`)
            return None;
        }
        let x = &self.channels[c].yhat;
        let name = &self.rec.outputs[c].name;
        let mut signals = Vec::new();
        // The most flexible variant of each (while a further cause is tested against it),
        // each inside its own class: hysteresis with a narrower loop (0.5 % of the range),
        // friction with stiffer pre-sliding (narrower stops), stiffening to the fifth power.
        // Neither variant reaches into the other's widths: a Preisach plane contains a relay
        // of zero width, which is a Coulomb force, so a hysteresis allowed every width absorbs
        // a friction beside it and the pair cannot be named.
        let rich = self.flexible.get() == Some(cause);
        match cause {
            Cause::Hysteresis => {
                // elastic-perfectly-plastic elements (stop operators) on the displacement:
                // a Prandtl-Ishlinskii restoring force whose loop grows with the excursion
                // after a reversal, over 1.5-28 % of the range (from 0.5 % in the flexible
                // variant); what saturates within friction's pre-sliding is friction's
                let range = span(x);
                let first = if rich { 0 } else { 1 };
                for &w in &PLAY_WIDTHS[first..] {
                    let r = w * range;
                    signals.push((
                        LoopSignal::Stop(r),
                        format!("stop operator r={r:.4} on {name}"),
                    ));
                }
            }
            Cause::Friction => {
                let (_, v0) = self.model_velocity(c);
                let vs = 5.0 * v0;
                signals.push((
                    LoopSignal::Sign(v0),
                    format!("Coulomb friction from d{name}/dt (model)"),
                ));
                signals.push((
                    LoopSignal::Viscous(vs),
                    format!("viscous friction at {vs:.4} /s of {name}"),
                ));
                signals.push((
                    LoopSignal::Stribeck(v0, vs),
                    format!("Stribeck peak of d{name}/dt"),
                ));
                // the direction of motion held while the mass sticks: an elastic-plastic
                // element with `PRESLIDING` of the stroke as pre-sliding
                let range = span(x);
                let r = PRESLIDING * range;
                signals.push((
                    LoopSignal::Stop(r),
                    format!("Coulomb friction with pre-sliding r={r:.4} on {name}"),
                ));
                if rich {
                    for w in FLEXIBLE_PRESLIDING {
                        let r = w * range;
                        signals.push((
                            LoopSignal::Stop(r),
                            format!("pre-sliding r={r:.4} on {name}"),
                        ));
                    }
                }
            }
            Cause::Nonlinearity => {
                // stiffening of the restoring force: quadratic and cubic in the displacement
                let (m, _) = signal::mean_std(x);
                let r = 0.5 * span(x);
                let powers: &[i32] = if rich { &[2, 3, 4, 5] } else { &[2, 3] };
                for &p in powers {
                    signals.push((
                        LoopSignal::Power(m, r, p),
                        format!("restoring force ({name} - mean)^{p}"),
                    ));
                }
                if rich {
                    // a stiffening where the output is not the deformed element (a second
                    // mass): the complete cubic in output and velocity
                    let (_, v0) = self.model_velocity(c);
                    let vs = 20.0 * v0;
                    for (p, q) in [(1, 1), (2, 1), (1, 2), (0, 3)] {
                        signals.push((
                            LoopSignal::Mixed(m, r, vs, p, q),
                            format!("({name} - mean)^{p} (d{name}/dt)^{q}"),
                        ));
                    }
                }
            }
            _ => return None,
        }
        Some(signals)
    }

    /// Features of `cause` for channel `c` inside the dynamics, or `None` when the cause acts
    /// at the output (the static features apply).
    pub(super) fn dynamic_features(
        &self,
        ss: &StateSpace,
        cause: Cause,
        c: usize,
    ) -> Option<Features> {
        let order = ss.order();
        if order == 0 {
            return None;
        }
        let rec = self.rec;
        let starts = &rec.segment_starts;
        let ch = &self.channels[c];
        let x = &ch.yhat;
        let (v, _) = self.model_velocity(c);
        let specs = self.loop_signals(cause, c)?;
        let mut signals: Vec<(Vec<f64>, &String)> = Vec::new();
        for (sig, label) in &specs {
            let mut out = vec![0.0; x.len()];
            for (s, e) in signal::segments(starts, x.len()) {
                let mut play = x[s];
                for i in s..e {
                    out[i] = sig.eval(x[i], v[i], &mut play);
                }
            }
            signals.push((out, label));
        }
        let mut cols = Vec::new();
        let mut names = Vec::new();
        let mut nonneg = Vec::new();
        for &k in &rec.drives {
            let d_k = ch.theta[order + k];
            let sign = restoring_sign(ss, &ch.theta[..order], d_k, k, self.sign_horizon());
            for ((sig, label), (spec, _)) in signals.iter().zip(&specs) {
                let mut col = ss.filter(sig, k, &ch.theta[..order], d_k, starts);
                let constrained = spec.dissipative() && sign.is_some();
                if let (true, Some(s)) = (constrained, sign) {
                    col.iter_mut().for_each(|v| *v *= s);
                }
                cols.push(col);
                nonneg.push(constrained);
                names.push(format!("{label} as {}", rec.inputs[k].name));
            }
        }
        Some((cols, names, nonneg))
    }

    /// A quarter of the rows of the record's longest trial (segment), the horizon of
    /// [`restoring_sign`].
    pub(super) fn sign_horizon(&self) -> usize {
        signal::segments(&self.rec.segment_starts, self.rec.len())
            .iter()
            .map(|(s, e)| (e - s) / 4)
            .max()
            .unwrap_or(1)
            .max(1)
    }

    /// Velocity of the baseline's free-run output of channel `c` and its sign-smoothing scale
    /// (5 % of the 95th percentile of its magnitude on training rows).
    pub fn model_velocity(&self, c: usize) -> (Vec<f64>, f64) {
        let rec = self.rec;
        let v = signal::central_rate(&self.channels[c].yhat, &rec.time_s, &rec.segment_starts, 1);
        let mut a: Vec<f64> = (0..v.len())
            .filter(|&i| self.train[i])
            .map(|i| v[i].abs())
            .collect();
        let k = (a.len() * 95 / 100).min(a.len().saturating_sub(1));
        let v0 = if a.is_empty() {
            1.0
        } else {
            let (_, p, _) = a.select_nth_unstable_by(k, |x, y| x.total_cmp(y));
            (0.05 * *p).max(1e-300)
        };
        (v, v0)
    }
}
