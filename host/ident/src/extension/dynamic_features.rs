//! Extensions inside the dynamics of the state-space baseline: a hysteretic restoring force, dry
//! friction and stiffening act where the input force does, so each enters as a signal computed
//! from the baseline's free-run output and filtered by the baseline's own response to that
//! input (`B_k`, `C`, `D_k`). The filtered columns stay linear in the extension's weights, so
//! they are fitted jointly with the output map by least squares on the free-run error.

use super::features::{Features, PLAY_WIDTHS};
use super::prepared::{Prepared, span};
use crate::cause::Cause;
use crate::signal;
use crate::statespace::StateSpace;

impl Prepared<'_> {
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
        let name = &rec.outputs[c].name;
        let mut signals: Vec<(Vec<f64>, String)> = Vec::new();
        match cause {
            Cause::Hysteresis => {
                // elastic-perfectly-plastic elements (stop operators) on the displacement:
                // a Prandtl-Ishlinskii restoring force
                let range = span(x);
                for &w in &PLAY_WIDTHS {
                    let r = w * range;
                    let p = signal::play(x, starts, r);
                    signals.push((
                        x.iter().zip(&p).map(|(a, b)| a - b).collect(),
                        format!("stop operator r={r:.4} on {name}"),
                    ));
                }
            }
            Cause::Friction => {
                let (v, v0) = self.model_velocity(c);
                let vs = 5.0 * v0;
                let sgn: Vec<f64> = v.iter().map(|s| (s / v0).tanh()).collect();
                signals.push((
                    sgn.clone(),
                    format!("Coulomb friction from d{name}/dt (model)"),
                ));
                signals.push((
                    v.iter().map(|s| s / vs).collect(),
                    format!("viscous friction at {vs:.4} /s of {name}"),
                ));
                signals.push((
                    sgn.iter()
                        .zip(&v)
                        .map(|(g, s)| g * (-(s / vs).powi(2)).exp())
                        .collect(),
                    format!("Stribeck peak of d{name}/dt"),
                ));
            }
            Cause::Nonlinearity => {
                // stiffening of the restoring force: quadratic and cubic in the displacement
                let (m, _) = signal::mean_std(x);
                let r = 0.5 * span(x);
                for p in [2, 3] {
                    signals.push((
                        x.iter().map(|v| ((v - m) / r).powi(p)).collect(),
                        format!("restoring force ({name} - mean)^{p}"),
                    ));
                }
            }
            _ => return None,
        }
        let mut cols = Vec::new();
        let mut names = Vec::new();
        for &k in &rec.drives {
            let d_k = ch.theta[order + k];
            for (sig, label) in &signals {
                cols.push(ss.filter(sig, k, &ch.theta[..order], d_k, starts));
                names.push(format!("{label} as {}", rec.inputs[k].name));
            }
        }
        let nonneg = vec![false; cols.len()];
        Some((cols, names, nonneg))
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
