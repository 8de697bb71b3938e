//! dlib's CNN face detector (`mmod_human_face_detector.dat`, Davis King, public domain; King,
//! "Max-Margin Object Detection", 2015): a small fully convolutional network scored over an
//! image pyramid. Each output cell above 0 is a face whose 80×80 window (at that pyramid level)
//! is centred where the cell's receptive field is; overlapping detections are reduced by the
//! non-maximum suppression stored with the model.

use std::path::{Path, PathBuf};

use burn::prelude::*;
use burn::tensor::module::{avg_pool2d, interpolate};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions};

use crate::dlib::Reader;
use crate::dnn::{self, Layer, Op};
use crate::{FaceError, Image};

/// Where `./scripts/fetch-models.sh` installs the detector, relative to the asset directory.
pub const DETECTOR_FILE: &str = "models/dlib/mmod_human_face_detector.dat";

/// The built-in detector in the asset pack.
pub fn builtin_detector() -> PathBuf {
    lightfarm_scene::catalog::builtin_assets_dir().join(DETECTOR_FILE)
}

/// dlib's `pyramid_down<6>`: each level is 5/6 the size of the one before.
const PYRAMID_STEP: f32 = 5.0 / 6.0;

/// The first pyramid level has a short side in this range: small images are upsampled (by an
/// integer factor of at most 4, so a 128-pixel portrait's face reaches the 80-pixel window),
/// large ones brought down (a portrait's face stays far above the window, and the pyramid of a
/// 4000-pixel photo would cost a minute on a CPU).
const FIRST_LEVEL: (usize, usize) = (512, 1024);

/// A face found in an image, in its pixel coordinates (x right, y down; `left`/`top` is the
/// corner of the box).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    pub left: f32,
    pub top: f32,
    pub width: f32,
    pub height: f32,
    /// The detector's score; above 0 is a face.
    pub score: f32,
}

impl Detection {
    fn iou(&self, o: &Detection) -> f32 {
        let w = (self.left + self.width).min(o.left + o.width) - self.left.max(o.left);
        let h = (self.top + self.height).min(o.top + o.height) - self.top.max(o.top);
        let inter = w.max(0.0) * h.max(0.0);
        inter / (self.width * self.height + o.width * o.height - inter)
    }
}

/// The `con<1,9,9,1,1, rcon5<rcon5<rcon5<downsampler<…>>>>>` of dlib's `dnn_mmod_face_detection_ex`,
/// outermost first.
fn architecture() -> Vec<Layer> {
    use Layer::*;
    let mut l = vec![Con {
        filters: 1,
        size: 9,
        stride: 1,
    }];
    for _ in 0..3 {
        l.extend([
            Relu,
            Affine,
            Con {
                filters: 45,
                size: 5,
                stride: 1,
            },
        ]);
    }
    for filters in [32, 32, 16] {
        l.extend([
            Relu,
            Affine,
            Con {
                filters,
                size: 5,
                stride: 2,
            },
        ]);
    }
    l
}

/// The face detector, frozen.
#[derive(Clone, Debug)]
pub struct FaceDetector {
    ops: Vec<Op>,
    mean: [f32; 3],
    window: (f32, f32),
    nms_iou: f32,
}

impl FaceDetector {
    pub fn load(path: &Path, device: &Device) -> Result<Self, FaceError> {
        let bytes = crate::read_model(
            path,
            builtin_detector(),
            crate::recognition::FACE_NET_FIX,
            "mmod_human_face_detector.dat",
        )?;
        Self::parse(&mut Reader::new(path, &bytes), device)
    }

    fn parse(r: &mut Reader<'_>, device: &Device) -> Result<Self, FaceError> {
        r.version("the loss layer", &[1])?;
        r.tag(&["loss_mmod_"])?;
        // mmod_options version 1: one detector window; later versions store a list, which
        // this model does not use.
        r.version("the detector options", &[1])?;
        let window = (
            r.size("window width", 4096)? as f32,
            r.size("window height", 4096)? as f32,
        );
        let _loss_per_false_alarm = r.float()?;
        let _loss_per_missed_target = r.float()?;
        let _truth_match_iou = r.float()?;
        let nms_iou = r.float()?;
        let _nms_covered = r.float()?;
        let _ignore_iou = r.float()?;
        let _ignore_covered = r.float()?;
        let layers = architecture();
        let versions = dnn::read_headers(r, &layers)?;
        let version = r.tag(&["input_rgb_image_pyramid", "input_rgb_image_pyramid2"])?;
        let mean = [r.float()?, r.float()?, r.float()?];
        if version == "input_rgb_image_pyramid2" {
            r.int()?; // padding between the tiles of dlib's tiled pyramid
            r.int()?;
        }
        let ops = dnn::read_layers(r, &layers, &versions, device)?;
        if !r.at_end() {
            return Err(r.error("unexpected data after the network"));
        }
        Ok(FaceDetector {
            ops,
            mean,
            window,
            nms_iou,
        })
    }

    /// The faces in `image`, best first.
    pub fn detect(&self, image: &Image<'_>, device: &Device) -> Vec<Detection> {
        let (w, h) = (image.width, image.height);
        let mut planar = vec![0f32; 3 * w * h];
        for (i, px) in image.rgb.chunks_exact(3).enumerate() {
            for c in 0..3 {
                planar[c * w * h + i] = (f32::from(px[c]) - self.mean[c]) / 256.0;
            }
        }
        let mut level = Tensor::<1>::from_floats(planar.as_slice(), device).reshape([1, 3, h, w]);
        let short = w.min(h);
        let mut scale = if short < FIRST_LEVEL.0 {
            FIRST_LEVEL.0.div_ceil(short).min(4) as f32
        } else if short > FIRST_LEVEL.1 {
            FIRST_LEVEL.1 as f32 / short as f32
        } else {
            1.0
        };
        if scale < 0.5 {
            // Average whole blocks first: one bilinear step over many pixels aliases.
            let k = (1.0 / scale).floor() as usize;
            level = avg_pool2d(level, AvgPoolOptions::new([k, k]).with_stride([k, k]));
        }
        if scale != 1.0 {
            level = resize(
                level,
                ((h as f32 * scale).round() as usize).max(1),
                ((w as f32 * scale).round() as usize).max(1),
            );
        }
        let mut found = Vec::new();
        loop {
            let [_, _, lh, lw] = level.dims();
            if (lw as f32) < self.window.0 || (lh as f32) < self.window.1 {
                break;
            }
            let out = dnn::forward(&self.ops, level.clone());
            let [_, _, oh, ow] = out.dims();
            let scores: Vec<f32> = out.into_data().try_to_vec::<f32>().unwrap_or_default();
            let (sx, sy) = (lw as f32 / w as f32, lh as f32 / h as f32);
            for (i, &score) in scores.iter().enumerate() {
                if score <= 0.0 {
                    continue;
                }
                // Centre of the cell's receptive field: three stride-2 5×5 convolutions
                // without padding map output x to input 8x + 14.
                let (cx, cy) = ((8 * (i % ow) + 14) as f32, (8 * (i / ow) + 14) as f32);
                found.push(Detection {
                    left: (cx - self.window.0 / 2.0) / sx,
                    top: (cy - self.window.1 / 2.0) / sy,
                    width: self.window.0 / sx,
                    height: self.window.1 / sy,
                    score,
                });
            }
            debug_assert_eq!(scores.len(), oh * ow);
            scale *= PYRAMID_STEP;
            let (nw, nh) = (
                (w as f32 * scale).round() as usize,
                (h as f32 * scale).round() as usize,
            );
            level = resize(level, nh.max(1), nw.max(1));
        }
        found.sort_by(|a, b| b.score.total_cmp(&a.score));
        let mut kept: Vec<Detection> = Vec::new();
        for d in found {
            if kept.iter().all(|k| k.iou(&d) <= self.nms_iou) {
                kept.push(d);
            }
        }
        kept
    }
}

fn resize(x: Tensor<4>, h: usize, w: usize) -> Tensor<4> {
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Bilinear)
            .with_align_corners(false)
            .with_output_size([h, w]),
    )
}
