//! The networks' losses on plain values, with their gradients with respect to the network's
//! outputs, for the plain engine's training ([`super::backprop`]): the same terms and weights
//! as [`NetData::loss`] (burn's graph), tested equal to it and to its autodiff gradient.

use super::{DZ_MAX_M, DZ_MIN_M, MASK_LOGIT_WIDTH, NetData, NetKind, SOFT_IOU_EPS};
use crate::{Result, TactileError};

fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// ln(1 + e^z) without overflow.
fn softplus(z: f64) -> f64 {
    z.max(0.0) + (-z.abs()).exp().ln_1p()
}

/// The sign as burn's `abs` differentiates it (0 at 0).
fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

impl NetData {
    /// The loss of the network outputs `out` (`[b, C, rows, cols]` for the inputs `idx`)
    /// against the targets of `target_idx`, as [`NetData::loss`], and its gradient with respect
    /// to `out` (same layout).
    pub fn loss_and_grad(
        &self,
        out: &[f32],
        idx: &[usize],
        target_idx: &[usize],
    ) -> Result<(f64, Vec<f32>)> {
        let n = self.rows * self.cols;
        let b = idx.len();
        let c = out.len() / (b * n).max(1);
        if b == 0 || target_idx.len() != b || out.len() != b * c * n {
            return Err(TactileError::Input(format!(
                "{} network outputs for {b} samples of {n} pixels and {} targets",
                out.len(),
                target_idx.len()
            )));
        }
        if let Some(&i) = target_idx.iter().find(|&&i| i >= self.len()) {
            return Err(TactileError::Input(format!(
                "target sample {i} of {}",
                self.len()
            )));
        }
        let mut grad = vec![0.0f32; out.len()];
        let loss = match self.kind {
            NetKind::Perception => {
                if c < 3 {
                    return Err(TactileError::Input(format!(
                        "the perception network gives [p_x, p_y, dz], got {c} channels"
                    )));
                }
                self.perception_loss(out, target_idx, c, &mut grad)
            }
            NetKind::Rendering => self.rendering_loss(out, target_idx, c, &mut grad),
        };
        Ok((loss, grad))
    }

    fn perception_loss(
        &self,
        out: &[f32],
        target_idx: &[usize],
        c: usize,
        grad: &mut [f32],
    ) -> f64 {
        let n = self.rows * self.cols;
        let b = target_idx.len();
        let all = (b * n) as f64;
        let width = f64::from(MASK_LOGIT_WIDTH);
        let scale = DZ_MAX_M - DZ_MIN_M;
        let (mut mse, mut force, mut iou_term, mut bce) = (0.0, 0.0, 0.0, 0.0);
        for (s, &t) in target_idx.iter().enumerate() {
            let dz = &out[(s * c + 2) * n..(s * c + 3) * n];
            let target = &self.target[t * n..(t + 1) * n];
            let mask = &self.mask[t * n..(t + 1) * n];
            let g = &mut grad[(s * c + 2) * n..(s * c + 3) * n];
            let err = |p: usize| f64::from(dz[p]) - f64::from(target[p]);
            let mut gd = vec![0.0f64; n];
            for (p, gp) in gd.iter_mut().enumerate() {
                let e = err(p);
                mse += e * e;
                *gp = 2.0 * e / all;
            }
            if self.force_loss_weight > 0.0 {
                let w = &self.force_weight[t * n..(t + 1) * n];
                let fe = scale * (0..n).map(|p| err(p) * f64::from(w[p])).sum::<f64>();
                force += fe * fe;
                let k = f64::from(self.force_loss_weight) * 2.0 * fe * scale / b as f64;
                gd.iter_mut()
                    .zip(w)
                    .for_each(|(a, &wp)| *a += k * f64::from(wp));
            }
            let logit = |p: usize| (1.0 - f64::from(dz[p])) / width;
            if self.iou_loss_weight > 0.0 {
                let (mut inter, mut sum) = (0.0, 0.0);
                for p in 0..n {
                    let (q, m) = (sigmoid(logit(p)), f64::from(mask[p]));
                    inter += q * m;
                    sum += q + m;
                }
                let eps = f64::from(SOFT_IOU_EPS);
                let (i, u) = (inter + eps, sum - inter + eps);
                iou_term += 1.0 - i / u;
                let k = f64::from(self.iou_loss_weight) / b as f64;
                for (p, gp) in gd.iter_mut().enumerate() {
                    let (q, m) = (sigmoid(logit(p)), f64::from(mask[p]));
                    let d_iou = (m * u - i * (1.0 - m)) / (u * u);
                    *gp += -k * d_iou * q * (1.0 - q) * (-1.0 / width);
                }
            }
            if self.mask_loss_weight > 0.0 {
                let k = f64::from(self.mask_loss_weight) / all;
                for (p, gp) in gd.iter_mut().enumerate() {
                    let (z, m) = (logit(p), f64::from(mask[p]));
                    bce += softplus(z) - z * m;
                    *gp += k * (sigmoid(z) - m) * (-1.0 / width);
                }
            }
            g.iter_mut().zip(&gd).for_each(|(a, &v)| *a = v as f32);
        }
        mse / all
            + f64::from(self.force_loss_weight) * force / b as f64
            + f64::from(self.iou_loss_weight) * iou_term / b as f64
            + f64::from(self.mask_loss_weight) * bce / all
    }

    fn rendering_loss(&self, out: &[f32], target_idx: &[usize], c: usize, grad: &mut [f32]) -> f64 {
        let n = self.rows * self.cols;
        let b = target_idx.len();
        let tc = self.target_channels;
        let eps = 1e-6;
        let (mut in_mask, mut outside) = (0.0f64, 0.0f64);
        for &t in target_idx {
            let m: f64 = self.mask[t * n..(t + 1) * n]
                .iter()
                .map(|&v| f64::from(v))
                .sum();
            in_mask += m;
            outside += n as f64 - m;
        }
        let (wc, wb) = (1.0 / (in_mask + eps), 0.1 / (outside + eps));
        let neutral_n = (b * c * n) as f64;
        let (mut contact, mut bg, mut neutral) = (0.0, 0.0, 0.0);
        for (s, &t) in target_idx.iter().enumerate() {
            let mask = &self.mask[t * n..(t + 1) * n];
            for ch in 0..c.min(tc) {
                let o = &out[(s * c + ch) * n..(s * c + ch + 1) * n];
                let target = &self.target[(t * tc + ch) * n..(t * tc + ch + 1) * n];
                let g = &mut grad[(s * c + ch) * n..(s * c + ch + 1) * n];
                for p in 0..n {
                    let pred = f64::from(o[p]).tanh();
                    let m = f64::from(mask[p]);
                    let e = pred - f64::from(target[p]);
                    contact += e.abs() * m;
                    bg += e.abs() * (1.0 - m);
                    neutral += (pred * (1.0 - m)).abs();
                    let d = sign(e) * (m * wc + (1.0 - m) * wb)
                        + 0.02 * sign(pred * (1.0 - m)) * (1.0 - m) / neutral_n;
                    g[p] = (d * (1.0 - pred * pred)) as f32;
                }
            }
        }
        contact / (in_mask + eps) + 0.1 * bg / (outside + eps) + 0.02 * neutral / neutral_n
    }
}
