//! The in-memory lat-long environment map.

use std::path::{Path, PathBuf};

use crate::load::LightError;
use crate::mapping::dir_to_uv;

/// Name used in errors for maps that did not come from a file.
const IN_MEMORY: &str = "<in-memory texels>";

/// Largest accepted width; 16k maps exist, anything far beyond is a corrupt header and would
/// otherwise make us allocate gigabytes before noticing.
pub(crate) const MAX_WIDTH: u32 = 32_768;

/// A lat-long environment map: linear RGB, row-major, row 0 = top (v = 0 = +Y).
#[derive(Clone, Debug, PartialEq)]
pub struct Hdri {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[f32; 3]>,
}

impl Hdri {
    /// A map of one colour. Zero sizes are raised to 1 so that `lookup` always has a texel;
    /// the size is not checked for 2:1 because constant maps look the same at any aspect.
    pub fn constant(width: u32, height: u32, rgb: [f32; 3]) -> Hdri {
        let width = width.max(1);
        let height = height.max(1);
        Hdri {
            width,
            height,
            texels: vec![rgb; width as usize * height as usize],
        }
    }

    /// Builds a map from texels with the same checks as [`Hdri::load`]: 2:1 size,
    /// `texels.len() == width * height`, finite values; negative values are clamped to 0.
    pub fn from_texels(width: u32, height: u32, texels: Vec<[f32; 3]>) -> Result<Hdri, LightError> {
        Self::from_texels_named(Path::new(IN_MEMORY), width, height, texels)
    }

    /// [`Hdri::from_texels`] with errors naming `path`, shared with the file loaders.
    pub(crate) fn from_texels_named(
        path: &Path,
        width: u32,
        height: u32,
        mut texels: Vec<[f32; 3]>,
    ) -> Result<Hdri, LightError> {
        check_size(path, width, height)?;
        let expected = width as usize * height as usize;
        if texels.len() != expected {
            return Err(LightError::InvalidSize {
                path: PathBuf::from(path),
                width,
                height,
                reason: format!(
                    "it holds {} texels but {width}x{height} needs {expected}",
                    texels.len()
                ),
            });
        }
        let non_finite = texels.iter().flatten().filter(|c| !c.is_finite()).count();
        if non_finite > 0 {
            return Err(LightError::NonFinite {
                path: PathBuf::from(path),
                count: non_finite,
            });
        }
        let mut clamped = 0usize;
        for c in texels.iter_mut().flatten() {
            // Lossy EXR compression (DWAB) leaves small negatives; a negative radiance would
            // make the sampling pdf negative, so clamp here once for every consumer.
            if *c < 0.0 {
                *c = 0.0;
                clamped += 1;
            } else if *c == 0.0 {
                // Normalizes -0.0 so the data is bit-identical whatever the sign of zero.
                *c = 0.0;
            }
        }
        if clamped > 0 {
            tracing::debug!(
                path = %path.display(),
                clamped,
                "clamped negative texel values to 0"
            );
        }
        Ok(Hdri {
            width,
            height,
            texels,
        })
    }

    /// Rec.709 luminance of a linear RGB triple.
    pub fn luminance(rgb: [f32; 3]) -> f32 {
        0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
    }

    /// The texel (nearest, no filtering) seen in env-local direction `dir_env`.
    pub fn lookup(&self, dir_env: [f32; 3]) -> [f32; 3] {
        let [u, v] = dir_to_uv(dir_env);
        let (x, y) = self.texel_index([u, v]);
        self.texels
            .get(y * self.width as usize + x)
            .copied()
            .unwrap_or([0.0; 3])
    }

    /// Column and row of the texel containing `uv`; out-of-range and NaN coordinates clamp
    /// to the border (float-to-int casts saturate, NaN -> 0).
    pub(crate) fn texel_index(&self, uv: [f32; 2]) -> (usize, usize) {
        let w = self.width.max(1) as usize;
        let h = self.height.max(1) as usize;
        let x = ((uv[0] * w as f32) as usize).min(w - 1);
        let y = ((uv[1] * h as f32) as usize).min(h - 1);
        (x, y)
    }

    /// Mean Rec.709 luminance over texels (not solid-angle weighted), as LICENSES.md reports.
    pub fn mean_luminance(&self) -> f64 {
        if self.texels.is_empty() {
            return 0.0;
        }
        let sum: f64 = self
            .texels
            .iter()
            .map(|t| f64::from(Hdri::luminance(*t)))
            .sum();
        sum / self.texels.len() as f64
    }
}

/// Lat-long maps must be exactly 2:1; anything else means the file is not equirectangular
/// (a cube cross, a mirror ball) and sampling it as lat-long would light scenes wrongly.
pub(crate) fn check_size(path: &Path, width: u32, height: u32) -> Result<(), LightError> {
    let reason = if width == 0 || height == 0 {
        Some("the map is empty".to_string())
    } else if u64::from(width) != 2 * u64::from(height) {
        Some(
            "a lat-long (equirectangular) map must be twice as wide as it is high \
             (e.g. 1024x512); convert it to a 2:1 lat-long map"
                .to_string(),
        )
    } else if width > MAX_WIDTH {
        Some(format!(
            "wider than the supported maximum of {MAX_WIDTH}; downsample the map"
        ))
    } else {
        None
    };
    match reason {
        Some(reason) => Err(LightError::InvalidSize {
            path: PathBuf::from(path),
            width,
            height,
            reason,
        }),
        None => Ok(()),
    }
}
