//! A U-Net encoder-decoder on images (Ronneberger et al. 2015): at each level a 3 x 3
//! convolution, a normalisation and a nonlinearity; 2 x 2 max pooling down, a 2 x 2 stride-2
//! transposed convolution up, skip connections by channel concatenation, and a 1 x 1 output
//! convolution. Fully convolutional: any height and width divisible by 2^(levels - 1).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, GroupNorm, GroupNormConfig, PaddingConfig2d};
use burn::tensor::module::max_pool2d;
use burn::tensor::ops::MaxPoolOptions;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{LearnError, Result};
use crate::init::seeded_init;
use crate::mlp::Activation;

/// The normalisation after each convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum UNetNorm {
    /// Batch normalisation (batch statistics while training on an autodiff device, running
    /// statistics otherwise).
    Batch,
    /// Group normalisation with this many groups (each level's width must divide by it).
    Group(usize),
}

/// Shape of a [`UNet`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UNetConfig {
    /// Input channels.
    pub input: usize,
    /// Output channels (the 1 x 1 output convolution, no activation).
    pub output: usize,
    /// Channels of each level from the full resolution down; the last is the bottleneck.
    pub widths: Vec<usize>,
    /// Normalisation after each convolution.
    pub norm: UNetNorm,
    /// Nonlinearity after each normalisation.
    pub activation: Activation,
}

impl UNetConfig {
    /// Checks the configuration: at least two levels, positive widths, group counts that
    /// divide every width.
    pub fn validate(&self) -> Result<()> {
        if self.widths.len() < 2 || self.input == 0 || self.output == 0 {
            return Err(LearnError::Config(format!(
                "a U-Net needs input and output channels and at least 2 levels, got {self:?}"
            )));
        }
        if let Some(w) = self.widths.iter().find(|&&w| w == 0) {
            return Err(LearnError::Config(format!("U-Net level width {w}")));
        }
        if let UNetNorm::Group(g) = self.norm
            && (g == 0 || self.widths.iter().any(|w| !w.is_multiple_of(g)))
        {
            return Err(LearnError::Config(format!(
                "{g} groups do not divide the U-Net widths {:?}",
                self.widths
            )));
        }
        Ok(())
    }

    /// The factor by which height and width must be divisible.
    pub fn divisor(&self) -> usize {
        1 << (self.widths.len() - 1)
    }

    /// Builds the network with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> Result<UNet> {
        self.validate()?;
        let block = |c_in: usize, c_out: usize| ConvBlock {
            conv: Conv2dConfig::new([c_in, c_out], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device),
            batch: matches!(self.norm, UNetNorm::Batch)
                .then(|| BatchNormConfig::new(c_out).init(device)),
            group: match self.norm {
                UNetNorm::Group(g) => Some(GroupNormConfig::new(g, c_out).init(device)),
                UNetNorm::Batch => None,
            },
            activation: self.activation.code(),
        };
        let w = &self.widths;
        let mut down = vec![block(self.input, w[0])];
        for l in 1..w.len() {
            down.push(block(w[l - 1], w[l]));
        }
        let mut up = Vec::new();
        let mut merge = Vec::new();
        for l in (1..w.len()).rev() {
            up.push(
                ConvTranspose2dConfig::new([w[l], w[l - 1]], [2, 2])
                    .with_stride([2, 2])
                    .init(device),
            );
            merge.push(block(2 * w[l - 1], w[l - 1]));
        }
        let head = Conv2dConfig::new([w[0], self.output], [1, 1]).init(device);
        Ok(seeded_init(
            UNet {
                down,
                up,
                merge,
                head,
            },
            seed,
        ))
    }
}

/// Convolution 3 x 3, normalisation, nonlinearity.
#[derive(Module, Debug)]
pub struct ConvBlock {
    /// The 3 x 3 convolution (padding 1).
    pub conv: Conv2d,
    /// Batch normalisation, when the network uses it.
    pub batch: Option<BatchNorm>,
    /// Group normalisation, when the network uses it.
    pub group: Option<GroupNorm>,
    activation: usize,
}

impl ConvBlock {
    /// The nonlinearity after the normalisation.
    pub fn activation(&self) -> Activation {
        Activation::from_code(self.activation)
    }

    /// Applies the block to `[batch, channels, height, width]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = self.conv.forward(x);
        let x = match (&self.batch, &self.group) {
            (Some(b), _) => b.forward(x),
            (None, Some(g)) => g.forward(x),
            (None, None) => x,
        };
        Activation::from_code(self.activation).apply(x)
    }
}

/// The U-Net (see the module documentation).
#[derive(Module, Debug)]
pub struct UNet {
    /// Encoder blocks, full resolution first; the last is the bottleneck.
    pub down: Vec<ConvBlock>,
    /// Upsampling from each coarse level, bottleneck first.
    pub up: Vec<ConvTranspose2d>,
    /// Blocks after each concatenation with the skip connection, coarse first.
    pub merge: Vec<ConvBlock>,
    /// 1 x 1 output convolution.
    pub head: Conv2d,
}

impl UNet {
    /// Maps `[batch, input, height, width]` to `[batch, output, height, width]`; height and
    /// width must be divisible by 2^(levels - 1) (checked by [`UNet::check_input`]).
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut skips = Vec::with_capacity(self.down.len());
        let mut x = x;
        for (l, block) in self.down.iter().enumerate() {
            if l > 0 {
                x = max_pool2d(x, MaxPoolOptions::new([2, 2]).with_stride([2, 2]));
            }
            x = block.forward(x);
            skips.push(x.clone());
        }
        skips.pop();
        for (up, merge) in self.up.iter().zip(&self.merge) {
            let skip = skips.pop().expect("one skip per decoder level");
            x = merge.forward(Tensor::cat(vec![up.forward(x), skip], 1));
        }
        self.head.forward(x)
    }

    /// An error unless `[channels, height, width]` fits the network.
    pub fn check_input(&self, channels: usize, height: usize, width: usize) -> Result<()> {
        let c_in = self.down[0].conv.weight.dims()[1];
        let div = 1usize << (self.down.len() - 1);
        if channels != c_in
            || height == 0
            || width == 0
            || !height.is_multiple_of(div)
            || !width.is_multiple_of(div)
        {
            return Err(LearnError::Data(format!(
                "a U-Net input must be {c_in} channels with height and width divisible by {div}, \
                 got {channels} x {height} x {width}"
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{cpu, cpu_autodiff, values};
    use burn::tensor::TensorData;

    fn config(norm: UNetNorm, activation: Activation) -> UNetConfig {
        UNetConfig {
            input: 3,
            output: 2,
            widths: vec![4, 8, 16],
            norm,
            activation,
        }
    }

    #[test]
    fn shapes_and_bad_configs() {
        let d = cpu();
        for norm in [UNetNorm::Batch, UNetNorm::Group(2)] {
            let net = config(norm, Activation::Gelu).init(&d, 1).unwrap();
            let x = Tensor::<4>::zeros([2, 3, 8, 12], &d);
            assert_eq!(net.forward(x).dims(), [2, 2, 8, 12]);
            assert!(net.check_input(3, 8, 12).is_ok());
            assert!(net.check_input(3, 6, 12).is_err());
            assert!(net.check_input(4, 8, 12).is_err());
        }
        let mut c = config(UNetNorm::Group(3), Activation::Relu);
        assert!(c.init(&d, 1).is_err());
        c.widths = vec![4];
        assert!(c.init(&d, 1).is_err());
    }

    /// Same seed, same weights and outputs; another seed, other outputs.
    #[test]
    fn seeded() {
        let d = cpu();
        let x = Tensor::<4>::from_data(
            TensorData::new(
                (0..96).map(|i| (i as f32 * 0.37).sin()).collect(),
                [1, 3, 4, 8],
            ),
            &d,
        );
        let c = config(UNetNorm::Group(4), Activation::Gelu);
        let a = values(c.init(&d, 7).unwrap().forward(x.clone()));
        let b = values(c.init(&d, 7).unwrap().forward(x.clone()));
        let e = values(c.init(&d, 8).unwrap().forward(x));
        assert_eq!(a, b);
        assert_ne!(a, e);
    }

    /// Every input pixel reaches the loss (the gradient by autodiff is non-zero almost
    /// everywhere): pooling, upsampling and the skips are wired.
    #[test]
    fn gradient_reaches_every_input_pixel() {
        let d = cpu_autodiff();
        let net = config(UNetNorm::Batch, Activation::Relu)
            .init(&d, 3)
            .unwrap();
        let x = Tensor::<4>::from_data(
            TensorData::new(
                (0..2 * 3 * 8 * 8)
                    .map(|i| ((i * 7919) % 97) as f32 / 97.0)
                    .collect(),
                [2, 3, 8, 8],
            ),
            &d,
        )
        .require_grad();
        let y = net.forward(x.clone()).powi_scalar(2).mean();
        let gx = values(x.grad(&y.backward()).expect("input gradient"));
        let nonzero = gx.iter().filter(|v| v.abs() > 0.0).count();
        assert!(nonzero > gx.len() * 9 / 10, "{nonzero} of {}", gx.len());
    }
}
