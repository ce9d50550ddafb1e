//! Sequence encoder: a linear embedding with sinusoidal positions, then pre-norm Transformer
//! encoder blocks.

use burn::module::Module;
use burn::nn::activation::ActivationConfig;
use burn::nn::transformer::{
    TransformerEncoder, TransformerEncoderConfig, TransformerEncoderInput,
};
use burn::nn::{
    Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig, PositionalEncoding,
    PositionalEncodingConfig,
};
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::init::seeded_init;

/// Shape of a [`SequenceEncoder`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceEncoderConfig {
    /// Features per time step.
    pub input: usize,
    /// Embedding width.
    pub d_model: usize,
    /// Attention heads per block.
    pub n_heads: usize,
    /// Hidden width of each block's feed-forward layer.
    pub d_ff: usize,
    /// Number of encoder blocks.
    pub n_layers: usize,
    /// Longest sequence the positional table covers.
    pub max_len: usize,
}

impl SequenceEncoderConfig {
    /// Builds the encoder with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> SequenceEncoder {
        let embed = LinearConfig::new(self.input, self.d_model)
            .with_initializer(Initializer::Zeros)
            .init(device);
        let positions = PositionalEncodingConfig::new(self.d_model)
            .with_max_sequence_size(self.max_len)
            .init(device);
        // Pre-norm blocks (LayerNorm before attention and feed-forward, inside the residual),
        // no dropout, ReLU in the feed-forward as in the common reference implementation.
        let blocks =
            TransformerEncoderConfig::new(self.d_model, self.d_ff, self.n_heads, self.n_layers)
                .with_dropout(0.0)
                .with_norm_first(true)
                .with_activation(ActivationConfig::Relu)
                .with_initializer(Initializer::Zeros)
                .init(device);
        // With pre-norm blocks the residual stream is never normalised, so a final norm keeps
        // the head's input on a fixed scale.
        let norm = LayerNormConfig::new(self.d_model).init(device);
        seeded_init(
            SequenceEncoder {
                embed,
                positions,
                blocks,
                norm,
            },
            seed,
        )
    }
}

/// Linear embedding + positional encoding + Transformer encoder blocks + final LayerNorm.
#[derive(Module, Debug)]
pub struct SequenceEncoder {
    embed: Linear,
    positions: PositionalEncoding,
    blocks: TransformerEncoder,
    norm: LayerNorm,
}

impl SequenceEncoder {
    /// Encodes `[batch, steps, input]` into `[batch, steps, d_model]`.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let h = self.positions.forward(self.embed.forward(x));
        let h = self.blocks.forward(TransformerEncoderInput::new(h));
        self.norm.forward(h)
    }

    /// The layers, for plain-array inference (`crate::infer_sequence`).
    pub(crate) fn parts(
        &self,
    ) -> (
        &Linear,
        &PositionalEncoding,
        &TransformerEncoder,
        &LayerNorm,
    ) {
        (&self.embed, &self.positions, &self.blocks, &self.norm)
    }

    /// The embedding of the last step, `[batch, d_model]`: a summary of the whole history.
    pub fn forward_last(&self, x: Tensor<3>) -> Tensor<2> {
        let h = self.forward(x);
        let [b, s, d] = h.dims();
        h.slice([0..b, s - 1..s, 0..d]).reshape([b, d])
    }
}
