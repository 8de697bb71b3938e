//! The adaptation loop: the base model frozen, f_Ā (and the critic) trained on batches of real
//! photos with section 4.3's losses, checkpoints that are complete models, resume after
//! `kill -9` on the same loss curve.
//!
//! Each step draws its photos, two catalog HDRIs (random rotations) and two OLAT lights of the
//! 168-light basis from (seed, step) alone, so a resumed run repeats the same batches.

use std::collections::HashMap;
use std::fs;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use lightfarm_face::{builtin_face_net, identity_loss, Alignment, FaceNet, LazyFaces};
use lightfarm_light::{OlatBasis, PrefilteredEnv, OLAT_DISC_DEG};
use lightfarm_nets::adapt::{olat_consistency, relative_consistency};
use lightfarm_nets::{
    critic_loss, load_weights, perceptual_loss, stable_param_ids, AdaptTarget, Adapter, LightBatch,
    LightInput, PatchGan, PatchGanConfig, RelightNet, ResNetConfig, Vgg16, RESNET_SIZE_MULTIPLE,
};
use lightfarm_photo::LazyMatting;
use lightfarm_scene::{AssetKind, Catalog};
use serde::{Deserialize, Serialize};

use super::checkpoint::{self, AdapterFile, ADAPTER_FILE};
use super::config::AdaptConfig;
use super::photos::{PhotoSet, Prepared};
use crate::data::{input_scale, mix};
use crate::infer::{load_net, resolve_model_dir};
use crate::lights::{identity_camera, Lighting};
use crate::train::{latest_checkpoint, truncate_losses, LOSS_FILE, MODEL_FILE, SEED_LOCK};
use crate::TrainError;

/// The resolved config, written on the first run and checked on every later one.
pub const ADAPT_RUN_FILE: &str = "adapt.json";
const PHOTO_CACHE: &str = "photo-cache";

/// One line of `losses.jsonl` of an adaptation run; a term is absent when its weight is 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdaptLog {
    pub step: u64,
    pub total: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub olat: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub similarity: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gan: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub critic: Option<f32>,
    pub photos_per_second: f32,
    /// Photos of the folder found unusable so far (each logged by name).
    pub skipped_photos: u64,
}

#[derive(Clone, Debug)]
pub struct AdaptSummary {
    pub start_step: u64,
    pub end_step: u64,
    pub checkpoint: PathBuf,
    pub cancelled: bool,
    pub photos: usize,
    pub skipped_photos: usize,
}

/// What adaptation reports as it goes.
pub trait AdaptObserver {
    fn on_start(&mut self, _start: u64, _end: u64) {}
    fn on_step(&mut self, _log: &AdaptLog) {}
}

impl AdaptObserver for () {}

/// The lightings of one step, each as a batch of `b` identical items.
struct StepLights {
    olat: [LightBatch; 3],
    hdri: [LightBatch; 2],
}

/// Light sources of the run: catalog HDRIs and the OLAT basis, prefiltered on first use.
struct Lights {
    catalog: Catalog,
    hdris: Vec<String>,
    loaded: HashMap<String, Arc<Lighting>>,
    basis: OlatBasis,
    olat: HashMap<usize, Arc<PrefilteredEnv>>,
}

impl Lights {
    fn new(catalog: Catalog, wanted: &[String], olat_lights: usize) -> Result<Lights, TrainError> {
        let hdris: Vec<String> = if wanted.is_empty() {
            catalog
                .of_kind(AssetKind::Hdri)
                .into_iter()
                .map(|a| a.id.clone())
                .collect()
        } else {
            for id in wanted {
                if catalog.get(id).is_none_or(|a| a.kind != AssetKind::Hdri) {
                    return Err(TrainError::Config(format!(
                        "hdris: '{id}' is not an HDRI of the asset catalog (`lightfarm assets list`)"
                    )));
                }
            }
            wanted.to_vec()
        };
        if hdris.is_empty() {
            return Err(TrainError::Config(
                "the asset catalog has no HDRIs for the relative consistency loss".into(),
            ));
        }
        Ok(Lights {
            catalog,
            hdris,
            loaded: HashMap::new(),
            basis: OlatBasis::new(olat_lights, OLAT_DISC_DEG, 512, 256)
                .map_err(|e| TrainError::Config(format!("olat_lights = {olat_lights}: {e}")))?,
            olat: HashMap::new(),
        })
    }

    fn hdri(&mut self, k: usize) -> Result<Arc<Lighting>, TrainError> {
        let id = self.hdris[k % self.hdris.len()].clone();
        if let Some(l) = self.loaded.get(&id) {
            return Ok(l.clone());
        }
        let asset = self
            .catalog
            .get(&id)
            .ok_or_else(|| TrainError::Config(format!("HDRI '{id}' left the catalog")))?;
        let l = Arc::new(Lighting::load(&self.catalog.path_of(asset))?);
        self.loaded.insert(id, l.clone());
        Ok(l)
    }

    fn olat(&mut self, i: usize) -> Arc<PrefilteredEnv> {
        let basis = &self.basis;
        self.olat
            .entry(i)
            .or_insert_with(|| Arc::new(PrefilteredEnv::compute(&basis.map(i))))
            .clone()
    }

    /// Step `step`'s lightings: OLAT lights a ≠ b and their sum (each light scaled to mean
    /// radiance 1 over the sphere, like the HDRIs), and two HDRIs at random rotations.
    fn for_step(
        &mut self,
        seed: u64,
        step: u64,
        b: usize,
        device: &Device,
    ) -> Result<StepLights, TrainError> {
        let r = |k: u64| mix(mix(seed ^ 0x6c69_6768_7473, step), k);
        let n = self.basis.len() as u64;
        let a = (r(0) % n) as usize;
        let second = (a as u64 + 1 + r(1) % (n - 1)) % n;
        let (ea, eb) = (self.olat(a), self.olat(second as usize));
        let sum = ea.sum(&eb).ok_or_else(|| {
            TrainError::Config("OLAT maps prefiltered at different resolutions".into())
        })?;
        let olat_scale = n as f32;
        let front = identity_camera(0.0, false);
        let batch = |env: &PrefilteredEnv, scale: f32, rot: [[f32; 3]; 3]| {
            let items: Vec<LightInput<'_>> = (0..b)
                .map(|_| LightInput {
                    env,
                    scale,
                    camera_to_env: rot,
                })
                .collect();
            LightBatch::new(&items, device).map_err(|e| TrainError::Config(e.to_string()))
        };
        let nh = self.hdris.len() as u64;
        let hi = (r(2) % nh) as usize;
        let hj = if nh > 1 {
            ((hi as u64 + 1 + r(3) % (nh - 1)) % nh) as usize
        } else {
            hi
        };
        let rot = |k: u64| identity_camera((r(k) % 360) as f32, false);
        let (li, lj) = (self.hdri(hi)?, self.hdri(hj)?);
        Ok(StepLights {
            olat: [
                batch(&ea, olat_scale, front)?,
                batch(&eb, olat_scale, front)?,
                batch(&sum, olat_scale, front)?,
            ],
            hdri: [
                batch(&li.env, li.scale, rot(4))?,
                batch(&lj.env, lj.scale, rot(5))?,
            ],
        })
    }
}

/// Photos of step `step`: `b` draws from (seed, step), redrawn past unusable ones.
fn draw_photos(
    photos: &PhotoSet,
    seed: u64,
    step: u64,
    b: usize,
) -> Result<Vec<Prepared>, TrainError> {
    let n = photos.len() as u64;
    let mut out = Vec::with_capacity(b);
    let mut k = 0u64;
    while out.len() < b {
        if k > 8 * n + 64 {
            // Draws keep hitting unusable photos: find out whether any is usable at all.
            let usable = (0..photos.len()).find_map(|i| photos.get(i).transpose());
            if usable.is_none() {
                return Err(TrainError::Input(format!(
                    "photos = {}: none of its {} photos can be used (each is named in the log \
                     with the reason)",
                    photos.folder().display(),
                    photos.len()
                )));
            }
            k = 0;
        }
        let i = (mix(mix(seed ^ 0x7068_6f74_6f73, step), k) % n) as usize;
        k += 1;
        if let Some(p) = photos.get(i)? {
            out.push(p);
        }
    }
    Ok(out)
}

/// A batch of photos on the device: the exposure-normalised, masked input and the mask.
fn to_tensors(batch: &[Prepared], size: usize, device: &Device) -> (Tensor<4>, Tensor<4>) {
    let b = batch.len();
    let mut input = vec![0f32; b * 3 * size * size];
    let mut mask = vec![0f32; b * size * size];
    for (k, p) in batch.iter().enumerate() {
        let masked: Vec<[f32; 3]> = p
            .rgb
            .iter()
            .zip(&p.mask)
            .map(|(c, &m)| c.map(|v| v * m))
            .collect();
        let scale = input_scale(&masked, &p.mask);
        for (i, (c, &m)) in masked.iter().zip(&p.mask).enumerate() {
            mask[k * size * size + i] = m;
            for ch in 0..3 {
                input[(k * 3 + ch) * size * size + i] = c[ch] * scale;
            }
        }
    }
    (
        Tensor::from_data(TensorData::new(input, [b, 3, size, size]), device),
        Tensor::from_data(TensorData::new(mask, [b, 1, size, size]), device),
    )
}

fn scalar(t: &Tensor<1>) -> f32 {
    t.clone().into_scalar::<f32>()
}

/// Adapts `cfg.base` to the photos of `cfg.photos` until `cfg.steps`, resuming from the run
/// directory's newest checkpoint. Stops early, after a checkpoint, when `cancel` is set.
pub fn adapt(
    cfg: &AdaptConfig,
    catalog: Catalog,
    observer: &mut dyn AdaptObserver,
    cancel: &AtomicBool,
) -> Result<AdaptSummary, TrainError> {
    let base_dir = resolve_model_dir(&cfg.base)
        .map_err(|e| TrainError::Config(format!("base = {}: {e}", cfg.base.display())))?;
    let plain = lightfarm_nets::device::select(&cfg.device)
        .map_err(|e| TrainError::Config(e.to_string()))?;
    let device = plain.clone().autodiff();
    let (base, net_cfg) = load_net(&base_dir, &device)?;
    let base: RelightNet = base.no_grad();
    let multiple = net_cfg.relight().size_multiple().max(RESNET_SIZE_MULTIPLE);
    if !cfg.size.is_multiple_of(multiple) {
        return Err(TrainError::Config(format!(
            "size = {} must be a multiple of {multiple} for the base model's {} UNet levels and \
             f_Ā's two down-samplings",
            cfg.size,
            net_cfg.widths.len()
        )));
    }
    fs::create_dir_all(cfg.out.join(crate::train::CHECKPOINTS))
        .map_err(|e| TrainError::io(&cfg.out, e))?;
    checkpoint::check_run_file(cfg)?;
    let shape = AdapterFile {
        target: cfg.target,
        base: cfg.adapter.base,
        blocks: cfg.adapter.blocks,
    };
    let guard = SEED_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    device.seed(cfg.seed);
    let adapter = Adapter::with_config(
        cfg.target,
        ResNetConfig::new(0, 0)
            .with_base(shape.base)
            .with_blocks(shape.blocks),
        &device,
    )
    .map_err(|e| TrainError::Config(format!("adapter: {e}")))?;
    let mut trainee = if cfg.finetune {
        let (tuned, _) = load_net(&base_dir, &device)?;
        Trainee::Finetune(stable_param_ids(tuned, 13))
    } else {
        Trainee::Adapter(stable_param_ids(adapter, 11))
    };
    let mut critic = stable_param_ids(
        PatchGanConfig::new()
            .with_width(cfg.critic_width)
            .init(&device),
        12,
    );
    drop(guard);
    let vgg = cfg
        .similarity_weights()
        .map(|p| Vgg16::load(&p, &device))
        .transpose()
        .map_err(|e| {
            TrainError::Config(format!(
                "vgg_weights: {e}; or set weights.similarity = 0 and vgg_weights = \"none\""
            ))
        })?;
    // The identity loss needs each photo's face: photos without one are skipped then.
    let face_net = (cfg.weights.identity > 0.0)
        .then(|| FaceNet::load(&builtin_face_net(), &device))
        .transpose()
        .map_err(|e| {
            TrainError::Config(format!(
                "weights.identity = {}: {e}; or set weights.identity = 0",
                cfg.weights.identity
            ))
        })?;
    let faces = face_net
        .is_some()
        .then(|| Arc::new(LazyFaces::builtin(plain.clone())));
    let mut optim = lightfarm_nets::optimizer();
    let mut critic_optim = lightfarm_nets::optimizer();
    let mut start = 0;
    if let Some(dir) = latest_checkpoint(&cfg.out)? {
        let ck = |e: String| TrainError::Checkpoint(format!("{}: {e}", dir.display()));
        trainee = match trainee {
            Trainee::Adapter(a) => Trainee::Adapter(
                load_weights(a, &dir.join(ADAPTER_FILE)).map_err(|e| ck(e.to_string()))?,
            ),
            Trainee::Finetune(n) => Trainee::Finetune(
                load_weights(n, &dir.join(MODEL_FILE)).map_err(|e| ck(e.to_string()))?,
            ),
        };
        critic = load_weights(critic, &dir.join(checkpoint::CRITIC_FILE))
            .map_err(|e| ck(e.to_string()))?;
        optim = optim
            .load(dir.join(checkpoint::OPTIM_FILE))
            .map_err(|e| ck(format!("optimizer state: {e:?}")))?;
        critic_optim = critic_optim
            .load(dir.join(checkpoint::CRITIC_OPTIM_FILE))
            .map_err(|e| ck(format!("critic optimizer state: {e:?}")))?;
        start = checkpoint::load_step(&dir)?;
        tracing::info!(step = start, checkpoint = %dir.display(), "resuming adaptation");
    }
    truncate_losses(&cfg.out.join(LOSS_FILE), start)?;
    observer.on_start(start, cfg.steps);
    let photos = PhotoSet::open(
        &cfg.photos,
        &cfg.out.join(PHOTO_CACHE),
        cfg.size,
        LazyMatting::builtin(),
        faces,
    )?;
    let mut lights = Lights::new(catalog, &cfg.hdris, cfg.olat_lights)?;
    let mut log = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(cfg.out.join(LOSS_FILE))
        .map_err(|e| TrainError::io(&cfg.out.join(LOSS_FILE), e))?;
    let w = &cfg.weights;
    let mut checkpoint_dir = latest_checkpoint(&cfg.out)?.unwrap_or_default();
    let mut step = start;
    let mut cancelled = false;
    while step < cfg.steps {
        let started = Instant::now();
        let batch = draw_photos(&photos, cfg.seed, step, cfg.batch)?;
        let (input, mask) = to_tensors(&batch, cfg.size, &device);
        let l = lights.for_step(cfg.seed, step, cfg.batch, &device)?;

        let d = base.decompose(input.clone());
        let refined = match &trainee {
            Trainee::Adapter(a) => a.refine(input.clone(), &d),
            Trainee::Finetune(n) => n.decompose(input.clone()),
        };
        let rbar = |light: &LightBatch| match &trainee {
            Trainee::Adapter(a) => {
                a.relight(&base, input.clone(), mask.clone(), light, &refined)
                    .relit
            }
            Trainee::Finetune(n) => n.render(input.clone(), mask.clone(), light, &refined).relit,
        };
        let r = |light: &LightBatch| base.render(input.clone(), mask.clone(), light, &d).relit;
        let rbar_i = rbar(&l.hdri[0]);
        let mut total: Option<Tensor<1>> = None;
        let mut add = |term: &Tensor<1>, weight: f64| {
            let t = term.clone().mul_scalar(weight);
            total = Some(match total.take() {
                Some(s) => s + t,
                None => t,
            });
        };
        let olat = (w.olat > 0.0).then(|| {
            olat_consistency(
                rbar(&l.olat[0]),
                rbar(&l.olat[1]),
                rbar(&l.olat[2]),
                mask.clone(),
            )
        });
        let relative = (w.relative > 0.0).then(|| {
            relative_consistency(
                r(&l.hdri[0]),
                r(&l.hdri[1]),
                rbar_i.clone(),
                rbar(&l.hdri[1]),
                mask.clone(),
            )
        });
        let similarity = vgg.as_ref().map(|v| match cfg.target {
            AdaptTarget::Albedo => perceptual_loss(
                v,
                refined.albedo.clone(),
                d.albedo.clone().detach(),
                mask.clone(),
            ),
            // The direct ablation compares relit images instead (section 4.3).
            AdaptTarget::Relit => {
                perceptual_loss(v, rbar_i.clone(), r(&l.hdri[0]).detach(), mask.clone())
            }
        });
        let identity = face_net.as_ref().map(|net| {
            let faces: Vec<Alignment> = batch.iter().filter_map(|p| p.face.clone()).collect();
            identity_loss(net, input.clone(), rbar_i.clone(), mask.clone(), &faces)
        });
        let gan = (w.gan > 0.0).then(|| {
            critic
                .forward(rbar_i.clone(), mask.clone())
                .sub_scalar(1.0)
                .powi_scalar(2)
                .mean()
        });
        for (term, weight) in [
            (&olat, w.olat),
            (&relative, w.relative),
            (&similarity, w.similarity),
            (&identity, w.identity),
            (&gan, w.gan),
        ] {
            if let Some(t) = term {
                add(t, weight);
            }
        }
        let total = total.ok_or_else(|| TrainError::Config("every loss weight is 0".into()))?;
        let total_value = scalar(&total);
        if !total_value.is_finite() {
            return Err(TrainError::Diverged {
                step,
                loss: total_value,
            });
        }
        let grads = total.backward();
        trainee = match trainee {
            Trainee::Adapter(a) => {
                let grads = GradientsParams::from_grads(grads, &a);
                Trainee::Adapter(optim.step(cfg.lr, a, grads))
            }
            Trainee::Finetune(n) => {
                let grads = GradientsParams::from_grads(grads, &n);
                Trainee::Finetune(optim.step(cfg.lr, n, grads))
            }
        };
        let critic_value = if w.gan > 0.0 {
            let c = critic_loss(&critic, input.clone(), rbar_i.detach(), mask.clone());
            let value = scalar(&c);
            let grads = GradientsParams::from_grads(c.backward(), &critic);
            critic = critic_optim.step(cfg.lr, critic, grads);
            Some(value)
        } else {
            None
        };
        step += 1;
        let entry = AdaptLog {
            step,
            total: total_value,
            olat: olat.as_ref().map(scalar),
            relative: relative.as_ref().map(scalar),
            similarity: similarity.as_ref().map(scalar),
            identity: identity.as_ref().map(scalar),
            gan: gan.as_ref().map(scalar),
            critic: critic_value,
            photos_per_second: batch.len() as f32 / started.elapsed().as_secs_f32().max(1e-9),
            skipped_photos: photos.skipped() as u64,
        };
        let line = serde_json::to_string(&entry).map_err(|e| TrainError::Config(e.to_string()))?;
        writeln!(log, "{line}").map_err(|e| TrainError::io(&cfg.out.join(LOSS_FILE), e))?;
        observer.on_step(&entry);
        cancelled = cancel.load(Ordering::Relaxed);
        if step.is_multiple_of(cfg.checkpoint_every) || step == cfg.steps || cancelled {
            log.flush()
                .map_err(|e| TrainError::io(&cfg.out.join(LOSS_FILE), e))?;
            checkpoint_dir = checkpoint::save(
                cfg,
                step,
                &base_dir,
                &shape,
                (&trainee, &critic, &optim, &critic_optim),
            )?;
        }
        if cancelled {
            break;
        }
    }
    Ok(AdaptSummary {
        start_step: start,
        end_step: step,
        checkpoint: checkpoint_dir,
        cancelled,
        photos: photos.len(),
        skipped_photos: photos.skipped(),
    })
}

/// What adaptation trains: f_Ā on the frozen base model (the paper), or the base model's own
/// networks (the ablation "finetune only").
// One value per run, moved through each optimizer step: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub(super) enum Trainee {
    Adapter(Adapter),
    Finetune(RelightNet),
}

/// What a checkpoint saves besides the base model.
pub(super) type Modules<'a> = (
    &'a Trainee,
    &'a PatchGan,
    &'a ModuleOptimizer,
    &'a ModuleOptimizer,
);
