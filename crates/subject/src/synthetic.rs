//! Generated people: a sample's synthetic head built from the catalog's model files.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use lightfarm_identity::makehuman::MakeHuman;
use lightfarm_identity::person::{generate, TextureSize};
use lightfarm_render::scene::Scene;
use lightfarm_scene::catalog::{Asset, AssetKind, Catalog};
use lightfarm_scene::expand::{SampleSpec, SyntheticHead};
use lightfarm_scene::identity::SyntheticIdentity;
use lightfarm_scene::identity::{identity_name, SYNTHETIC_MODELS};

use crate::assemble::resolve;
use crate::head::{assign_head_materials, Head};
use crate::SubjectError;

/// Renders at most this many pixels on a side get the small textures: their face covers a
/// few dozen pixels, and full textures would cost more than the render.
const SMALL_TEXTURES_MAX_PX: u32 = 128;

/// The loaded models, kept for the process: workers render many samples from one set of files.
type Cached = (Vec<PathBuf>, Arc<MakeHuman>);
static MODEL: Mutex<Option<Cached>> = Mutex::new(None);

/// MakeHuman from its core and targets files, with the ICT Face Model's modes matched to it.
fn model(paths: Vec<PathBuf>) -> Result<Arc<MakeHuman>, SubjectError> {
    let mut cache = MODEL.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((p, m)) = cache.as_ref() {
        if *p == paths {
            return Ok(m.clone());
        }
    }
    let [core, targets, ict] = paths.as_slice() else {
        return Err(SubjectError::Asset {
            asset: "makehuman".into(),
            reason: format!("expected 3 model files, got {}", paths.len()),
        });
    };
    let loaded = MakeHuman::load(core, targets)
        .and_then(|m| m.with_ict(ict))
        .map_err(|e| SubjectError::Asset {
            asset: "makehuman".into(),
            reason: e.to_string(),
        })?;
    let loaded = Arc::new(loaded);
    *cache = Some((paths, loaded.clone()));
    Ok(loaded)
}

/// Generated people kept by a worker, so further samples of a person (other expressions,
/// lightings, cameras) skip the generation: keyed by the identity's name, the BLAKE3 of every
/// parameter and the texture size, least recently used first out.
struct PeopleCache {
    entries: VecDeque<(String, TextureSize, Arc<Scene>)>,
    bytes: usize,
}

static PEOPLE: Mutex<PeopleCache> = Mutex::new(PeopleCache {
    entries: VecDeque::new(),
    bytes: 0,
});

/// `LIGHTFARM_PEOPLE_CACHE_MB` (default 1024; 0 turns the cache off). A full-size person is
/// ~90 MB of textures.
pub const PEOPLE_CACHE_ENV: &str = "LIGHTFARM_PEOPLE_CACHE_MB";
const PEOPLE_CACHE_DEFAULT_MB: usize = 1024;

fn cache_budget() -> usize {
    let mb = std::env::var(PEOPLE_CACHE_ENV)
        .ok()
        .and_then(|v| match v.trim().parse::<usize>() {
            Ok(mb) => Some(mb),
            Err(_) => {
                tracing::warn!(
                    value = %v,
                    "{PEOPLE_CACHE_ENV} is not a whole number of MiB; using {PEOPLE_CACHE_DEFAULT_MB}"
                );
                None
            }
        })
        .unwrap_or(PEOPLE_CACHE_DEFAULT_MB);
    mb << 20
}

fn scene_bytes(scene: &Scene) -> usize {
    let textures: usize = scene.textures.iter().map(|t| t.rgba8.len()).sum();
    let meshes: usize = scene
        .meshes
        .iter()
        .map(|m| {
            let morphs: usize = m
                .morph_targets
                .iter()
                .map(|t| (t.position_deltas.len() + t.normal_deltas.len()) * 12)
                .sum();
            m.positions.len() * 44 + m.indices.len() * 4 + morphs
        })
        .sum();
    textures + meshes
}

/// The cache key of a person: their name and a hash of every parameter (a re-expanded spec
/// with other distributions gives the same name different parameters).
fn cache_key(identity: &SyntheticIdentity) -> String {
    let params = serde_json::to_vec(identity).unwrap_or_default();
    format!(
        "{}/{}",
        identity_name(identity.id),
        blake3::hash(&params).to_hex()
    )
}

fn cached_person(key: &str, size: TextureSize) -> Option<Arc<Scene>> {
    let mut cache = PEOPLE.lock().unwrap_or_else(|e| e.into_inner());
    let at = cache
        .entries
        .iter()
        .position(|(k, s, _)| k == key && *s == size)?;
    let entry = cache.entries.remove(at)?;
    let scene = entry.2.clone();
    cache.entries.push_back(entry);
    Some(scene)
}

fn keep_person(key: String, size: TextureSize, scene: Arc<Scene>) {
    let budget = cache_budget();
    let bytes = scene_bytes(&scene);
    if bytes > budget {
        return;
    }
    let mut cache = PEOPLE.lock().unwrap_or_else(|e| e.into_inner());
    if cache
        .entries
        .iter()
        .any(|(k, s, _)| *k == key && *s == size)
    {
        return;
    }
    while cache.bytes + bytes > budget {
        let Some((_, _, old)) = cache.entries.pop_front() else {
            break;
        };
        cache.bytes = cache.bytes.saturating_sub(scene_bytes(&old));
    }
    cache.bytes += bytes;
    cache.entries.push_back((key, size, scene));
}

/// How many people the worker's cache holds (for tests and logs).
pub fn cached_people() -> usize {
    PEOPLE.lock().map(|c| c.entries.len()).unwrap_or(0)
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
    let model = model(paths)?;
    let r = &sample.render;
    let size = if r.width.max(r.height) <= SMALL_TEXTURES_MAX_PX {
        TextureSize::SMALL
    } else {
        TextureSize::FULL
    };
    let name = identity_name(synthetic.identity.id);
    let key = cache_key(&synthetic.identity);
    let scene = match cached_person(&key, size) {
        Some(scene) => {
            tracing::debug!(identity = %name, "synthetic person from the worker's cache");
            scene
        }
        None => {
            let person =
                generate(&model, &synthetic.identity, size).map_err(|e| SubjectError::Asset {
                    asset: name.clone(),
                    reason: e.to_string(),
                })?;
            tracing::debug!(identity = %name, params = ?synthetic.identity, record = ?person.record, "generated a synthetic person");
            let scene = Arc::new(person.scene);
            keep_person(key, size, scene.clone());
            scene
        }
    };
    let mut scene = Scene::clone(&scene);
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
