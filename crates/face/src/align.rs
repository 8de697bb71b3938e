//! A face, located and aligned: the detector's box, the five landmarks in it, and the
//! similarity that maps dlib's 150² face chip onto the image (dlib's `get_face_chip_details`
//! with the face_recognition default padding 0.25). Chips are cut on Burn with a bilinear grid
//! sample, so the identity loss is differentiable through the cut too.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use burn::prelude::*;
use burn::tensor::module::avg_pool2d;
use burn::tensor::ops::{
    AvgPoolOptions, GridSampleOptions, GridSamplePaddingMode, InterpolateMode,
};

use crate::detect::{Detection, FaceDetector};
use crate::landmarks::{similarity, ShapePredictor, Similarity};
use crate::{FaceError, Image, CHIP_SIZE};

/// Where dlib's chip puts the five landmarks (outer and inner corner of the image-right eye,
/// then of the image-left eye, then the base of the nose), as fractions of an unpadded chip:
/// the constants of dlib's `get_face_chip_details` for the 5-point model.
const TEMPLATE: [[f32; 2]; 5] = [
    [0.859_567_46, 0.213_498_15],
    [0.646_060_5, 0.228_967_44],
    [0.120_575_06, 0.213_727_45],
    [0.334_085_06, 0.229_064_24],
    [0.490_112_3, 0.627_797_5],
];

/// Margin around the template, as a fraction of it on each side (dlib's
/// `compute_face_descriptor` default).
pub const CHIP_PADDING: f32 = 0.25;

/// A face in an image.
#[derive(Clone, Debug, PartialEq)]
pub struct Alignment {
    pub face: Detection,
    /// The five landmarks, in image pixels.
    pub landmarks: Vec<[f32; 2]>,
    /// Chip pixel → image pixel.
    chip: Similarity,
}

impl PartialEq for Similarity {
    fn eq(&self, o: &Self) -> bool {
        self.a == o.a && self.b == o.b && self.t == o.t
    }
}

impl Alignment {
    /// The alignment of a face from its box and five landmarks (in dlib's order), e.g. as
    /// cached from an earlier [`FaceAligner::align`].
    pub fn new(face: Detection, landmarks: Vec<[f32; 2]>) -> Self {
        let n = CHIP_SIZE as f32;
        let template: Vec<[f32; 2]> = TEMPLATE
            .iter()
            .map(|p| p.map(|v| (CHIP_PADDING + v) / (2.0 * CHIP_PADDING + 1.0) * n))
            .collect();
        let chip = similarity(&template, &landmarks);
        Alignment {
            face,
            landmarks,
            chip,
        }
    }

    /// The same face in a crop of the image: the square (x0, y0, side) resized to `size`.
    pub fn in_crop(&self, x0: f32, y0: f32, side: f32, size: f32) -> Alignment {
        let k = size / side;
        let map = |p: [f32; 2]| [(p[0] - x0) * k, (p[1] - y0) * k];
        let f = &self.face;
        let [left, top] = map([f.left, f.top]);
        Alignment::new(
            Detection {
                left,
                top,
                width: f.width * k,
                height: f.height * k,
                score: f.score,
            },
            self.landmarks.iter().map(|&p| map(p)).collect(),
        )
    }

    /// Image pixels per chip pixel.
    pub fn scale(&self) -> f32 {
        self.chip.scale()
    }

    /// The image point of chip pixel (u, v).
    pub fn chip_to_image(&self, u: f32, v: f32) -> [f32; 2] {
        self.chip.apply([u, v])
    }
}

/// The face chips of a batch of images ([B, 3, H, W], any value range) → [B, 3, 150, 150],
/// image `k` cut by `alignments[k]`. Where the chip leaves the image it is 0.
pub fn face_chips(images: Tensor<4>, alignments: &[Alignment]) -> Tensor<4> {
    let [b, _, h, w] = images.dims();
    assert_eq!(b, alignments.len(), "one alignment per image");
    let device = images.device();
    // Bilinear sampling aliases when it skips pixels; average k×k blocks first when the chip
    // is at least k times smaller than the face.
    let k = alignments
        .iter()
        .map(|a| a.scale().floor() as usize)
        .min()
        .unwrap_or(1)
        .clamp(1, h.min(w));
    let (images, h, w) = if k > 1 {
        let pooled = avg_pool2d(images, AvgPoolOptions::new([k, k]).with_stride([k, k]));
        let [_, _, ph, pw] = pooled.dims();
        (pooled, ph, pw)
    } else {
        (images, h, w)
    };
    let n = CHIP_SIZE;
    let mut grid = Vec::with_capacity(b * n * n * 2);
    for a in alignments {
        for v in 0..n {
            for u in 0..n {
                let [x, y] = a.chip_to_image(u as f32, v as f32);
                let (x, y) = ((x + 0.5) / k as f32 - 0.5, (y + 0.5) / k as f32 - 0.5);
                grid.push(2.0 * x / (w.max(2) - 1) as f32 - 1.0);
                grid.push(2.0 * y / (h.max(2) - 1) as f32 - 1.0);
            }
        }
    }
    let grid = Tensor::<1>::from_floats(grid.as_slice(), &device).reshape([b, n, n, 2]);
    images.grid_sample_2d(
        grid,
        GridSampleOptions::new(InterpolateMode::Bilinear)
            .with_padding_mode(GridSamplePaddingMode::Zeros)
            .with_align_corners(true),
    )
}

/// The detector and the landmark model together.
pub struct FaceAligner {
    detector: FaceDetector,
    landmarks: ShapePredictor,
    device: Device,
}

impl FaceAligner {
    pub fn load(detector: &Path, landmarks: &Path, device: &Device) -> Result<Self, FaceError> {
        Ok(FaceAligner {
            detector: FaceDetector::load(detector, device)?,
            landmarks: ShapePredictor::load(landmarks)?,
            device: device.clone(),
        })
    }

    /// The models `./scripts/fetch-models.sh` installs.
    pub fn builtin(device: &Device) -> Result<Self, FaceError> {
        Self::load(
            &crate::detect::builtin_detector(),
            &crate::landmarks::builtin_landmarks(),
            device,
        )
    }

    /// The faces in `image`, best first.
    pub fn detect(&self, image: &Image<'_>) -> Vec<Detection> {
        self.detector.detect(image, &self.device)
    }

    /// The best face of `image`, aligned; `None` when the detector finds none.
    pub fn align(&self, image: &Image<'_>) -> Option<Alignment> {
        let face = self.detect(image).into_iter().next()?;
        Some(self.align_box(image, face))
    }

    /// The face in a known box.
    pub fn align_box(&self, image: &Image<'_>, face: Detection) -> Alignment {
        Alignment::new(face, self.landmarks.predict(image, &face))
    }
}

/// The face models, loaded the first time a photo needs them, so commands that never align a
/// face never read them.
pub struct LazyFaces {
    detector: PathBuf,
    landmarks: PathBuf,
    device: Device,
    loaded: Mutex<Option<Arc<FaceAligner>>>,
}

impl LazyFaces {
    pub fn new(detector: PathBuf, landmarks: PathBuf, device: Device) -> Self {
        LazyFaces {
            detector,
            landmarks,
            device,
            loaded: Mutex::new(None),
        }
    }

    /// The models `./scripts/fetch-models.sh` installs, not yet loaded.
    pub fn builtin(device: Device) -> Self {
        Self::new(
            crate::detect::builtin_detector(),
            crate::landmarks::builtin_landmarks(),
            device,
        )
    }

    pub fn get(&self) -> Result<Arc<FaceAligner>, FaceError> {
        let mut loaded = self.loaded.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(a) = loaded.as_ref() {
            return Ok(a.clone());
        }
        let a = Arc::new(FaceAligner::load(
            &self.detector,
            &self.landmarks,
            &self.device,
        )?);
        *loaded = Some(a.clone());
        Ok(a)
    }
}
