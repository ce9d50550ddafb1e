//! DeepSets encoder (Zaheer et al. 2017; dissertation eq 6.10): `rho(scale * sum_i phi(p_i))`,
//! invariant to the order of the set's elements and defined for sets of any size, the empty
//! one included (`rho(0)`).
//!
//! A batch of sets is one `[points, input]` tensor with a count per set; the per-set sums are
//! one product with a `[sets, points]` membership matrix, so the sum and its gradient need no
//! scatter.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::error::{LearnError, Result};
use crate::mlp::{Mlp, MlpConfig};

/// Shape of a [`DeepSets`] encoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeepSetsConfig {
    /// The point-wise network phi (input -> d_h).
    pub phi: MlpConfig,
    /// The set network rho (d_h -> d_g).
    pub rho: MlpConfig,
    /// Factor on the sum (e.g. the area each point stands for, so the sum is an integral).
    pub scale: f64,
}

impl DeepSetsConfig {
    /// Builds phi and rho with weights drawn from `seed` (phi from `seed`, rho from `seed + 1`).
    pub fn init(&self, device: &Device, seed: u64) -> Result<DeepSets> {
        if self.phi.output != self.rho.input {
            return Err(LearnError::Config(format!(
                "DeepSets: phi gives {} features but rho takes {}",
                self.phi.output, self.rho.input
            )));
        }
        Ok(DeepSets {
            phi: self.phi.init(device, seed),
            rho: self.rho.init(device, seed.wrapping_add(1)),
            scale: self.scale,
        })
    }
}

/// `rho(scale * sum phi(p))` per set.
#[derive(Module, Debug)]
pub struct DeepSets {
    /// Point-wise network.
    pub phi: Mlp,
    /// Set network.
    pub rho: Mlp,
    scale: f64,
}

impl DeepSets {
    /// Encodes the sets stacked in `points` (`[sum(counts), input]`, set after set) into
    /// `[counts.len(), d_g]`. `points` is ignored (may be `None`) when every set is empty.
    pub fn forward(
        &self,
        points: Option<Tensor<2>>,
        counts: &[usize],
        device: &Device,
    ) -> Tensor<2> {
        let total: usize = counts.iter().sum();
        let sets = counts.len();
        let width = self.rho_input();
        let pooled = match points {
            Some(p) if total > 0 => {
                let mut member = vec![0.0f32; sets * total];
                let mut at = 0;
                for (s, &c) in counts.iter().enumerate() {
                    for j in at..at + c {
                        member[s * total + j] = self.scale as f32;
                    }
                    at += c;
                }
                let m = Tensor::<2>::from_data(TensorData::new(member, [sets, total]), device);
                m.matmul(self.phi.forward(p))
            }
            _ => Tensor::<2>::zeros([sets, width], device),
        };
        self.rho.forward(pooled)
    }

    /// The factor on the sum.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    fn rho_input(&self) -> usize {
        self.rho.layers.first().map_or(0, |l| l.weight.dims()[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{cpu, cpu_autodiff, values};

    fn config() -> DeepSetsConfig {
        DeepSetsConfig {
            phi: MlpConfig::relu(3, &[16], 8),
            rho: MlpConfig::relu(8, &[16], 5),
            scale: 0.25,
        }
    }

    fn pts(v: &[[f32; 3]], device: &Device) -> Tensor<2> {
        let flat: Vec<f32> = v.iter().flatten().copied().collect();
        Tensor::from_data(TensorData::new(flat, [v.len(), 3]), device)
    }

    #[test]
    fn order_of_points_does_not_matter_and_sets_stay_apart() {
        let device = cpu();
        let enc = config().init(&device, 3).unwrap();
        let a: Vec<[f32; 3]> = (0..7)
            .map(|i| [(i as f32).sin(), (i as f32 * 0.3).cos(), i as f32 * 0.1])
            .collect();
        let b = [[0.5f32, -0.2, 0.1], [0.0, 0.3, -0.4]];
        let one = values(enc.forward(Some(pts(&a, &device)), &[7], &device));
        let mut rev = a.clone();
        rev.reverse();
        rev.swap(0, 3);
        let other = values(enc.forward(Some(pts(&rev, &device)), &[7], &device));
        for (x, y) in one.iter().zip(&other) {
            assert!((x - y).abs() < 1e-5, "{one:?} vs {other:?}");
        }
        // Batched with another set, each set's code is what it gets alone.
        let mut both = a.clone();
        both.extend(b);
        let batch = values(enc.forward(Some(pts(&both, &device)), &[7, 2], &device));
        let alone_b = values(enc.forward(Some(pts(&b, &device)), &[2], &device));
        for k in 0..5 {
            assert!((batch[k] - one[k]).abs() < 1e-5);
            assert!((batch[5 + k] - alone_b[k]).abs() < 1e-5);
        }
        // Duplicating every point doubles the sum: not the same code (a sum, not a mean).
        let mut twice = a.clone();
        twice.extend(a.iter().copied());
        let dup = values(enc.forward(Some(pts(&twice, &device)), &[14], &device));
        assert!(dup.iter().zip(&one).any(|(x, y)| (x - y).abs() > 1e-4));
    }

    #[test]
    fn empty_set_is_rho_of_zero() {
        let device = cpu();
        let enc = config().init(&device, 5).unwrap();
        let empty = values(enc.forward(None, &[0], &device));
        let rho0 = values(enc.rho.forward(Tensor::<2>::zeros([1, 8], &device)));
        assert_eq!(empty, rho0);
        // An empty set beside a full one.
        let b = [[0.5f32, -0.2, 0.1]];
        let mixed = values(enc.forward(Some(pts(&b, &device)), &[0, 1], &device));
        assert_eq!(&mixed[..5], &rho0[..]);
    }

    #[test]
    fn mismatched_widths_are_refused() {
        let mut c = config();
        c.rho.input = 9;
        assert!(c.init(&cpu(), 0).is_err());
    }

    #[test]
    fn point_gradient_matches_finite_differences() {
        let device = cpu_autodiff();
        let enc = config().init(&device, 11).unwrap();
        let base: Vec<f32> = (0..15).map(|i| (i as f32 * 0.61).sin()).collect();
        let loss = |v: &[f32], track: bool| {
            let mut x = Tensor::<2>::from_data(TensorData::new(v.to_vec(), [5, 3]), &device);
            if track {
                x = x.require_grad();
            }
            let out = enc.forward(Some(x.clone()), &[3, 2], &device);
            ((out.clone() * out).sum(), x)
        };
        let pairs =
            crate::gradcheck::gradient_pairs(&base, &(0..15).collect::<Vec<_>>(), 1e-2, loss)
                .unwrap();
        for p in pairs {
            assert!(p.agrees(3e-3, 3e-2), "coordinate {}: {p:?}", p.index);
        }
    }
}
