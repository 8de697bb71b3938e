//! The input pipeline: a folder export or a coordinator job (`farm.rs`), read in a seeded order that is a pure function of
//! (seed, step) — so a run resumed from a checkpoint sees exactly the batches it would have —
//! decoded on background threads, cropped, mirrored, and paired both ways (lit0 → lit1 under
//! HDRI 1 and lit1 → lit0 under HDRI 0).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::{Arc, Mutex};

use burn::prelude::*;
use lightfarm_nets::{LightBatch, LightInput, Targets};
use lightfarm_store::{list_export_folder, ExportEntry};

use crate::farm::{FarmSource, StreamState};
use crate::lights::{camera_to_env, LightCache, Lighting};
use crate::sample::{decode_sample, SampleImages};
use crate::TrainError;

/// Mean luminance the network's input image is scaled to over its mask. Inputs are normalised
/// by their own brightness (a photograph's exposure is unknown at relight time); targets by
/// their HDRI's (`lights::REFERENCE_LUMINANCE`).
pub const INPUT_LUMINANCE: f32 = 0.5;

/// Decoded samples kept in memory: small datasets (tests, the demo) then decode once.
const DECODED_CACHE: usize = 64;

pub struct Dataset {
    source: Source,
    decoded: Mutex<HashMap<u64, Arc<SampleImages>>>,
    /// Samples `decoded` may hold ([`DECODED_CACHE`] unless set).
    decoded_limit: usize,
}

enum Source {
    /// The export's samples and, by sample index, their positions.
    Folder {
        entries: Vec<ExportEntry>,
        items: Arc<Vec<u64>>,
        by_index: HashMap<u64, usize>,
    },
    Farm(Box<FarmSource>),
}

impl Dataset {
    /// The samples of `split` ("train", "test", or "all") in a folder export.
    pub fn open(path: &Path, split: &str) -> Result<Dataset, TrainError> {
        let all = list_export_folder(path).map_err(|e| TrainError::Input(e.to_string()))?;
        let mut splits: Vec<String> = all.iter().map(|e| e.split.clone()).collect();
        splits.sort();
        splits.dedup();
        let entries: Vec<ExportEntry> = all
            .into_iter()
            .filter(|e| split == "all" || e.split == split)
            .collect();
        if entries.is_empty() {
            return Err(TrainError::Input(format!(
                "{} has no samples of split '{split}' (it has: {}); pick one of those or \"all\"",
                path.display(),
                if splits.is_empty() {
                    "none".to_owned()
                } else {
                    splits.join(", ")
                }
            )));
        }
        let items: Vec<u64> = entries.iter().map(|e| e.index).collect();
        let by_index = items.iter().enumerate().map(|(i, &x)| (x, i)).collect();
        Ok(Dataset {
            source: Source::Folder {
                entries,
                items: Arc::new(items),
                by_index,
            },
            decoded: Mutex::new(HashMap::new()),
            decoded_limit: DECODED_CACHE,
        })
    }

    /// A coordinator job followed by `source` (see [`crate::farm`]).
    pub fn farm(source: FarmSource) -> Dataset {
        Dataset {
            source: Source::Farm(Box::new(source)),
            decoded: Mutex::new(HashMap::new()),
            decoded_limit: DECODED_CACHE,
        }
    }

    /// Keeps at most `limit` decoded samples in memory; 0 decodes every draw, as training on a
    /// dataset far larger than the cache does (`examples/bench_loader.rs` times that).
    pub fn with_decoded_cache(mut self, limit: usize) -> Dataset {
        self.decoded_limit = limit;
        self
    }

    /// The sample indices training draws from until the next [`Self::refresh`], in a fixed
    /// order (the export's for a folder, by sample index for a stream).
    pub fn items(&self) -> Arc<Vec<u64>> {
        match &self.source {
            Source::Folder { items, .. } => items.clone(),
            Source::Farm(f) => Arc::new(f.state().samples.iter().map(|s| s.index).collect()),
        }
    }

    /// Takes in the samples a stream received since the last refresh; true if there were any.
    pub fn refresh(&self) -> Result<bool, TrainError> {
        match &self.source {
            Source::Folder { .. } => Ok(false),
            Source::Farm(f) => f.refresh(),
        }
    }

    /// The snapshot a checkpoint must keep, for a stream.
    pub fn stream_state(&self) -> Option<Arc<StreamState>> {
        match &self.source {
            Source::Folder { .. } => None,
            Source::Farm(f) => Some(f.state()),
        }
    }

    pub fn len(&self) -> usize {
        self.items().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `i`-th sample of [`Self::items`].
    pub fn load(&self, i: usize) -> Result<Arc<SampleImages>, TrainError> {
        let items = self.items();
        let index = *items.get(i).ok_or_else(|| {
            TrainError::Input(format!("no sample at position {i} of {}", items.len()))
        })?;
        self.load_sample(index)
    }

    /// Sample `index` of the job, decoded.
    pub fn load_sample(&self, index: u64) -> Result<Arc<SampleImages>, TrainError> {
        if let Some(s) = self
            .decoded
            .lock()
            .ok()
            .and_then(|c| c.get(&index).cloned())
        {
            return Ok(s);
        }
        let images = Arc::new(match &self.source {
            Source::Folder {
                entries, by_index, ..
            } => {
                let entry = by_index.get(&index).map(|&i| &entries[i]).ok_or_else(|| {
                    TrainError::Input(format!("the export has no sample {index}"))
                })?;
                let sample = entry.read().map_err(|e| TrainError::Input(e.to_string()))?;
                decode_sample(&sample.exr, &entry.exr.display().to_string())?
            }
            Source::Farm(f) => {
                decode_sample(&f.bytes(index)?, &format!("{index} of the streamed job"))?
            }
        });
        if let Ok(mut c) = self.decoded.lock() {
            if c.len() < self.decoded_limit {
                c.insert(index, images.clone());
            }
        }
        Ok(images)
    }
}

/// What one batch slot holds at a given step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Draw {
    pub sample: usize,
    /// Input lit1 and target lit0 (under HDRI 0) instead of the other way round.
    pub swap: bool,
    pub mirror: bool,
    /// Crop origin as fractions in [0, 1) of the slack (full size − crop).
    pub crop: (u64, u64),
}

/// The draws of `step`: epoch-wise permutations of the dataset, so every sample is seen once
/// per epoch, and per-slot augmentation from a hash of (seed, position).
pub fn plan(seed: u64, step: u64, batch: usize, n: usize) -> Vec<Draw> {
    (0..batch as u64)
        .map(|j| {
            let position = step * batch as u64 + j;
            let epoch = position / n as u64;
            let perm = permutation(n, mix(seed ^ 0x5eed, epoch));
            let mut r = mix(seed, position ^ 0xa5a5_0000_0000);
            let mut next = || {
                r = mix(r, 1);
                r
            };
            Draw {
                sample: perm[(position % n as u64) as usize],
                swap: next() & 1 == 1,
                mirror: next() & 1 == 1,
                crop: (next(), next()),
            }
        })
        .collect()
}

/// SplitMix64 finaliser of `a` and `b`: a stateless, platform-independent hash.
pub(crate) fn mix(a: u64, b: u64) -> u64 {
    let mut z = a
        .wrapping_add(b.wrapping_mul(0x9e37_79b9_7f4a_7c15))
        .wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn permutation(n: usize, seed: u64) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    let mut r = seed;
    for i in (1..n).rev() {
        r = mix(r, i as u64);
        p.swap(i, (r % (i as u64 + 1)) as usize);
    }
    p
}

/// One training pair on the host, planar CHW at the crop size.
pub struct Example {
    pub size: usize,
    pub input: Vec<f32>,
    pub mask: Vec<f32>,
    pub normal: Vec<f32>,
    pub normal_lens: Vec<f32>,
    pub albedo: Vec<f32>,
    pub target: Vec<f32>,
    pub lighting: Arc<Lighting>,
    pub camera_to_env: [[f32; 3]; 3],
}

/// Cuts `draw`'s square crop of `crop` pixels (the whole image when 0) out of a sample.
pub fn example(
    s: &SampleImages,
    draw: &Draw,
    crop: usize,
    lights: &LightCache,
) -> Result<Example, TrainError> {
    let full = s.width.min(s.height);
    let size = if crop == 0 { full } else { crop };
    if size > full || s.width != s.height && crop == 0 {
        return Err(TrainError::Input(format!(
            "sample {} is {}x{}; crop {crop} needs square samples at least that big (set `crop` ≤ {full})",
            s.spec.index, s.width, s.height
        )));
    }
    let x0 = (draw.crop.0 % (s.width - size + 1) as u64) as usize;
    let y0 = (draw.crop.1 % (s.height - size + 1) as u64) as usize;
    let (k_in, k_out) = if draw.swap { (1, 0) } else { (0, 1) };
    let lighting = lights.get(&s.spec.lighting[k_out])?;
    let rot = camera_to_env(
        s.spec.camera.camera_to_world(),
        &s.spec.lighting[k_out],
        draw.mirror,
    );

    let src = |x: usize, y: usize| {
        let sx = if draw.mirror {
            x0 + size - 1 - x
        } else {
            x0 + x
        };
        (y0 + y) * s.width + sx
    };
    let planar3 = |img: &[[f32; 3]], flip_x: bool, scale: f32| -> Vec<f32> {
        let mut out = vec![0f32; 3 * size * size];
        for y in 0..size {
            for x in 0..size {
                let v = img[src(x, y)];
                for c in 0..3 {
                    let sign = if flip_x && c == 0 && draw.mirror {
                        -1.0
                    } else {
                        1.0
                    };
                    out[(c * size + y) * size + x] = v[c] * sign * scale;
                }
            }
        }
        out
    };
    let mut mask = vec![0f32; size * size];
    for y in 0..size {
        for x in 0..size {
            mask[y * size + x] = s.mask[src(x, y)];
        }
    }
    let in_scale = input_scale(&s.lit[k_in], &s.mask);
    Ok(Example {
        size,
        input: planar3(&s.lit[k_in], false, in_scale),
        mask,
        normal: planar3(&s.normal, true, 1.0),
        normal_lens: planar3(&s.normal_lens, true, 1.0),
        albedo: planar3(&s.albedo, false, 1.0),
        target: planar3(&s.lit[k_out], false, lighting.scale),
        lighting,
        camera_to_env: rot,
    })
}

/// The factor that brings an image's mean luminance over its mask to [`INPUT_LUMINANCE`].
pub fn input_scale(rgb: &[[f32; 3]], mask: &[f32]) -> f32 {
    let (mut sum, mut weight) = (0f64, 0f64);
    for (p, &m) in rgb.iter().zip(mask) {
        sum += f64::from(m) * f64::from(lightfarm_light::Hdri::luminance(*p));
        weight += f64::from(m);
    }
    let mean = if weight > 0.0 { sum / weight } else { 0.0 };
    if mean > 1e-8 {
        (f64::from(INPUT_LUMINANCE) / mean) as f32
    } else {
        1.0
    }
}

/// A batch on the device.
pub struct Batch {
    pub input: Tensor<4>,
    pub light: LightBatch,
    pub targets: Targets,
}

pub fn to_device(examples: &[Example], device: &Device) -> Result<Batch, TrainError> {
    let b = examples.len();
    let size = examples
        .first()
        .map(|e| e.size)
        .ok_or_else(|| TrainError::Input("empty batch".into()))?;
    let stack = |f: &dyn Fn(&Example) -> &Vec<f32>, c: usize| -> Tensor<4> {
        let mut data = Vec::with_capacity(b * c * size * size);
        for e in examples {
            data.extend_from_slice(f(e));
        }
        Tensor::from_data(TensorData::new(data, [b, c, size, size]), device)
    };
    let light_inputs: Vec<LightInput<'_>> = examples
        .iter()
        .map(|e| LightInput {
            env: &e.lighting.env,
            scale: e.lighting.scale,
            camera_to_env: e.camera_to_env,
        })
        .collect();
    Ok(Batch {
        input: stack(&|e| &e.input, 3),
        light: LightBatch::new(&light_inputs, device)
            .map_err(|e| TrainError::Input(e.to_string()))?,
        targets: Targets {
            normal: stack(&|e| &e.normal, 3),
            normal_lens: stack(&|e| &e.normal_lens, 3),
            albedo: stack(&|e| &e.albedo, 3),
            relit: stack(&|e| &e.target, 3),
            mask: stack(&|e| &e.mask, 1),
        },
    })
}

/// Builds the examples of steps `start..` on `threads` background threads, handing them out
/// in step order with at most a few steps decoded ahead.
pub struct Prefetcher {
    items: usize,
    rx: Receiver<(u64, Result<Vec<Example>, TrainError>)>,
    pending: BTreeMap<u64, Result<Vec<Example>, TrainError>>,
    next: u64,
}

pub struct PrefetchParams {
    pub seed: u64,
    pub batch: usize,
    pub crop: usize,
    pub start: u64,
    pub end: u64,
    pub threads: usize,
}

impl Prefetcher {
    /// `items` is the dataset's [`Dataset::items`] in force for these steps.
    pub fn start(
        dataset: Arc<Dataset>,
        items: Arc<Vec<u64>>,
        lights: Arc<LightCache>,
        p: PrefetchParams,
    ) -> Prefetcher {
        let threads = p.threads.max(1);
        let (tx, rx) = sync_channel(threads * 2);
        let count = items.len();
        for w in 0..threads as u64 {
            let (tx, dataset, items, lights) =
                (tx.clone(), dataset.clone(), items.clone(), lights.clone());
            let (seed, batch, crop, start, end) = (p.seed, p.batch, p.crop, p.start, p.end);
            std::thread::Builder::new()
                .name(format!("prefetch-{w}"))
                .spawn(move || {
                    let mut step = start + w;
                    while step < end {
                        let result = plan(seed, step, batch, items.len())
                            .iter()
                            .map(|d| {
                                let s = dataset.load_sample(items[d.sample])?;
                                example(&s, d, crop, &lights)
                            })
                            .collect();
                        if tx.send((step, result)).is_err() {
                            return; // the trainer stopped
                        }
                        step += threads as u64;
                    }
                })
                .expect("spawning a prefetch thread");
        }
        Prefetcher {
            items: count,
            rx,
            pending: BTreeMap::new(),
            next: p.start,
        }
    }

    /// How many samples the steps draw from.
    pub fn items(&self) -> usize {
        self.items
    }

    /// The examples of the next step, in order.
    pub fn next_batch(&mut self) -> Result<Vec<Example>, TrainError> {
        loop {
            if let Some(r) = self.pending.remove(&self.next) {
                self.next += 1;
                return r;
            }
            let (step, r) = self
                .rx
                .recv()
                .map_err(|_| TrainError::Input("the data pipeline stopped early".into()))?;
            self.pending.insert(step, r);
        }
    }
}
