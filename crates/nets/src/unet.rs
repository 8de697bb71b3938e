//! The UNet every network of the paper is built from (Total Relighting uses UNets for f_N, f_A,
//! f_S and f_R): two 3×3 convolutions per level, average-pool down, nearest up, skip
//! concatenation, a 1×1 head. Channel widths are configurable so CPU tests run a tiny one.

use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::PaddingConfig2d;
use burn::prelude::*;
use burn::tensor::activation::leaky_relu;
use burn::tensor::module::{avg_pool2d, interpolate};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions};

use crate::precision::compute_in;

/// Negative slope of every hidden activation.
const LEAK: f64 = 0.2;

#[derive(Config, Debug)]
pub struct UNetConfig {
    pub in_channels: usize,
    pub out_channels: usize,
    /// Channels per level, finest first; the image is halved between levels.
    pub widths: Vec<usize>,
}

impl UNetConfig {
    pub fn init(&self, device: &Device) -> UNet {
        let w = &self.widths;
        let mut down = Vec::with_capacity(w.len());
        for (level, &width) in w.iter().enumerate() {
            let input = if level == 0 {
                self.in_channels
            } else {
                w[level - 1]
            };
            down.push(ConvBlock::new(input, width, device));
        }
        let up = (0..w.len().saturating_sub(1))
            .map(|level| ConvBlock::new(w[level + 1] + w[level], w[level], device))
            .collect();
        let head = Conv2dConfig::new([w[0], self.out_channels], [1, 1]).init(device);
        UNet { down, up, head }
    }
}

/// Images given to a UNet with `levels` levels must have sides divisible by this.
pub fn size_multiple(levels: usize) -> usize {
    1 << levels.saturating_sub(1)
}

#[derive(Module, Debug)]
pub struct ConvBlock {
    first: Conv2d,
    second: Conv2d,
}

impl ConvBlock {
    fn new(input: usize, output: usize, device: &Device) -> ConvBlock {
        let conv = |i, o| {
            Conv2dConfig::new([i, o], [3, 3])
                .with_padding(PaddingConfig2d::Same)
                .init(device)
        };
        ConvBlock {
            first: conv(input, output),
            second: conv(output, output),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = leaky_relu(self.first.forward(x), LEAK);
        leaky_relu(self.second.forward(x), LEAK)
    }
}

#[derive(Module, Debug)]
pub struct UNet {
    down: Vec<ConvBlock>,
    up: Vec<ConvBlock>,
    head: Conv2d,
}

impl UNet {
    pub fn levels(&self) -> usize {
        self.down.len()
    }

    /// `x`: [batch, in_channels, H, W] with H and W multiples of [`size_multiple`]; returns
    /// [batch, out_channels, H, W] without an output activation (each network picks its own).
    /// Computes in its weights' precision and answers in `x`'s ([`crate::precision`]).
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        compute_in(x, self.head.weight.val().dtype(), |x| self.layers(x))
    }

    fn layers(&self, x: Tensor<4>) -> Tensor<4> {
        let mut skips = Vec::with_capacity(self.down.len());
        let mut x = x;
        for (level, block) in self.down.iter().enumerate() {
            if level > 0 {
                x = avg_pool2d(x, AvgPoolOptions::new([2, 2]).with_stride([2, 2]));
            }
            x = block.forward(x);
            skips.push(x.clone());
        }
        skips.pop();
        for block in self.up.iter().rev() {
            let skip = skips.pop().expect("one skip per up block");
            let [_, _, h, w] = skip.dims();
            let up = interpolate(
                x,
                InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([h, w]),
            );
            x = block.forward(Tensor::cat(vec![up, skip], 1));
        }
        self.head.forward(x)
    }
}
