//! Generated people: a sample's synthetic head built from the catalog's model files.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use lightfarm_identity::makehuman::MakeHuman;
use lightfarm_identity::person::{generate, TextureSize};
use lightfarm_scene::catalog::{Asset, AssetKind, Catalog};
use lightfarm_scene::expand::{SampleSpec, SyntheticHead};
use lightfarm_scene::identity::{identity_name, SYNTHETIC_MODELS};

use crate::assemble::resolve;
use crate::head::{assign_head_materials, Head};
use crate::SubjectError;

/// Renders at most this many pixels on a side get the small textures: their face covers a
/// few dozen pixels, and full textures would cost more than the render.
const SMALL_TEXTURES_MAX_PX: u32 = 128;

/// The loaded model, kept for the process: workers render many samples from one pair of files.
type Cached = (PathBuf, PathBuf, Arc<MakeHuman>);
static MODEL: Mutex<Option<Cached>> = Mutex::new(None);

fn model(core: PathBuf, targets: PathBuf) -> Result<Arc<MakeHuman>, SubjectError> {
    let mut cache = MODEL.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((c, t, m)) = cache.as_ref() {
        if *c == core && *t == targets {
            return Ok(m.clone());
        }
    }
    let loaded = Arc::new(
        MakeHuman::load(&core, &targets).map_err(|e| SubjectError::Asset {
            asset: "makehuman".into(),
            reason: e.to_string(),
        })?,
    );
    *cache = Some((core, targets, loaded.clone()));
    Ok(loaded)
}

/// The head of a sample whose person is generated.
pub fn synthetic_head(
    catalog: &Catalog,
    synthetic: &SyntheticHead,
    sample: &SampleSpec,
) -> Result<Head, SubjectError> {
    let mut paths = Vec::new();
    for id in SYNTHETIC_MODELS {
        let pinned = synthetic
            .models
            .iter()
            .find(|m| m.id == id)
            .ok_or_else(|| SubjectError::Asset {
                asset: id.to_owned(),
                reason:
                    "the sample's synthetic head does not pin this model file; re-expand the spec"
                        .into(),
            })?;
        let (_, path) = resolve(catalog, &pinned.id, &pinned.blake3, AssetKind::Model)?;
        paths.push(path);
    }
    let model = model(paths[0].clone(), paths[1].clone())?;
    let r = &sample.render;
    let size = if r.width.max(r.height) <= SMALL_TEXTURES_MAX_PX {
        TextureSize::SMALL
    } else {
        TextureSize::FULL
    };
    let name = identity_name(synthetic.identity.id);
    let person = generate(&model, &synthetic.identity, size).map_err(|e| SubjectError::Asset {
        asset: name.clone(),
        reason: e.to_string(),
    })?;
    tracing::debug!(identity = %name, record = ?person.record, "generated a synthetic person");
    let mut scene = person.scene;
    assign_head_materials(&mut scene);
    let asset = Asset {
        id: name,
        kind: AssetKind::Head,
        path: String::new(),
        blake3: String::new(),
        license: "CC0-1.0".into(),
        attribution: String::new(),
        identity: None,
        tags: Default::default(),
        frame: None,
        landmarks: None,
    };
    Head::from_scene(&asset, scene, &sample.head.expression.weights)
}
