//! A trained model applied to one image: load it from a run or checkpoint directory, pad the
//! image to the UNet's size multiple, and return the relit image with its intermediates.

use std::path::{Path, PathBuf};

use burn::prelude::*;
use lightfarm_nets::{load_weights, Adapter, LightBatch, LightInput, RelightNet, ResNetConfig};

use crate::adapt::checkpoint::{AdapterFile, ADAPTER_FILE, ADAPTER_JSON};

use crate::config::NetConfig;
use crate::data::input_scale;
use crate::lights::Lighting;
use crate::train::{latest_checkpoint, MODEL_FILE, NET_FILE};
use crate::TrainError;

pub struct Model {
    pub net: RelightNet,
    /// Set for a model adapted to real photos: f_Ā refines the albedo (or the relit image).
    pub adapter: Option<Adapter>,
    pub config: NetConfig,
    pub device: Device,
    /// The checkpoint directory the weights came from.
    pub dir: PathBuf,
}

/// Finds the model in `path`: a run directory (its newest checkpoint), a checkpoint directory,
/// or its `model.safetensors`.
pub fn resolve_model_dir(path: &Path) -> Result<PathBuf, TrainError> {
    let missing = || {
        TrainError::Input(format!(
            "--model {}: no model there; give a run directory (with checkpoints/), a checkpoint \
             directory, or its {MODEL_FILE}",
            path.display()
        ))
    };
    if path.is_file() {
        return path.parent().map(Path::to_owned).ok_or_else(missing);
    }
    if path.join(MODEL_FILE).is_file() {
        return Ok(path.to_owned());
    }
    latest_checkpoint(path)?.ok_or_else(missing)
}

/// The network in checkpoint directory `dir` (its `net.json` and weights) on `device`.
pub fn load_net(dir: &Path, device: &Device) -> Result<(RelightNet, NetConfig), TrainError> {
    let net_path = dir.join(NET_FILE);
    let text = std::fs::read_to_string(&net_path).map_err(|e| TrainError::io(&net_path, e))?;
    let config: NetConfig = serde_json::from_str(&text).map_err(|e| {
        TrainError::Input(format!(
            "{}: not a network description ({e})",
            net_path.display()
        ))
    })?;
    let net = config
        .relight()
        .init(device)
        .map_err(|e| TrainError::Config(format!("{}: {e}", net_path.display())))?;
    let net =
        load_weights(net, &dir.join(MODEL_FILE)).map_err(|e| TrainError::Input(e.to_string()))?;
    Ok((net, config))
}

/// The synthetic-to-real adapter of an adapted checkpoint (`lightfarm adapt`), if `dir` has one.
fn load_adapter(dir: &Path, device: &Device) -> Result<Option<Adapter>, TrainError> {
    let json = dir.join(ADAPTER_JSON);
    if !json.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&json).map_err(|e| TrainError::io(&json, e))?;
    let shape: AdapterFile = serde_json::from_str(&text).map_err(|e| {
        TrainError::Input(format!(
            "{}: not an adapter description ({e})",
            json.display()
        ))
    })?;
    let adapter = Adapter::with_config(
        shape.target,
        ResNetConfig::new(0, 0)
            .with_base(shape.base)
            .with_blocks(shape.blocks),
        device,
    )
    .map_err(|e| TrainError::Input(format!("{}: {e}", json.display())))?;
    load_weights(adapter, &dir.join(ADAPTER_FILE))
        .map(Some)
        .map_err(|e| TrainError::Input(e.to_string()))
}

pub fn load_model(path: &Path, device: &str) -> Result<Model, TrainError> {
    let dir = resolve_model_dir(path)?;
    let device =
        lightfarm_nets::device::select(device).map_err(|e| TrainError::Config(e.to_string()))?;
    let (net, config) = load_net(&dir, &device)?;
    let adapter = load_adapter(&dir, &device)?;
    Ok(Model {
        net,
        adapter,
        config,
        device,
        dir,
    })
}

/// The relit image and what the networks predicted on the way, row-major RGB at input size.
pub struct Relighting {
    pub width: usize,
    pub height: usize,
    pub relit: Vec<[f32; 3]>,
    pub normal: Vec<[f32; 3]>,
    pub normal_lens: Vec<[f32; 3]>,
    pub albedo: Vec<[f32; 3]>,
    pub diffuse: Vec<[f32; 3]>,
    pub specular: Vec<[f32; 3]>,
}

impl Relighting {
    /// The relit image with the paper's inset (diffuse and mirror ball under the target
    /// lighting) at the bottom right, when the image is large enough to hold it.
    pub fn with_inset(&self, lighting: &Lighting, camera_to_env: [[f32; 3]; 3]) -> Vec<[f32; 3]> {
        let (w, h) = (self.width, self.height);
        let mut out = self.relit.clone();
        if let Some(ball) = inset_ball(w, h) {
            let balls = light_balls(lighting, camera_to_env, ball);
            for y in 0..ball {
                for x in 0..2 * ball {
                    out[(h - ball + y) * w + (w - 2 * ball + x)] = balls[y * 2 * ball + x];
                }
            }
        }
        out
    }
}

/// Side in pixels of each of the inset's two light balls on a `width` × `height` image, or None
/// when the image is too small to hold them (then no inset is drawn).
pub fn inset_ball(width: usize, height: usize) -> Option<usize> {
    let ball = (height.min(width) / 5).max(8);
    (2 * ball <= width && ball <= height).then_some(ball)
}

/// Whether pixel (x, y) of a `width` × `height` relit image is covered by the inset that
/// [`Relighting::with_inset`] draws at the bottom right.
pub fn in_inset(width: usize, height: usize, x: usize, y: usize) -> bool {
    inset_ball(width, height).is_some_and(|b| x >= width - 2 * b && y >= height - b)
}

/// Normals as colours, (n + 1)/2, linearised so an sRGB PNG shows exactly those values.
pub fn normal_colours(normals: &[[f32; 3]]) -> Vec<[f32; 3]> {
    normals
        .iter()
        .map(|v| v.map(|c| crate::image_io::srgb_decode((c * 0.5 + 0.5).clamp(0.0, 1.0))))
        .collect()
}

impl Model {
    /// Relights `rgb` (linear, masked) under `lighting`; `camera_to_env` orients the light maps.
    /// The output is in the trainer's units: the HDRI scaled to mean luminance 1.
    pub fn relight(
        &self,
        rgb: &[[f32; 3]],
        mask: &[f32],
        width: usize,
        height: usize,
        lighting: &Lighting,
        camera_to_env: [[f32; 3]; 3],
    ) -> Result<Relighting, TrainError> {
        let m = self.config.relight().size_multiple();
        let (pw, ph) = (width.div_ceil(m) * m, height.div_ceil(m) * m);
        let scale = input_scale(rgb, mask);
        let mut input = vec![0f32; 3 * pw * ph];
        let mut mask_p = vec![0f32; pw * ph];
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                mask_p[y * pw + x] = mask[i];
                for c in 0..3 {
                    input[(c * ph + y) * pw + x] = rgb[i][c] * scale;
                }
            }
        }
        let d = &self.device;
        let input = Tensor::<4>::from_data(TensorData::new(input, [1, 3, ph, pw]), d);
        let mask_t = Tensor::<4>::from_data(TensorData::new(mask_p, [1, 1, ph, pw]), d);
        let light = LightBatch::new(
            &[LightInput {
                env: &lighting.env,
                scale: lighting.scale,
                camera_to_env,
            }],
            d,
        )
        .map_err(|e| TrainError::Input(e.to_string()))?;
        let out = match &self.adapter {
            None => self.net.forward(input, mask_t, &light),
            Some(adapter) => {
                let d = self.net.decompose(input.clone());
                let refined = adapter.refine(input.clone(), &d);
                adapter.relight(&self.net, input, mask_t, &light, &refined)
            }
        };
        let host = |t: Tensor<4>| -> Result<Vec<[f32; 3]>, TrainError> {
            let v: Vec<f32> = t
                .into_data()
                .try_to_vec::<f32>()
                .map_err(|e| TrainError::Input(format!("reading a result back: {e:?}")))?;
            Ok((0..width * height)
                .map(|i| {
                    let (x, y) = (i % width, i / width);
                    [0, 1, 2].map(|c| v[(c * ph + y) * pw + x])
                })
                .collect())
        };
        Ok(Relighting {
            width,
            height,
            relit: host(out.relit)?,
            normal: host(out.normal)?,
            normal_lens: host(out.normal_lens)?,
            albedo: host(out.albedo)?,
            diffuse: host(out.diffuse)?,
            specular: host(out.specular)?,
        })
    }
}

/// The paper's figure inset: a diffuse ball (irradiance/π × 0.8) and a mirror ball under the
/// target lighting, each `size` px, side by side, as seen by a camera with `camera_to_env`.
pub fn light_balls(
    lighting: &Lighting,
    camera_to_env: [[f32; 3]; 3],
    size: usize,
) -> Vec<[f32; 3]> {
    let mul = |n: [f32; 3]| -> [f32; 3] {
        [0, 1, 2].map(|i| {
            camera_to_env[i][0] * n[0] + camera_to_env[i][1] * n[1] + camera_to_env[i][2] * n[2]
        })
    };
    // The mirror ball samples the sharpest prefiltered map, so it shows the lighting's shape
    // at the resolution the network sees.
    let sharp = lighting.env.phong.last();
    let mut out = vec![[0f32; 3]; 2 * size * size];
    for y in 0..size {
        for x in 0..size {
            let px = (x as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let py = 1.0 - (y as f32 + 0.5) / size as f32 * 2.0;
            let r2 = px * px + py * py;
            if r2 >= 1.0 {
                continue;
            }
            let n = [px, py, (1.0 - r2).sqrt()];
            let e = lighting.env.sh.irradiance(mul(n));
            out[y * 2 * size + x] = e.map(|v| v.max(0.0) * 0.8 * lighting.scale);
            let r = [
                2.0 * n[2] * n[0],
                2.0 * n[2] * n[1],
                2.0 * n[2] * n[2] - 1.0,
            ];
            if let Some(map) = sharp {
                out[y * 2 * size + size + x] = map.lookup(mul(r)).map(|v| v * lighting.scale);
            }
        }
    }
    out
}
