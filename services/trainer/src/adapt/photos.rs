//! The real portraits adaptation trains on. The folder is scanned once; each photo is prepared
//! on first use — decoded, matted with MODNet (unless it has alpha), cropped square around the
//! subject and resized — and kept in the run directory as a small RGBA PNG, so later epochs
//! and resumed runs read that. A photo that cannot be used is logged by name once, remembered
//! (`.skip` file with the reason) and never drawn again.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use image::imageops::{resize, FilterType};
use image::{ImageBuffer, Rgba, RgbaImage};
use lightfarm_photo::LazyMatting;

use crate::image_io::srgb_decode;
use crate::TrainError;

/// Foreground share below which a photo is taken to show no subject.
const MIN_COVERAGE: f32 = 0.02;

/// A prepared photo: linear RGB and its foreground alpha, `size` × `size`, row-major.
#[derive(Clone, Debug)]
pub struct Prepared {
    pub rgb: Vec<[f32; 3]>,
    pub mask: Vec<f32>,
}

pub struct PhotoSet {
    dir: PathBuf,
    files: Vec<PathBuf>,
    cache: PathBuf,
    size: usize,
    matting: LazyMatting,
    /// Index → why it cannot be used.
    skipped: Mutex<HashMap<usize, String>>,
}

fn is_photo(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["jpg", "jpeg", "png"].contains(&e.to_ascii_lowercase().as_str()))
}

fn scan(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), TrainError> {
    let entries = std::fs::read_dir(dir).map_err(|e| TrainError::io(dir, e))?;
    for e in entries {
        let path = e.map_err(|e| TrainError::io(dir, e))?.path();
        if path.is_dir() {
            scan(&path, out)?;
        } else if is_photo(&path) {
            out.push(path);
        }
    }
    Ok(())
}

impl PhotoSet {
    /// The JPEG and PNG files under `dir` (recursively, in path order); prepared photos go to
    /// `cache`. A folder without any is an error naming it.
    pub fn open(
        dir: &Path,
        cache: &Path,
        size: usize,
        matting: LazyMatting,
    ) -> Result<PhotoSet, TrainError> {
        if !dir.is_dir() {
            return Err(TrainError::Config(format!(
                "photos = {}: not a folder; give a folder of real portraits (JPEG or PNG)",
                dir.display()
            )));
        }
        let mut files = Vec::new();
        scan(dir, &mut files)?;
        files.sort();
        if files.is_empty() {
            return Err(TrainError::Config(format!(
                "photos = {}: no .jpg, .jpeg or .png files there",
                dir.display()
            )));
        }
        std::fs::create_dir_all(cache).map_err(|e| TrainError::io(cache, e))?;
        Ok(PhotoSet {
            dir: dir.to_owned(),
            files,
            cache: cache.to_owned(),
            size,
            matting,
            skipped: Mutex::new(HashMap::new()),
        })
    }

    pub fn len(&self) -> usize {
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Photos found unusable so far.
    pub fn skipped(&self) -> usize {
        self.skipped.lock().map(|s| s.len()).unwrap_or(0)
    }

    pub fn folder(&self) -> &Path {
        &self.dir
    }

    /// Cache key: the file's path under the folder, length and modification time, and the
    /// output size, so an edited photo is prepared again.
    fn key(&self, i: usize) -> Result<String, TrainError> {
        let path = &self.files[i];
        let meta = std::fs::metadata(path).map_err(|e| TrainError::io(path, e))?;
        let mtime = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_nanos());
        let rel = path.strip_prefix(&self.dir).unwrap_or(path);
        let text = format!("{}\n{}\n{mtime}\n{}", rel.display(), meta.len(), self.size);
        Ok(blake3::hash(text.as_bytes()).to_hex()[..24].to_string())
    }

    fn skip(&self, i: usize, reason: String) {
        tracing::warn!(photo = %self.files[i].display(), %reason, "skipping photo");
        if let Ok(mut s) = self.skipped.lock() {
            s.insert(i, reason);
        }
    }

    /// Photo `i` prepared, or None when it cannot be used (logged once). Errors are problems
    /// of the installation (no MODNet, an unwritable cache), not of the photo.
    pub fn get(&self, i: usize) -> Result<Option<Prepared>, TrainError> {
        if self
            .skipped
            .lock()
            .map(|s| s.contains_key(&i))
            .unwrap_or(false)
        {
            return Ok(None);
        }
        let key = self.key(i)?;
        let png = self.cache.join(format!("{key}.png"));
        let skip_file = self.cache.join(format!("{key}.skip"));
        if let Ok(reason) = std::fs::read_to_string(&skip_file) {
            self.skip(i, reason);
            return Ok(None);
        }
        if let Ok(img) = image::open(&png) {
            return Ok(Some(from_rgba(&img.to_rgba8())));
        }
        match self.prepare(i)? {
            Ok(img) => {
                let tmp = png.with_extension("png.tmp");
                img.save_with_format(&tmp, image::ImageFormat::Png)
                    .map_err(|e| TrainError::Input(format!("{}: {e}", tmp.display())))?;
                std::fs::rename(&tmp, &png).map_err(|e| TrainError::io(&png, e))?;
                Ok(Some(from_rgba(&img)))
            }
            Err(reason) => {
                std::fs::write(&skip_file, &reason).map_err(|e| TrainError::io(&skip_file, e))?;
                self.skip(i, reason);
                Ok(None)
            }
        }
    }

    /// The prepared 8-bit RGBA image, or why the photo cannot be used.
    fn prepare(&self, i: usize) -> Result<Result<RgbaImage, String>, TrainError> {
        let path = &self.files[i];
        let bytes = match std::fs::read(path) {
            Ok(b) => b,
            Err(e) => return Ok(Err(format!("cannot read it ({e})"))),
        };
        let img = match image::load_from_memory(&bytes) {
            Ok(img) => img,
            Err(e) => return Ok(Err(format!("not a readable image ({e})"))),
        };
        let has_alpha = img.color().has_alpha();
        let rgba = img.to_rgba32f();
        let (w, h) = (rgba.width() as usize, rgba.height() as usize);
        if w < 16 || h < 16 {
            return Ok(Err(format!("{w}x{h} is too small")));
        }
        let alpha: Vec<f32> = if has_alpha {
            rgba.pixels().map(|p| p[3]).collect()
        } else {
            let srgb: Vec<[f32; 3]> = rgba.pixels().map(|p| [p[0], p[1], p[2]]).collect();
            self.matting.get()?.alpha(&srgb, w, h)?
        };
        let coverage = alpha.iter().sum::<f32>() / alpha.len() as f32;
        if coverage < MIN_COVERAGE {
            return Ok(Err(format!(
                "no subject: the matte covers {:.1}% of the photo",
                coverage * 100.0
            )));
        }
        let (x0, y0, side) = crop_square(&alpha, w, h);
        let cropped: ImageBuffer<Rgba<f32>, Vec<f32>> =
            ImageBuffer::from_fn(side as u32, side as u32, |x, y| {
                let (sx, sy) = (x0 + x as usize, y0 + y as usize);
                let p = rgba.get_pixel(sx as u32, sy as u32);
                Rgba([p[0], p[1], p[2], alpha[sy * w + sx]])
            });
        let s = self.size as u32;
        let small = resize(&cropped, s, s, FilterType::Triangle);
        Ok(Ok(RgbaImage::from_fn(s, s, |x, y| {
            let p = small.get_pixel(x, y);
            Rgba(p.0.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
        })))
    }
}

/// (left, top, side) of the square crop: the short side of the photo, centred on the
/// foreground horizontally and, in a portrait-format photo, starting just above the top of the
/// foreground (where the head is), like the renders' framing.
pub(crate) fn crop_square(alpha: &[f32], w: usize, h: usize) -> (usize, usize, usize) {
    let side = w.min(h);
    let (mut sx, mut sum) = (0f64, 0f64);
    let mut top = h;
    for y in 0..h {
        for x in 0..w {
            let a = f64::from(alpha[y * w + x]);
            sx += a * x as f64;
            sum += a;
            if a > 0.5 && y < top {
                top = y;
            }
        }
    }
    let cx = if sum > 0.0 { sx / sum } else { w as f64 / 2.0 };
    let x0 = (cx - side as f64 / 2.0)
        .round()
        .clamp(0.0, (w - side) as f64) as usize;
    let top = if top == h { 0 } else { top };
    let y0 = top.saturating_sub(side / 20).min(h - side);
    (x0, y0, side)
}

fn from_rgba(img: &RgbaImage) -> Prepared {
    Prepared {
        rgb: img
            .pixels()
            .map(|p| [p[0], p[1], p[2]].map(|v| srgb_decode(f32::from(v) / 255.0)))
            .collect(),
        mask: img.pixels().map(|p| f32::from(p[3]) / 255.0).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::crop_square;

    #[test]
    fn crops_follow_the_subject() {
        // A landscape photo with the subject on the right third: the crop moves right.
        let (w, h) = (300, 100);
        let alpha: Vec<f32> = (0..w * h)
            .map(|i| {
                if (200..260).contains(&(i % w)) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        assert_eq!(crop_square(&alpha, w, h), (180, 0, 100));
        // A portrait photo whose subject starts at row 150: the crop starts just above it.
        let (w, h) = (100, 400);
        let alpha: Vec<f32> = (0..w * h)
            .map(|i| if i / w >= 150 { 1.0 } else { 0.0 })
            .collect();
        assert_eq!(crop_square(&alpha, w, h), (0, 145, 100));
        // No foreground: centred, from the top.
        assert_eq!(crop_square(&vec![0.0; 50 * 80], 50, 80), (0, 0, 50));
    }
}
