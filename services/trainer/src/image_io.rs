//! Portrait images in and out of `relight`: PNG/JPEG (sRGB) or OpenEXR (linear), an optional
//! mask or a MODNet matte, and display PNGs.

use std::path::Path;

use lightfarm_photo::LazyMatting;

use lightfarm_nets::metrics::srgb_encode;

use lightfarm_store::ExrLayer;

use crate::sample::{decode_sample, SampleImages};
use crate::TrainError;

/// An input portrait in linear RGB with its foreground mask.
pub struct Portrait {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<[f32; 3]>,
    pub mask: Vec<f32>,
    /// Set when the input was a lightfarm sample EXR (its camera orients the light maps).
    pub sample: Option<SampleImages>,
    /// The mask is MODNet's matte of the photo.
    pub matted: bool,
}

/// sRGB → linear.
pub fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Reads `path`: a lightfarm sample EXR (lit0 and its mask), any RGB(A) EXR, or an 8/16-bit
/// image (sRGB decoded; alpha is the mask). `mask` (white = subject) overrides the built-in one.
/// A photo with neither is matted with `matte` (MODNet) when given, else all foreground.
pub fn load_portrait(
    path: &Path,
    mask: Option<&Path>,
    matte: Option<&LazyMatting>,
) -> Result<Portrait, TrainError> {
    let bad = |r: String| TrainError::Input(format!("--image {}: {r}", path.display()));
    let bytes = std::fs::read(path).map_err(|e| TrainError::io(path, e))?;
    let is_exr = bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]);
    // `own_mask`: the file says what is foreground (a sample's coverage, an alpha channel).
    let (mut p, own_mask) = if is_exr {
        match decode_sample(&bytes, &path.display().to_string()) {
            Ok(s) => (
                Portrait {
                    width: s.width,
                    height: s.height,
                    rgb: s.lit[0].clone(),
                    mask: s.mask.clone(),
                    sample: Some(s),
                    matted: false,
                },
                true,
            ),
            Err(_) => load_plain_exr(&bytes).map_err(bad)?,
        }
    } else {
        let img = image::load_from_memory(&bytes)
            .map_err(|e| bad(format!("not a readable image ({e})")))?;
        let rgba = img.to_rgba32f();
        let (w, h) = (rgba.width() as usize, rgba.height() as usize);
        let has_alpha = img.color().has_alpha();
        let p = Portrait {
            width: w,
            height: h,
            rgb: rgba
                .pixels()
                .map(|p| [p[0], p[1], p[2]].map(srgb_decode))
                .collect(),
            mask: rgba
                .pixels()
                .map(|p| if has_alpha { p[3] } else { 1.0 })
                .collect(),
            sample: None,
            matted: false,
        };
        (p, has_alpha)
    };
    if p.width == 0 || p.height == 0 || p.width > 8192 || p.height > 8192 {
        return Err(bad(format!(
            "{}x{} is outside 1..=8192 pixels a side",
            p.width, p.height
        )));
    }
    if let Some(m) = mask {
        let img = image::open(m)
            .map_err(|e| {
                TrainError::Input(format!(
                    "--mask {}: not a readable image ({e})",
                    m.display()
                ))
            })?
            .to_luma32f();
        if (img.width() as usize, img.height() as usize) != (p.width, p.height) {
            return Err(TrainError::Input(format!(
                "--mask {} is {}x{} but the image is {}x{}",
                m.display(),
                img.width(),
                img.height(),
                p.width,
                p.height
            )));
        }
        p.mask = img.pixels().map(|v| v[0].clamp(0.0, 1.0)).collect();
    } else if let (false, Some(matte)) = (own_mask, matte) {
        let srgb: Vec<[f32; 3]> = p.rgb.iter().map(|c| c.map(srgb_encode)).collect();
        p.mask = matte.get()?.alpha(&srgb, p.width, p.height)?;
        p.matted = true;
    }
    for (c, &m) in p.rgb.iter_mut().zip(&p.mask) {
        *c = c.map(|v| if v.is_finite() { v.max(0.0) * m } else { 0.0 });
    }
    Ok(p)
}

/// An RGB(A) EXR, and whether it had an alpha channel.
fn load_plain_exr(bytes: &[u8]) -> Result<(Portrait, bool), String> {
    let layer = ExrLayer::read(bytes)?;
    let (w, h) = (layer.width, layer.height);
    let find = |n: &str| layer.channel_any_case(n).transpose();
    let (r, g, b) = match (find("R")?, find("G")?, find("B")?) {
        (Some(r), Some(g), Some(b)) => (r, g, b),
        _ => return Err("has no R, G, B channels".into()),
    };
    let alpha = find("A")?;
    let has_alpha = alpha.is_some();
    let a = alpha.unwrap_or_else(|| vec![1.0; w * h]);
    let p = Portrait {
        width: w,
        height: h,
        rgb: (0..w * h).map(|i| [r[i], g[i], b[i]]).collect(),
        mask: a.into_iter().map(|v| v.clamp(0.0, 1.0)).collect(),
        sample: None,
        matted: false,
    };
    Ok((p, has_alpha))
}

/// Writes linear RGB as an sRGB PNG (clamped).
pub fn write_png(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[[f32; 3]],
) -> Result<(), TrainError> {
    let bytes = png_bytes(width, height, rgb)?;
    std::fs::write(path, bytes).map_err(|e| TrainError::io(path, e))
}

/// Linear RGB as sRGB PNG bytes.
pub fn png_bytes(width: usize, height: usize, rgb: &[[f32; 3]]) -> Result<Vec<u8>, TrainError> {
    let data: Vec<u8> = rgb
        .iter()
        .flat_map(|p| p.map(|v| (srgb_encode(v) * 255.0 + 0.5) as u8))
        .collect();
    let img = image::RgbImage::from_raw(width as u32, height as u32, data)
        .ok_or_else(|| TrainError::Input("image buffer of the wrong size".into()))?;
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .map_err(|e| TrainError::Input(format!("encoding a PNG: {e}")))?;
    Ok(out)
}

/// A mask or alpha in [0, 1] as gray PNG bytes (linear: alpha is coverage, not light).
pub fn gray_png_bytes(width: usize, height: usize, v: &[f32]) -> Result<Vec<u8>, TrainError> {
    let data: Vec<u8> = v
        .iter()
        .map(|&a| {
            (if a.is_finite() {
                a.clamp(0.0, 1.0)
            } else {
                0.0
            } * 255.0
                + 0.5) as u8
        })
        .collect();
    let img = image::GrayImage::from_raw(width as u32, height as u32, data)
        .ok_or_else(|| TrainError::Input("mask buffer of the wrong size".into()))?;
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .map_err(|e| TrainError::Input(format!("encoding a PNG: {e}")))?;
    Ok(out)
}
