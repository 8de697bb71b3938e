//! MediaPipe's face mesh (`face_landmark.tflite`, Apache-2.0): a rotated square crop of the
//! face, resized to 192², → 468 landmarks and a face-presence score. It gives the skin mask of
//! the real-photo lighting metric (see [`crate::skin`]).
//!
//! MediaPipe crops the face from its own detector's box, rotated so the eyes are level and
//! scaled 1.5×, then, on later frames, from the previous mesh. Here the first crop comes from
//! dlib's box and eye landmarks the same way, and the crop is refitted to the mesh it gives
//! (MediaPipe's tracking rule: the mesh's box in the eye-level frame, 1.5×), which makes the
//! result independent of how tightly the first detector boxes a face.

use std::path::{Path, PathBuf};

use burn::prelude::*;
use burn::tensor::activation::sigmoid;

use crate::align::Alignment;
use crate::tflite::{read_graph, Graph};
use crate::{FaceError, Image};

/// Where `./scripts/fetch-models.sh` installs the mesh, relative to the asset directory.
pub const MESH_FILE: &str = "models/mediapipe/face_landmark.tflite";

/// What installs the built-in mesh, for error messages.
pub const MESH_FIX: &str = "run ./scripts/fetch-models.sh (it downloads the mediapipe==0.10.14 \
     wheel from PyPI and checks the model's hash)";

/// Landmarks of the mesh.
pub const MESH_POINTS: usize = 468;

/// Margin of the crop around a face box (MediaPipe's scale for both of its crops).
const ROI_SCALE: f32 = 1.5;

/// The built-in mesh: [`MESH_FILE`] in the asset pack (`$LIGHTFARM_ASSETS` or the
/// repository's `assets/`).
pub fn builtin_face_mesh() -> PathBuf {
    lightfarm_scene::catalog::builtin_assets_dir().join(MESH_FILE)
}

/// A rotated square of an image: centre and side in pixels, and the angle of its x axis
/// (radians, image y down).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roi {
    pub centre: [f32; 2],
    pub side: f32,
    pub angle: f32,
}

impl Roi {
    /// The crop MediaPipe takes around a detected face: dlib's box scaled 1.5×, turned so the
    /// line between the eyes is level.
    pub fn from_alignment(a: &Alignment) -> Roi {
        let l = &a.landmarks;
        let mid = |i: usize, j: usize| [(l[i][0] + l[j][0]) / 2.0, (l[i][1] + l[j][1]) / 2.0];
        // dlib's order: image-right eye (outer, inner), image-left eye, nose.
        let (right, left) = (mid(0, 1), mid(2, 3));
        let f = &a.face;
        Roi {
            centre: [f.left + f.width / 2.0, f.top + f.height / 2.0],
            side: ROI_SCALE * f.width.max(f.height),
            angle: (right[1] - left[1]).atan2(right[0] - left[0]),
        }
    }

    /// The crop around a mesh: its box in the frame where the eye corners (33, 263) are level,
    /// squared and scaled 1.5×.
    pub fn from_points(points: &[[f32; 3]]) -> Roi {
        let (a, b) = (points[263], points[33]);
        let angle = (a[1] - b[1]).atan2(a[0] - b[0]);
        let (c, s) = (angle.cos(), angle.sin());
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        for p in points {
            let q = [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        let m = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        Roi {
            centre: [c * m[0] - s * m[1], s * m[0] + c * m[1]],
            side: ROI_SCALE * (hi[0] - lo[0]).max(hi[1] - lo[1]),
            angle,
        }
    }

    /// The image point of crop coordinates (u, v) ∈ [0, 1]².
    pub fn to_image(&self, u: f32, v: f32) -> [f32; 2] {
        let (x, y) = ((u - 0.5) * self.side, (v - 0.5) * self.side);
        let (c, s) = (self.angle.cos(), self.angle.sin());
        [
            self.centre[0] + c * x - s * y,
            self.centre[1] + s * x + c * y,
        ]
    }
}

/// The mesh of one face.
#[derive(Clone, Debug)]
pub struct Mesh {
    /// The 468 landmarks: x, y in image pixels, z (depth, in pixels, smaller is nearer the
    /// camera) relative to the face.
    pub points: Vec<[f32; 3]>,
    /// The network's face-presence probability for the crop.
    pub presence: f32,
    /// The crop it was computed in.
    pub roi: Roi,
}

/// The face-mesh network.
#[derive(Debug)]
pub struct FaceMesh {
    graph: Graph,
    device: Device,
}

impl FaceMesh {
    /// Reads MediaPipe's `face_landmark.tflite`; the error names the file, and the fix when it
    /// is the built-in one.
    pub fn load(path: &Path, device: &Device) -> Result<Self, FaceError> {
        let graph = read_graph(path, builtin_face_mesh(), MESH_FIX, device)?;
        let err = |reason: String| FaceError::Model {
            path: path.to_owned(),
            reason,
        };
        if graph.input_shape[2] != 3 || graph.input_shape[0] != graph.input_shape[1] {
            return Err(err(format!(
                "input of shape {:?}, expected a square RGB image",
                graph.input_shape
            )));
        }
        let probe = graph.forward(Tensor::<4>::zeros(
            [1, 3, graph.input_shape[0], graph.input_shape[1]],
            device,
        ));
        match probe.iter().map(|t| t.dims()[1]).collect::<Vec<_>>()[..] {
            [n, 1] if n == 3 * MESH_POINTS => {}
            ref got => {
                return Err(err(format!(
                    "outputs of {got:?} values, expected the mesh's [{}, 1]",
                    3 * MESH_POINTS
                )))
            }
        }
        Ok(FaceMesh {
            graph,
            device: device.clone(),
        })
    }

    /// The built-in mesh ([`builtin_face_mesh`]).
    pub fn builtin(device: &Device) -> Result<Self, FaceError> {
        Self::load(&builtin_face_mesh(), device)
    }

    /// Side of the network's input.
    pub fn input_size(&self) -> usize {
        self.graph.input_shape[0]
    }

    /// The mesh in one crop of the image.
    pub fn in_roi(&self, image: &Image<'_>, roi: Roi) -> Mesh {
        let n = self.input_size();
        let crop = crop(image, roi, n);
        let input = Tensor::<4>::from_data(TensorData::new(crop, [1, n, n, 3]), &self.device)
            .permute([0, 3, 1, 2]);
        let out = self.graph.forward(input);
        let values: Vec<f32> = out[0]
            .clone()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap_or_default();
        let presence = sigmoid(out[1].clone()).into_scalar::<f32>().clamp(0.0, 1.0);
        let k = 1.0 / n as f32;
        let points = values
            .chunks_exact(3)
            .map(|p| {
                let [x, y] = roi.to_image(p[0] * k, p[1] * k);
                [x, y, p[2] * k * roi.side]
            })
            .collect();
        Mesh {
            points,
            presence,
            roi,
        }
    }

    /// The mesh of the face dlib found: a first crop from its box, then one refitted to the
    /// mesh of the first.
    pub fn fit(&self, image: &Image<'_>, face: &Alignment) -> Mesh {
        let first = self.in_roi(image, Roi::from_alignment(face));
        self.in_roi(image, Roi::from_points(&first.points))
    }
}

/// The crop resized to n² by bilinear sampling (zero outside the image), NHWC in [0, 1].
fn crop(image: &Image<'_>, roi: Roi, n: usize) -> Vec<f32> {
    let (w, h) = (image.width as isize, image.height as isize);
    let at = |x: isize, y: isize, c: usize| -> f32 {
        if x < 0 || y < 0 || x >= w || y >= h {
            0.0
        } else {
            f32::from(image.rgb[3 * (y * w + x) as usize + c]) / 255.0
        }
    };
    // Average over the footprint of a crop pixel when it covers several image pixels.
    let step = roi.side / n as f32;
    let taps = (step.floor() as usize).clamp(1, 4);
    let mut out = vec![0f32; n * n * 3];
    for v in 0..n {
        for u in 0..n {
            let mut acc = [0f32; 3];
            for ty in 0..taps {
                for tx in 0..taps {
                    let fu = (u as f32 + (tx as f32 + 0.5) / taps as f32) / n as f32;
                    let fv = (v as f32 + (ty as f32 + 0.5) / taps as f32) / n as f32;
                    let [x, y] = roi.to_image(fu, fv);
                    let (x, y) = (x - 0.5, y - 0.5);
                    let (x0, y0) = (x.floor(), y.floor());
                    let (fx, fy) = (x - x0, y - y0);
                    let (x0, y0) = (x0 as isize, y0 as isize);
                    for (c, a) in acc.iter_mut().enumerate() {
                        *a += (1.0 - fy) * ((1.0 - fx) * at(x0, y0, c) + fx * at(x0 + 1, y0, c))
                            + fy * ((1.0 - fx) * at(x0, y0 + 1, c) + fx * at(x0 + 1, y0 + 1, c));
                    }
                }
            }
            let k = 1.0 / (taps * taps) as f32;
            for c in 0..3 {
                out[3 * (v * n + u) + c] = acc[c] * k;
            }
        }
    }
    out
}
