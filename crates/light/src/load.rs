//! Loading environment maps from disk, and the crate's error type.
//!
//! Maps come from users and asset stores, so every failure is an error naming the file; the
//! third-party decoders are additionally fenced with `catch_unwind` because a panic inside
//! them on a hostile file must not take a render worker down.

use std::io::Cursor;
use std::panic::{self, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use crate::hdri::{check_size, Hdri, MAX_WIDTH};

/// Errors from building or loading an environment map. Each names the file (or
/// `<in-memory texels>`) and says what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum LightError {
    #[error("cannot read environment map {}: {source}; check the path and its permissions", .path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("environment map {} could not be decoded: {reason}; the file is corrupt or truncated, re-download or re-export it", .path.display())]
    Decode { path: PathBuf, reason: String },
    #[error("environment map {} is neither Radiance .hdr nor OpenEXR (judged by its first bytes, not its name); convert it to .hdr or .exr", .path.display())]
    UnsupportedFormat { path: PathBuf },
    #[error("environment map {} is {width}x{height}: {reason}", .path.display())]
    InvalidSize {
        path: PathBuf,
        width: u32,
        height: u32,
        reason: String,
    },
    #[error("environment map {} has {count} NaN or infinite channel values; fix or re-export the map with finite values", .path.display())]
    NonFinite { path: PathBuf, count: usize },
    #[error("OLAT basis of {reason}")]
    InvalidOlat { reason: String },
}

/// OpenEXR magic number (first four bytes of every .exr file).
const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];
/// Radiance files start with `#?RADIANCE` or `#?RGBE`; `#?` is the common part.
const HDR_MAGIC: &[u8] = b"#?";

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Radiance,
    OpenExr,
}

fn sniff(bytes: &[u8]) -> Option<Format> {
    if bytes.starts_with(&EXR_MAGIC) {
        Some(Format::OpenExr)
    } else if bytes.starts_with(HDR_MAGIC) {
        Some(Format::Radiance)
    } else {
        None
    }
}

impl Hdri {
    /// Loads a lat-long map: Radiance `.hdr` (RLE RGBE) or OpenEXR (first layer with R, G, B;
    /// half or float), detected by magic bytes. Negative values are clamped to 0; NaN/inf,
    /// non-2:1 sizes and corrupt or truncated files are errors naming `path`.
    pub fn load(path: &Path) -> Result<Hdri, LightError> {
        let bytes = std::fs::read(path).map_err(|source| LightError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        if bytes.is_empty() {
            return Err(decode_err(path, "the file is empty (0 bytes)"));
        }
        let format = sniff(&bytes).ok_or_else(|| LightError::UnsupportedFormat {
            path: path.to_path_buf(),
        })?;
        let decoded = panic::catch_unwind(AssertUnwindSafe(|| match format {
            Format::Radiance => decode_radiance(path, &bytes),
            Format::OpenExr => decode_exr(path, &bytes),
        }));
        let (width, height, texels) = match decoded {
            Ok(result) => result?,
            Err(_) => {
                return Err(decode_err(
                    path,
                    "the decoder crashed on this file (see the log for its message)",
                ))
            }
        };
        let hdri = Hdri::from_texels_named(path, width, height, texels)?;
        tracing::info!(
            path = %path.display(),
            ?format,
            width,
            height,
            mean_luminance = hdri.mean_luminance(),
            "loaded environment map"
        );
        Ok(hdri)
    }
}

fn decode_err(path: &Path, reason: impl Into<String>) -> LightError {
    LightError::Decode {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

type Decoded = (u32, u32, Vec<[f32; 3]>);

fn decode_radiance(path: &Path, bytes: &[u8]) -> Result<Decoded, LightError> {
    use image::ImageDecoder;

    let decoder = image::codecs::hdr::HdrDecoder::new(Cursor::new(bytes))
        .map_err(|e| decode_err(path, format!("bad Radiance header: {e}")))?;
    let (width, height) = decoder.dimensions();
    // Check before decoding so a bogus header cannot make us allocate a huge buffer.
    check_size(path, width, height)?;
    let image = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| decode_err(path, format!("bad Radiance pixel data: {e}")))?;
    let rgb = image.into_rgb32f();
    let texels = rgb.pixels().map(|p| p.0).collect();
    Ok((width, height, texels))
}

fn decode_exr(path: &Path, bytes: &[u8]) -> Result<Decoded, LightError> {
    use exr::prelude::*;

    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
        .map_err(|e| decode_err(path, format!("bad OpenEXR header: {e}")))?;
    for header in meta.headers.iter() {
        let size = header.layer_size;
        let too_big = size.0 > MAX_WIDTH as usize || size.1 > MAX_WIDTH as usize;
        if too_big {
            return Err(LightError::InvalidSize {
                path: path.to_path_buf(),
                width: u32::try_from(size.0).unwrap_or(u32::MAX),
                height: u32::try_from(size.1).unwrap_or(u32::MAX),
                reason: format!(
                    "a layer is larger than the supported maximum of {MAX_WIDTH}; downsample the map"
                ),
            });
        }
    }

    struct Pixels {
        width: usize,
        texels: Vec<[f32; 3]>,
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |resolution, _channels: &RgbaChannels| Pixels {
                width: resolution.width(),
                texels: vec![[0.0; 3]; resolution.width() * resolution.height()],
            },
            |pixels: &mut Pixels, position, (r, g, b, _a): (f32, f32, f32, f32)| {
                let index = position.y() * pixels.width + position.x();
                if let Some(texel) = pixels.texels.get_mut(index) {
                    *texel = [r, g, b];
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| match e {
            Error::NotSupported(what) => decode_err(
                path,
                format!("unsupported OpenEXR feature or no layer with R, G and B channels: {what}"),
            ),
            other => decode_err(path, format!("bad OpenEXR data: {other}")),
        })?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let width = u32::try_from(w).map_err(|_| decode_err(path, "layer width out of range"))?;
    let height = u32::try_from(h).map_err(|_| decode_err(path, "layer height out of range"))?;
    Ok((width, height, layer.channel_data.pixels.texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sniffs_magic_bytes() {
        assert_eq!(sniff(b"#?RADIANCE\n"), Some(Format::Radiance));
        assert_eq!(sniff(b"#?RGBE\n"), Some(Format::Radiance));
        assert_eq!(
            sniff(&[0x76, 0x2f, 0x31, 0x01, 2, 0]),
            Some(Format::OpenExr)
        );
        assert_eq!(sniff(b"\x89PNG\r\n"), None);
        assert_eq!(sniff(b""), None);
    }

    #[test]
    fn from_texels_clamps_negatives_and_rejects_nan() {
        let ok = Hdri::from_texels(2, 1, vec![[-0.002, 1.0, 0.5], [0.0, -0.0, 3.0]]);
        let hdri = ok.expect("valid texels");
        assert_eq!(hdri.texels[0], [0.0, 1.0, 0.5]);
        assert!(hdri.texels[1][1].is_sign_positive());

        let err = Hdri::from_texels(2, 1, vec![[f32::NAN, 1.0, f32::INFINITY], [0.0; 3]])
            .expect_err("NaN must be rejected");
        assert!(
            matches!(err, LightError::NonFinite { count: 2, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("<in-memory texels>"));

        let err = Hdri::from_texels(2, 1, vec![[0.0; 3]]).expect_err("wrong length");
        assert!(matches!(err, LightError::InvalidSize { .. }), "{err}");
    }
}
