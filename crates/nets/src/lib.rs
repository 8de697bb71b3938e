//! The relighting networks of Yeh et al. 2022 on Burn 0.22: UNets for f_N, f_A, f_S, f_R,
//! device-side light maps, the losses of section 4.2 (with the perceptual loss when the user
//! supplies VGG16 weights), evaluation metrics (LPIPS likewise), and safetensors I/O.
//!
//! Tensors are NCHW f32; the convolutions can train in f16 or bf16 ([`precision`]). Networks
//! are backend-agnostic: [`device::select`] picks Burn's flex CPU backend or wgpu.

pub mod adapt;
pub mod device;
pub mod lightmap;
pub mod loss;
pub mod metrics;
pub mod precision;
pub mod relight;
pub mod resnet;
pub mod unet;
pub mod vgg;

use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleMapper, Param, ParamId};
use burn::prelude::Tensor;
use burn::store::{ModuleSnapshot, SafetensorsStore};

pub use adapt::{AdaptTarget, AdaptWeights, Adapter};
pub use lightmap::{LightBatch, LightInput};
pub use loss::{critic_loss, generator_loss, LossWeights, PatchGan, PatchGanConfig, Targets};
pub use precision::{cast_module, in_precision, Precision};
pub use relight::{Decomposition, RelightConfig, RelightNet, Relit, RenderNet};
pub use resnet::{ResNet, ResNetConfig, RESNET_SIZE_MULTIPLE};
pub use vgg::{perceptual_loss, Lpips, Vgg16};

#[derive(Debug, thiserror::Error)]
pub enum NetsError {
    #[error("network config: {0}")]
    Config(String),
    #[error("tensor shapes: {0}")]
    Shape(String),
    #[error("{0}")]
    Device(String),
    #[error("weights {path}: {reason}")]
    Weights { path: PathBuf, reason: String },
}

/// The optimizer of every network here: Adam with Burn's defaults (β 0.9/0.999, ε 1e-5), as
/// `bench/train_torch.py` mirrors it.
pub fn optimizer() -> burn::optim::ModuleOptimizer {
    burn::optim::AdamConfig::new().init()
}

/// Gives a module's parameters ids that depend only on their order in the module and on
/// `namespace`, and initialises them. Burn keys optimizer state by parameter id and draws fresh random ids at init, so
/// without this an Adam state saved by one process matches no parameter of the next.
pub fn stable_param_ids<M: Module>(module: M, namespace: u32) -> M {
    struct Renumber {
        base: u64,
        next: u64,
    }
    impl ModuleMapper for Renumber {
        fn map_float<const D: usize>(&mut self, mut param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            // Burn initialises parameters lazily, on first use; do it now, so the random draws
            // happen where the caller seeded (and locked) the generator.
            let _ = param.val();
            param.id = ParamId::from(self.base | self.next);
            self.next += 1;
            param
        }
    }
    module.map(&mut Renumber {
        base: u64::from(namespace) << 32,
        next: 0,
    })
}

/// Writes a module's parameters as safetensors (named by their module paths).
pub fn save_weights<M: Module + ModuleSnapshot>(module: &M, path: &Path) -> Result<(), NetsError> {
    let mut store = SafetensorsStore::from_file(path).overwrite(true);
    module
        .save_into(&mut store)
        .map_err(|e| NetsError::Weights {
            path: path.to_owned(),
            reason: e.to_string(),
        })
}

/// Loads parameters saved by [`save_weights`] into `module`; every parameter must be present
/// with its shape, so weights of another network config are refused, not half-applied.
pub fn load_weights<M: Module + ModuleSnapshot>(
    mut module: M,
    path: &Path,
) -> Result<M, NetsError> {
    let err = |reason: String| NetsError::Weights {
        path: path.to_owned(),
        reason,
    };
    if !path.is_file() {
        return Err(err("no such file".into()));
    }
    let mut store = SafetensorsStore::from_file(path);
    let result = module
        .load_from(&mut store)
        .map_err(|e| err(e.to_string()))?;
    if !result.is_success() || !result.missing.is_empty() {
        return Err(err(format!(
            "does not match this network config ({} errors, {} missing, e.g. {:?}); check the widths and render_net it was trained with",
            result.errors.len(),
            result.missing.len(),
            result.missing.first().map(|m| &m.0)
        )));
    }
    Ok(module)
}
