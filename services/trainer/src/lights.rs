//! Prefiltered HDRIs for the light maps, computed once per HDRI and shared by every sample lit
//! by it (rotation and flip are folded into the per-sample lookup matrix instead).

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

use lightfarm_light::{EnvTransform, Hdri, PrefilteredEnv};
use lightfarm_scene::expand::LightingSample;
use lightfarm_scene::{AssetKind, Catalog};

use crate::TrainError;

/// Mean luminance every HDRI is scaled to: images and light maps of all HDRIs then share one
/// range, which the L1 losses need (a sunny map is 100× a dim interior).
pub const REFERENCE_LUMINANCE: f32 = 1.0;

/// One HDRI's prefiltered maps and the scale that normalises its mean luminance.
#[derive(Debug)]
pub struct Lighting {
    pub env: PrefilteredEnv,
    pub scale: f32,
}

impl Lighting {
    pub fn new(hdri: &Hdri) -> Lighting {
        let env = PrefilteredEnv::compute(hdri);
        let mean = Hdri::luminance(env.sh.mean_radiance());
        let scale = if mean > 0.0 && mean.is_finite() {
            REFERENCE_LUMINANCE / mean
        } else {
            1.0
        };
        Lighting { env, scale }
    }

    pub fn load(path: &Path) -> Result<Lighting, TrainError> {
        let hdri = Hdri::load(path).map_err(|e| TrainError::Input(format!("HDRI: {e}")))?;
        Ok(Lighting::new(&hdri))
    }
}

/// HDRIs by catalog id, prefiltered on first use.
pub struct LightCache {
    catalog: Catalog,
    cache: Mutex<HashMap<String, Arc<Lighting>>>,
}

impl LightCache {
    pub fn new(catalog: Catalog) -> LightCache {
        LightCache {
            catalog,
            cache: Mutex::new(HashMap::new()),
        }
    }

    pub fn get(&self, lighting: &LightingSample) -> Result<Arc<Lighting>, TrainError> {
        if let Some(l) = self
            .cache
            .lock()
            .map_err(|_| poisoned())?
            .get(&lighting.hdri)
        {
            return Ok(l.clone());
        }
        let asset = self
            .catalog
            .get(&lighting.hdri)
            .filter(|a| a.kind == AssetKind::Hdri)
            .ok_or_else(|| {
                TrainError::Input(format!(
                    "the samples use HDRI '{}', which the asset catalog does not have; train with \
                     the catalog the dataset was rendered from (`assets = \"path/catalog.toml\"`)",
                    lighting.hdri
                ))
            })?;
        if asset.blake3 != lighting.blake3 {
            return Err(TrainError::Input(format!(
                "HDRI '{}' in the catalog is not the one the samples were rendered with (blake3 \
                 {} vs {}); use the catalog the dataset was rendered from",
                lighting.hdri, asset.blake3, lighting.blake3
            )));
        }
        let started = std::time::Instant::now();
        let l = Arc::new(Lighting::load(&self.catalog.path_of(asset))?);
        tracing::info!(hdri = %lighting.hdri, ms = started.elapsed().as_millis() as u64, "prefiltered HDRI");
        self.cache
            .lock()
            .map_err(|_| poisoned())?
            .insert(lighting.hdri.clone(), l.clone());
        Ok(l)
    }
}

fn poisoned() -> TrainError {
    TrainError::Input("the light-map cache was poisoned by a panic in another thread".into())
}

/// Camera-space → env-local rotation for a sample: camera → world (the camera's basis), then
/// world → env (the HDRI's rotation and flip). `mirror` flips camera-space x, for samples the
/// data pipeline mirrors horizontally.
pub fn camera_to_env(
    camera_to_world: [[f64; 3]; 3],
    lighting: &LightingSample,
    mirror: bool,
) -> [[f32; 3]; 3] {
    let t = EnvTransform {
        rotation_deg: lighting.rotation_deg as f32,
        flip: lighting.flip,
    };
    let mut m = [[0f32; 3]; 3];
    for j in 0..3 {
        let col = [
            camera_to_world[0][j],
            camera_to_world[1][j],
            camera_to_world[2][j],
        ]
        .map(|v| v as f32);
        let e = t.world_to_env(col);
        let sign = if mirror && j == 0 { -1.0 } else { 1.0 };
        for i in 0..3 {
            m[i][j] = e[i] * sign;
        }
    }
    m
}

/// The rotation for a photograph relit under an HDRI: the camera looks down −Z at a subject
/// facing +Z, the world frame of the HDRI.
pub fn identity_camera(rotation_deg: f32, flip: bool) -> [[f32; 3]; 3] {
    let t = EnvTransform { rotation_deg, flip };
    let mut m = [[0f32; 3]; 3];
    for j in 0..3 {
        let mut col = [0f32; 3];
        col[j] = 1.0;
        let e = t.world_to_env(col);
        for i in 0..3 {
            m[i][j] = e[i];
        }
    }
    m
}
