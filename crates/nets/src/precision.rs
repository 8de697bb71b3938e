//! Half-precision training, the way PyTorch's automatic mixed precision does it: the
//! convolutions (the UNets, the critic, VGG16) run in f16 or bf16 on copies of the weights,
//! everything between them (light maps, shading, softmax, normalisation, the losses) stays f32,
//! and the optimiser keeps f32 master weights.
//!
//! A network computes in its weights' precision and answers in its input's ([`UNet::forward`],
//! [`PatchGan::forward`], [`Vgg16::features`]), so casting a network's weights is all a caller
//! does. Gradients reach the f32 weights through the cast, whose backward casts them back.
//!
//! [`UNet::forward`]: crate::unet::UNet::forward
//! [`PatchGan::forward`]: crate::loss::PatchGan::forward
//! [`Vgg16::features`]: crate::vgg::Vgg16::features

use std::fmt;

use burn::module::{Module, ModuleMapper, Param};
use burn::prelude::*;
use burn::tensor::{DType, FloatDType};
use serde::{Deserialize, Serialize};

use crate::NetsError;

/// The precision the networks' convolutions train in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Everything in f32.
    #[default]
    F32,
    /// IEEE half: 5 exponent bits, so the loss is scaled to keep small gradients from
    /// flushing to zero (the trainer's dynamic loss scale).
    F16,
    /// bfloat16: f32's exponent range with 8 bits of mantissa; needs no loss scale.
    Bf16,
}

impl Precision {
    pub fn dtype(self) -> FloatDType {
        match self {
            Precision::F32 => FloatDType::F32,
            Precision::F16 => FloatDType::F16,
            Precision::Bf16 => FloatDType::BF16,
        }
    }

    pub fn is_half(self) -> bool {
        self != Precision::F32
    }

    /// f16's exponent range is narrow enough that gradients need a loss scale.
    pub fn needs_loss_scale(self) -> bool {
        self == Precision::F16
    }

    /// Whether `device` computes in this precision; the error names the device and the way out.
    pub fn check(self, device: &Device) -> Result<(), NetsError> {
        let dtype: DType = self.dtype().into();
        if device.supports_dtype(dtype) {
            return Ok(());
        }
        Err(NetsError::Device(format!(
            "precision = \"{self}\": the training device {device:?} does not compute in {dtype:?} \
             (Burn's wgpu backend has f16 only where the GPU offers shader-f16, and no bf16); \
             use precision = \"f16\" or \"f32\""
        )))
    }
}

impl std::str::FromStr for Precision {
    type Err = NetsError;

    fn from_str(s: &str) -> Result<Self, NetsError> {
        match s.trim().to_ascii_lowercase().as_str() {
            "f32" => Ok(Precision::F32),
            "f16" => Ok(Precision::F16),
            "bf16" => Ok(Precision::Bf16),
            other => Err(NetsError::Config(format!(
                "precision '{other}': use f32, f16 or bf16"
            ))),
        }
    }
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
            Precision::Bf16 => "bf16",
        })
    }
}

/// `module` with every float parameter cast to `dtype`, the parameter ids kept. On an autodiff
/// device the cast is part of the graph: gradients flow back to the original parameters.
pub fn cast_module<M: Module>(module: M, dtype: FloatDType) -> M {
    struct Cast(FloatDType);
    impl ModuleMapper for Cast {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let dtype = self.0;
            param.map(|t| t.cast(dtype))
        }
    }
    module.map(&mut Cast(dtype))
}

/// A copy of `module` to run a pass in `precision`: cast for f16/bf16, as is for f32. Cast once
/// per backward pass: the cast is part of that pass's graph, and Burn keeps no graph across a
/// backward.
pub fn in_precision<M: Module>(module: &M, precision: Precision) -> M {
    if precision.is_half() {
        cast_module(module.clone(), precision.dtype())
    } else {
        module.clone()
    }
}

/// Runs `f` on `x` cast to `compute`, and casts its answer back to `x`'s precision: a network's
/// weights set the precision it computes in, its caller's tensors the one it answers in.
pub(crate) fn compute_in(
    x: Tensor<4>,
    compute: DType,
    f: impl FnOnce(Tensor<4>) -> Tensor<4>,
) -> Tensor<4> {
    let io = x.dtype();
    if io == compute {
        return f(x);
    }
    f(x.cast(FloatDType::from(compute))).cast(FloatDType::from(io))
}

#[cfg(test)]
mod tests {
    use burn::module::ModuleVisitor;

    use super::*;
    use crate::unet::UNetConfig;

    fn ids_and_dtypes<M: Module>(m: &M) -> Vec<(String, DType)> {
        struct Collect(Vec<(String, DType)>);
        impl ModuleVisitor for Collect {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                self.0.push((param.id.to_string(), param.val().dtype()));
            }
        }
        let mut c = Collect(Vec::new());
        m.visit(&mut c);
        c.0
    }

    #[test]
    fn casting_keeps_the_parameter_ids() {
        let device = Device::flex();
        let net = UNetConfig::new(3, 2, vec![4, 8]).init(&device);
        let before = ids_and_dtypes(&net);
        let after = ids_and_dtypes(&cast_module(net, FloatDType::F16));
        assert_eq!(before.len(), after.len());
        for ((id_a, dt_a), (id_b, dt_b)) in before.iter().zip(&after) {
            assert_eq!(id_a, id_b);
            assert_eq!(*dt_a, DType::F32);
            assert_eq!(*dt_b, DType::F16);
        }
    }

    #[test]
    fn a_half_unet_answers_in_f32_close_to_the_f32_one() {
        let device = Device::flex();
        device.seed(3);
        let net = UNetConfig::new(3, 2, vec![4, 8]).init(&device);
        let x = Tensor::<4>::random([1, 3, 8, 8], burn::tensor::Distribution::Default, &device);
        let full = net.forward(x.clone());
        for precision in [Precision::F16, Precision::Bf16] {
            let half = cast_module(net.clone(), precision.dtype()).forward(x.clone());
            assert_eq!(half.dtype(), DType::F32, "{precision}");
            let err = (half - full.clone()).abs().max().into_scalar::<f32>();
            let scale = full.clone().abs().max().into_scalar::<f32>();
            // bf16 keeps 8 mantissa bits (relative step 2^-8), f16 11.
            let bound = if precision == Precision::F16 {
                4e-3
            } else {
                3e-2
            };
            assert!(err <= bound * scale, "{precision}: {err} vs {scale}");
            assert!(
                err > 0.0,
                "{precision}: the half network computed nothing in half"
            );
        }
    }

    #[test]
    fn precision_names_parse_and_print() {
        #[derive(Deserialize)]
        struct Doc {
            p: Precision,
        }
        for (text, p) in [
            ("f32", Precision::F32),
            ("f16", Precision::F16),
            ("bf16", Precision::Bf16),
        ] {
            let doc: Doc = toml::from_str(&format!("p = \"{text}\"")).unwrap();
            assert_eq!(doc.p, p);
            assert_eq!(p.to_string(), text);
            assert_eq!(text.parse::<Precision>().unwrap(), p);
        }
        let err = "f8".parse::<Precision>().unwrap_err().to_string();
        assert!(err.contains("f8") && err.contains("bf16"), "{err}");
        assert!(toml::from_str::<Doc>("p = \"f8\"").is_err());
    }

    #[test]
    fn flex_computes_in_every_precision() {
        for p in [Precision::F32, Precision::F16, Precision::Bf16] {
            p.check(&Device::flex()).unwrap();
        }
    }
}
