//! The real portraits adaptation trains on. The folder is scanned once; each photo is prepared
//! on first use — decoded, matted with MODNet (unless it has alpha), cropped square around the
//! subject and resized — and kept in the run directory as a small RGBA PNG, so later epochs
//! and resumed runs read that. A photo that cannot be used is logged by name once, remembered
//! (`.skip` file with the reason) and never drawn again. When faces are asked for (the
//! identity loss, the real-photo metrics), the prepared photo's face is found and aligned with
//! dlib's detector and 5-point landmarks (`.face` file); a photo without a detectable face is
//! skipped the same way (`.noface` file, so a later run that needs no face still uses it).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use image::imageops::{resize, FilterType};
use image::{ImageBuffer, Rgba, RgbaImage};
use lightfarm_face::{Alignment, Detection, Image, LazyFaces};
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
    /// The face, in this image's pixels, when the set was opened with face models.
    pub face: Option<Alignment>,
}

pub struct PhotoSet {
    dir: PathBuf,
    files: Vec<PathBuf>,
    cache: PathBuf,
    size: usize,
    matting: LazyMatting,
    faces: Option<Arc<LazyFaces>>,
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
    /// `cache`. A folder without any is an error naming it. With `faces`, every photo must
    /// show a detectable face.
    pub fn open(
        dir: &Path,
        cache: &Path,
        size: usize,
        matting: LazyMatting,
        faces: Option<Arc<LazyFaces>>,
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
            faces,
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
        let face_file = self.cache.join(format!("{key}.face"));
        let none_file = self.cache.join(format!("{key}.noface"));
        // What the cache knows of the face: Some(None) = no face, None = not looked for.
        let cached_face = || -> Option<Option<Alignment>> {
            if none_file.exists() {
                return Some(None);
            }
            let text = std::fs::read_to_string(&face_file).ok()?;
            parse_face(&text).map(Some)
        };
        let cached = image::open(&png).ok().and_then(|img| {
            let face = match &self.faces {
                None => None,
                Some(_) => Some(cached_face()?),
            };
            Some((img.to_rgba8(), face))
        });
        let (img, face) = match cached {
            Some(hit) => hit,
            None => match self.prepare(i)? {
                Ok((img, face)) => {
                    let tmp = png.with_extension("png.tmp");
                    img.save_with_format(&tmp, image::ImageFormat::Png)
                        .map_err(|e| TrainError::Input(format!("{}: {e}", tmp.display())))?;
                    std::fs::rename(&tmp, &png).map_err(|e| TrainError::io(&png, e))?;
                    match &face {
                        Some(Some(a)) => std::fs::write(&face_file, format_face(a))
                            .map_err(|e| TrainError::io(&face_file, e))?,
                        Some(None) => std::fs::write(&none_file, "")
                            .map_err(|e| TrainError::io(&none_file, e))?,
                        None => {}
                    }
                    (img, face)
                }
                Err(reason) => {
                    std::fs::write(&skip_file, &reason)
                        .map_err(|e| TrainError::io(&skip_file, e))?;
                    self.skip(i, reason);
                    return Ok(None);
                }
            },
        };
        let mut prepared = from_rgba(&img);
        match face {
            Some(None) => {
                self.skip(i, "no face found (dlib's CNN face detector)".into());
                return Ok(None);
            }
            Some(Some(a)) => prepared.face = Some(a),
            None => {}
        }
        Ok(Some(prepared))
    }

    /// The face of the whole photo, found by dlib's detector and landmarks, mapped into the
    /// square crop (x0, y0, side) resized to the output size; Some(None) when there is none,
    /// None when no faces were asked for.
    fn find_face(
        &self,
        rgba: &ImageBuffer<Rgba<f32>, Vec<f32>>,
        (x0, y0, side): (usize, usize, usize),
    ) -> Result<Option<Option<Alignment>>, TrainError> {
        let Some(faces) = &self.faces else {
            return Ok(None);
        };
        let aligner = faces
            .get()
            .map_err(|e| TrainError::Config(format!("face models: {e}")))?;
        let rgb: Vec<u8> = rgba
            .pixels()
            .flat_map(|p| [p[0], p[1], p[2]].map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
            .collect();
        let (w, h) = (rgba.width() as usize, rgba.height() as usize);
        let image = Image::new(&rgb, w, h).map_err(|e| TrainError::Input(e.to_string()))?;
        Ok(Some(aligner.align(&image).map(|a| {
            a.in_crop(x0 as f32, y0 as f32, side as f32, self.size as f32)
        })))
    }

    /// The prepared 8-bit RGBA image and its face (see [`Self::find_face`]), or why the photo
    /// cannot be used.
    #[allow(clippy::type_complexity)]
    fn prepare(
        &self,
        i: usize,
    ) -> Result<Result<(RgbaImage, Option<Option<Alignment>>), String>, TrainError> {
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
        let face = self.find_face(&rgba, (x0, y0, side))?;
        Ok(Ok((
            RgbaImage::from_fn(s, s, |x, y| {
                let p = small.get_pixel(x, y);
                Rgba(p.0.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
            }),
            face,
        )))
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
        face: None,
    }
}

/// A face as one line of numbers: box (left, top, width, height, score), then the landmarks.
fn format_face(a: &Alignment) -> String {
    let f = &a.face;
    let mut v = vec![f.left, f.top, f.width, f.height, f.score];
    v.extend(a.landmarks.iter().flatten());
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

fn parse_face(text: &str) -> Option<Alignment> {
    let v: Vec<f32> = text
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()?;
    if v.len() != 15 || v.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let face = Detection {
        left: v[0],
        top: v[1],
        width: v[2],
        height: v[3],
        score: v[4],
    };
    Some(Alignment::new(
        face,
        v[5..].chunks_exact(2).map(|p| [p[0], p[1]]).collect(),
    ))
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
