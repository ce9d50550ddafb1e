//! Multilayer perceptron: linear layers with an activation between them, linear output.

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::{Device, Tensor, activation};
use serde::{Deserialize, Serialize};

use crate::init::seeded_init;

/// The nonlinearity between hidden layers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Activation {
    /// max(0, x).
    Relu,
    /// Gaussian error linear unit (tanh-free exact form).
    Gelu,
    /// Hyperbolic tangent.
    Tanh,
}

impl Activation {
    /// Applies the nonlinearity elementwise.
    pub fn apply<const D: usize>(self, x: Tensor<D>) -> Tensor<D> {
        match self {
            Self::Relu => activation::relu(x),
            Self::Gelu => activation::gelu(x),
            Self::Tanh => activation::tanh(x),
        }
    }

    pub(crate) fn code(self) -> usize {
        match self {
            Self::Relu => 0,
            Self::Gelu => 1,
            Self::Tanh => 2,
        }
    }

    pub(crate) fn from_code(code: usize) -> Self {
        match code {
            1 => Self::Gelu,
            2 => Self::Tanh,
            _ => Self::Relu,
        }
    }
}

/// Shape of an [`Mlp`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MlpConfig {
    /// Input features.
    pub input: usize,
    /// Width of each hidden layer, in order.
    pub hidden: Vec<usize>,
    /// Output features (linear, no activation).
    pub output: usize,
    /// Nonlinearity after each hidden layer.
    pub activation: Activation,
}

impl MlpConfig {
    /// A ReLU network `input -> hidden... -> output`.
    pub fn relu(input: usize, hidden: &[usize], output: usize) -> Self {
        Self {
            input,
            hidden: hidden.to_vec(),
            output,
            activation: Activation::Relu,
        }
    }

    /// Builds the network with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> Mlp {
        let widths: Vec<usize> = std::iter::once(self.input)
            .chain(self.hidden.iter().copied())
            .chain(std::iter::once(self.output))
            .collect();
        let layers = widths
            .windows(2)
            .map(|w| {
                LinearConfig::new(w[0], w[1])
                    .with_initializer(Initializer::Zeros)
                    .init(device)
            })
            .collect();
        seeded_init(
            Mlp {
                layers,
                activation: self.activation.code(),
            },
            seed,
        )
    }
}

/// A multilayer perceptron; works on any leading batch dimensions.
#[derive(Module, Debug)]
pub struct Mlp {
    /// Hidden layers followed by the output layer.
    pub layers: Vec<Linear>,
    activation: usize,
}

impl Mlp {
    /// The nonlinearity between hidden layers.
    pub fn activation(&self) -> Activation {
        Activation::from_code(self.activation)
    }

    /// Maps `[..., input]` to `[..., output]`.
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        let act = Activation::from_code(self.activation);
        let last = self.layers.len() - 1;
        let mut x = x;
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(x);
            if i < last {
                x = act.apply(x);
            }
        }
        x
    }
}
