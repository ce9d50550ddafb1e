//! Autodiff gradients against central finite differences: the check every custom layer
//! and loss of the toolkit runs in its tests.

use crate::values;
use burn::tensor::Tensor;

/// One input coordinate's gradient, by autodiff and by central differences.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GradientPair {
    /// Index of the coordinate in the flattened input.
    pub index: usize,
    /// The autodiff gradient.
    pub autodiff: f64,
    /// `(loss(x + h e_i) - loss(x - h e_i)) / 2h`.
    pub finite_difference: f64,
}

impl GradientPair {
    /// Whether the two agree within `abs + rel * max(|autodiff|, |finite difference|)`.
    pub fn agrees(&self, abs: f64, rel: f64) -> bool {
        let (a, f) = (self.autodiff, self.finite_difference);
        (a - f).abs() < abs + rel * a.abs().max(f.abs())
    }
}

/// Gradient pairs of the scalar `loss` at `base`, coordinates `indices`, step `h`.
///
/// `loss(values, track)` builds the input tensor from `values` (with `require_grad` when
/// `track`), and returns the scalar loss (a one-element tensor) and that input. `None`
/// when the input was not tracked, so it has no gradient.
pub fn gradient_pairs<const D: usize>(
    base: &[f32],
    indices: &[usize],
    h: f32,
    loss: impl Fn(&[f32], bool) -> (Tensor<1>, Tensor<D>),
) -> Option<Vec<GradientPair>> {
    let (l, x) = loss(base, true);
    let grad = values(x.grad(&l.backward())?);
    let scalar = |v: &[f32]| f64::from(values(loss(v, false).0)[0]);
    Some(
        indices
            .iter()
            .map(|&k| {
                let (mut up, mut down) = (base.to_vec(), base.to_vec());
                up[k] += h;
                down[k] -= h;
                GradientPair {
                    index: k,
                    autodiff: f64::from(grad[k]),
                    finite_difference: (scalar(&up) - scalar(&down)) / (2.0 * f64::from(h)),
                }
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu_autodiff;
    use burn::tensor::TensorData;

    /// On `sum(x^3)` the pairs are `3 x^2` both ways, and a wrong gradient is caught.
    #[test]
    fn cubic_gradient_and_a_wrong_one() {
        let device = cpu_autodiff();
        let base = [0.5f32, -1.0, 2.0];
        let cube = |v: &[f32], track: bool| {
            let mut x = Tensor::<1>::from_data(TensorData::new(v.to_vec(), [3]), &device);
            if track {
                x = x.require_grad();
            }
            ((x.clone() * x.clone() * x.clone()).sum(), x)
        };
        let pairs = gradient_pairs(&base, &[0, 1, 2], 1e-2, cube).unwrap();
        for (p, x) in pairs.iter().zip(base) {
            let exact = 3.0 * f64::from(x).powi(2);
            assert!((p.autodiff - exact).abs() < 1e-5, "{p:?}");
            assert!(p.agrees(3e-3, 3e-2), "{p:?}");
        }
        // detach the input from the loss: autodiff sees 3 x^2 only through one factor
        let wrong = |v: &[f32], track: bool| {
            let mut x = Tensor::<1>::from_data(TensorData::new(v.to_vec(), [3]), &device);
            if track {
                x = x.require_grad();
            }
            (
                (x.clone() * x.clone().detach() * x.clone().detach()).sum(),
                x,
            )
        };
        let pairs = gradient_pairs(&base, &[2], 1e-2, wrong).unwrap();
        assert!(!pairs[0].agrees(3e-3, 3e-2), "{:?}", pairs[0]);
    }
}
