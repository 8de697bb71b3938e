//! Viewable images of a committed sample: its EXR decoded once, each pass tone-mapped to an
//! 8-bit PNG at full size plus one thumbnail strip of all six passes side by side, written
//! next to the data under `previews/<blake3>/`. A sample's bytes never change (the directory
//! is named by their hash), so what is there is never stale; gallery pages read those PNGs
//! and never touch an EXR again.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use image::ImageEncoder;
use lightfarm_store::{BlobStore, ExrLayer, SAMPLE_ATTRIBUTE};

/// The passes a preview shows, in the order of the thumbnail strip.
pub const PASSES: [&str; 6] = ["lit0", "lit1", "albedo", "normal", "normal_lens", "mask"];
/// Height of one tile of the thumbnail strip (smaller samples keep their own height).
pub const THUMB_HEIGHT: usize = 96;
/// Decodes at once; more would only queue for the same cores the coordinator serves from.
const CONCURRENT_DECODES: usize = 2;

/// Makes and finds previews; cheap to clone.
#[derive(Clone)]
pub struct Previews {
    blobs: Arc<dyn BlobStore>,
    dir: PathBuf,
    decodes: Arc<tokio::sync::Semaphore>,
}

/// One pass as linear floats, row-major, 3 channels (the mask repeated).
struct Pass {
    rgb: Vec<[f32; 3]>,
}

impl Previews {
    pub fn new(blobs: Arc<dyn BlobStore>, dir: PathBuf) -> Previews {
        Previews {
            blobs,
            dir,
            decodes: Arc::new(tokio::sync::Semaphore::new(CONCURRENT_DECODES)),
        }
    }

    /// The blob store the samples are read from.
    pub fn blobs(&self) -> Arc<dyn BlobStore> {
        self.blobs.clone()
    }

    fn sample_dir(&self, blake3: &str) -> Result<PathBuf, String> {
        if !lightfarm_store::is_hash(blake3) {
            return Err(format!("`{blake3}` is not a sample hash"));
        }
        Ok(self.dir.join(blake3))
    }

    /// The PNG `file` ("strip", a pass name, or "header" for the EXR header's JSON) of the
    /// sample whose EXR has hash `blake3`, made first if this sample has none yet.
    pub async fn file(&self, blake3: &str, file: &str) -> Result<Vec<u8>, String> {
        let name = match file {
            "strip" => "strip.png".to_owned(),
            "header" => "header.json".to_owned(),
            p if PASSES.contains(&p) => format!("{p}.png"),
            other => {
                return Err(format!(
                    "`{other}` is not a preview (strip, header, {})",
                    PASSES.join(", ")
                ))
            }
        };
        let dir = self.sample_dir(blake3)?;
        let path = dir.join(&name);
        if let Ok(bytes) = tokio::fs::read(&path).await {
            return Ok(bytes);
        }
        let _permit = self
            .decodes
            .acquire()
            .await
            .map_err(|_| "the coordinator is shutting down".to_owned())?;
        // Another request may have made it while this one waited.
        if let Ok(bytes) = tokio::fs::read(&path).await {
            return Ok(bytes);
        }
        let (blobs, hash, target) = (self.blobs.clone(), blake3.to_owned(), dir.clone());
        tokio::task::spawn_blocking(move || make(blobs.as_ref(), &hash, &target))
            .await
            .map_err(|e| format!("preview thread: {e}"))??;
        tokio::fs::read(&path)
            .await
            .map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// Decodes the sample and writes every preview into `dir` at once: into a temporary sibling
/// first, renamed into place, so a reader never sees half a set.
fn make(blobs: &dyn BlobStore, blake3: &str, dir: &Path) -> Result<(), String> {
    let exr = blobs
        .read(blake3)
        .map_err(|e| format!("sample {blake3}: {e}"))?;
    let (width, height, passes, header) =
        decode(&exr).map_err(|e| format!("sample {blake3}: {e}"))?;
    let parent = dir.parent().unwrap_or(dir);
    std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
    let tmp = tempfile::Builder::new()
        .prefix(".making-")
        .tempdir_in(parent)
        .map_err(|e| format!("{}: {e}", parent.display()))?;
    let (tw, th) = thumb_size(width, height);
    let mut strip = vec![0u8; tw * PASSES.len() * th * 3];
    for (k, (name, pass)) in PASSES.iter().zip(&passes).enumerate() {
        let pixels = tone_map(name, pass);
        png(
            &tmp.path().join(format!("{name}.png")),
            &pixels,
            width,
            height,
        )?;
        let small = shrink(&pixels, width, height, tw, th);
        for y in 0..th {
            let row = (y * tw * PASSES.len() + k * tw) * 3;
            strip[row..row + tw * 3].copy_from_slice(&small[y * tw * 3..(y + 1) * tw * 3]);
        }
    }
    png(&tmp.path().join("strip.png"), &strip, tw * PASSES.len(), th)?;
    let header_path = tmp.path().join("header.json");
    std::fs::write(&header_path, header).map_err(|e| format!("{}: {e}", header_path.display()))?;
    let made = tmp.keep();
    if let Err(e) = std::fs::rename(&made, dir) {
        let _ = std::fs::remove_dir_all(&made);
        // Lost a race with another maker of the same sample: theirs is as good as ours.
        if !dir.join("strip.png").exists() {
            return Err(format!("{}: {e}", dir.display()));
        }
    }
    Ok(())
}

type Decoded = (usize, usize, Vec<Pass>, String);

/// The six passes of a sample EXR and its header attribute (the JSON text, or `{}`).
fn decode(bytes: &[u8]) -> Result<Decoded, String> {
    let layer = ExrLayer::read(bytes)?;
    let mut passes = Vec::with_capacity(PASSES.len());
    for name in PASSES {
        let comps = match name {
            "normal" | "normal_lens" => ["X", "Y", "Z"],
            "mask" => ["A", "A", "A"],
            _ => ["R", "G", "B"],
        };
        passes.push(Pass {
            rgb: layer.rgb(name, comps)?,
        });
    }
    let header = layer
        .text(SAMPLE_ATTRIBUTE)
        .unwrap_or_else(|| "{}".to_owned());
    Ok((layer.width, layer.height, passes, header))
}

/// Width and height of one tile of the thumbnail strip of a `width`×`height` sample.
pub fn thumb_size(width: usize, height: usize) -> (usize, usize) {
    let th = THUMB_HEIGHT.min(height).max(1);
    ((width * th).div_ceil(height.max(1)).max(1), th)
}

fn srgb8(linear: f32) -> u8 {
    let x = linear.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// 8-bit sRGB for display. Radiance is exposed so that its 98th-percentile luminance maps to
/// 0.9 (each lit pass on its own: previews are for looking, the EXR keeps the numbers);
/// albedo is shown as is; normals as `0.5 + 0.5 n`; the mask as grey levels.
fn tone_map(name: &str, pass: &Pass) -> Vec<u8> {
    let scale = if name.starts_with("lit") {
        let mut lum: Vec<f32> = pass
            .rgb
            .iter()
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .filter(|l| *l > 0.0)
            .collect();
        lum.sort_by(f32::total_cmp);
        let p98 = lum
            .get(lum.len() * 98 / 100)
            .or(lum.last())
            .copied()
            .unwrap_or(1.0);
        if p98 > 0.0 {
            0.9 / p98
        } else {
            1.0
        }
    } else {
        1.0
    };
    let mut out = Vec::with_capacity(pass.rgb.len() * 3);
    for p in &pass.rgb {
        for c in p {
            out.push(match name {
                "normal" | "normal_lens" => ((0.5 + 0.5 * c).clamp(0.0, 1.0) * 255.0 + 0.5) as u8,
                "mask" => (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8,
                _ => srgb8(c * scale),
            });
        }
    }
    out
}

/// Box-filtered downscale of 8-bit RGB from w×h to tw×th.
fn shrink(src: &[u8], w: usize, h: usize, tw: usize, th: usize) -> Vec<u8> {
    let mut out = vec![0u8; tw * th * 3];
    for ty in 0..th {
        let (y0, y1) = (ty * h / th, ((ty + 1) * h).div_ceil(th).min(h));
        for tx in 0..tw {
            let (x0, x1) = (tx * w / tw, ((tx + 1) * w).div_ceil(tw).min(w));
            let mut sum = [0u32; 3];
            for y in y0..y1.max(y0 + 1) {
                for x in x0..x1.max(x0 + 1) {
                    for (c, s) in sum.iter_mut().enumerate() {
                        *s += u32::from(src[(y * w + x) * 3 + c]);
                    }
                }
            }
            let n = ((y1.max(y0 + 1) - y0) * (x1.max(x0 + 1) - x0)) as u32;
            for c in 0..3 {
                out[(ty * tw + tx) * 3 + c] = ((sum[c] + n / 2) / n) as u8;
            }
        }
    }
    out
}

fn png(path: &Path, rgb: &[u8], w: usize, h: usize) -> Result<(), String> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(rgb, w as u32, h as u32, image::ExtendedColorType::Rgb8)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    std::fs::write(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shrink_averages_boxes_and_keeps_flat_colours() {
        // 4×2 → 2×1: each output pixel is the mean of a 2×2 block.
        let src: Vec<u8> = [0u8, 100, 200, 40]
            .iter()
            .cycle()
            .take(8)
            .flat_map(|&v| [v; 3])
            .collect();
        let out = shrink(&src, 4, 2, 2, 1);
        assert_eq!(out, vec![50, 50, 50, 120, 120, 120]);
        let flat = vec![77u8; 5 * 3 * 3];
        assert!(shrink(&flat, 5, 3, 2, 2).iter().all(|&v| v == 77));
    }

    #[test]
    fn tone_map_exposes_radiance_and_maps_normals() {
        let lit = Pass {
            rgb: (0..100).map(|i| [i as f32 * 10.0; 3]).collect(),
        };
        let px = tone_map("lit0", &lit);
        // The 98th percentile (980) lands near 0.9 → sRGB ≈ 243; nothing overflows.
        assert!((240..=246).contains(&px[98 * 3]), "{}", px[98 * 3]);
        assert_eq!(px[0], 0);
        let n = Pass {
            rgb: vec![[-1.0, 0.0, 1.0]],
        };
        assert_eq!(tone_map("normal", &n), vec![0, 128, 255]);
    }

    #[test]
    fn a_file_that_is_no_exr_is_named_as_such() {
        let err = decode(b"not an exr").err().unwrap_or_default();
        assert!(err.contains("not a readable OpenEXR"), "{err}");
    }
}
