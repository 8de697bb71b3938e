//! The image-to-image ResNet of the paper's synthetic-to-real network f_Ā (section 4.6: two
//! down-sampling layers, nine residual blocks, two up-sampling layers, 32 channels first and
//! doubled per down-sampling). Instance normalisation, as in the ResNet generators it follows
//! (Johnson et al. 2016, pix2pixHD), because adaptation batches are small. Up-sampling is
//! nearest-neighbour then a 3×3 convolution, which avoids transposed convolutions' checkerboard.

use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, InstanceNorm, InstanceNormConfig, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::relu;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};

use crate::NetsError;

/// Down-sampling steps; image sides must be multiples of 2^this.
const DOWN: usize = 2;

#[derive(Config, Debug)]
pub struct ResNetConfig {
    pub in_channels: usize,
    pub out_channels: usize,
    /// Channels of the first layer; doubled by each down-sampling.
    #[config(default = 32)]
    pub base: usize,
    #[config(default = 9)]
    pub blocks: usize,
    /// Start the output layer at zero, so the network's output is 0 until it trains: a
    /// residual network added to a trained model starts as the model itself.
    #[config(default = true)]
    pub zero_output: bool,
}

impl ResNetConfig {
    pub fn validate(&self) -> Result<(), NetsError> {
        if self.base == 0 || self.base > 1024 || self.blocks > 64 {
            return Err(NetsError::Config(format!(
                "residual network base {} / blocks {}: give 1..=1024 channels and 0..=64 blocks \
                 (the paper: 32 and 9)",
                self.base, self.blocks
            )));
        }
        Ok(())
    }

    pub fn init(&self, device: &Device) -> Result<ResNet, NetsError> {
        self.validate()?;
        let conv = |i, o, k: usize, stride: usize| {
            Conv2dConfig::new([i, o], [k, k])
                .with_stride([stride, stride])
                .with_padding(PaddingConfig2d::Explicit(k / 2, k / 2, k / 2, k / 2))
                .init(device)
        };
        let norm = |c| InstanceNormConfig::new(c).init(device);
        let b = self.base;
        let top = b << DOWN;
        let mut head = Conv2dConfig::new([b, self.out_channels], [7, 7])
            .with_padding(PaddingConfig2d::Explicit(3, 3, 3, 3));
        if self.zero_output {
            head = head.with_initializer(Initializer::Zeros);
        }
        Ok(ResNet {
            stem: conv(self.in_channels, b, 7, 1),
            stem_norm: norm(b),
            down: (0..DOWN)
                .map(|k| ConvNorm {
                    conv: conv(b << k, b << (k + 1), 3, 2),
                    norm: norm(b << (k + 1)),
                })
                .collect(),
            blocks: (0..self.blocks)
                .map(|_| ResBlock {
                    a: ConvNorm {
                        conv: conv(top, top, 3, 1),
                        norm: norm(top),
                    },
                    b: ConvNorm {
                        conv: conv(top, top, 3, 1),
                        norm: norm(top),
                    },
                })
                .collect(),
            up: (0..DOWN)
                .map(|k| ConvNorm {
                    conv: conv(top >> k, top >> (k + 1), 3, 1),
                    norm: norm(top >> (k + 1)),
                })
                .collect(),
            head: head.init(device),
        })
    }
}

/// Image sides given to a [`ResNet`] must be multiples of this.
pub const RESNET_SIZE_MULTIPLE: usize = 1 << DOWN;

#[derive(Module, Debug)]
pub struct ConvNorm {
    conv: Conv2d,
    norm: InstanceNorm,
}

impl ConvNorm {
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(self.norm.forward(self.conv.forward(x)))
    }
}

#[derive(Module, Debug)]
pub struct ResBlock {
    a: ConvNorm,
    b: ConvNorm,
}

#[derive(Module, Debug)]
pub struct ResNet {
    stem: Conv2d,
    stem_norm: InstanceNorm,
    down: Vec<ConvNorm>,
    blocks: Vec<ResBlock>,
    up: Vec<ConvNorm>,
    head: Conv2d,
}

impl ResNet {
    /// [B, in, H, W] → [B, out, H, W]; H and W multiples of [`RESNET_SIZE_MULTIPLE`].
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = relu(self.stem_norm.forward(self.stem.forward(x)));
        for d in &self.down {
            x = d.forward(x);
        }
        for block in &self.blocks {
            // The second half has no activation after the sum's normalisation, as in ResNet
            // generators: the block learns a residual of either sign.
            let h = block.a.forward(x.clone());
            let h = block.b.norm.forward(block.b.conv.forward(h));
            x = x + h;
        }
        for u in &self.up {
            let [_, _, h, w] = x.dims();
            x = interpolate(
                x,
                InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([h * 2, w * 2]),
            );
            x = u.forward(x);
        }
        self.head.forward(x)
    }
}
