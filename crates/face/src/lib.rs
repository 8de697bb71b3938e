//! Faces in images, for the paper's identity loss and identity metric (section 4.3, Table 4):
//! dlib's CNN face detector, its 5-point landmarks, the aligned 150² face chip and its
//! face-recognition ResNet, all read from dlib's own model files (public domain) and run on
//! Burn or plain Rust; and MediaPipe's face mesh (Apache-2.0, TensorFlow Lite) for the skin
//! mask of the real-photo lighting metric.

mod align;
mod detect;
mod dlib;
mod dnn;
mod identity;
mod landmarks;
mod mesh;
mod recognition;
pub mod skin;
mod tflite;

pub use align::{face_chips, Alignment, FaceAligner, LazyFaces, CHIP_PADDING};
pub use detect::{builtin_detector, Detection, FaceDetector, DETECTOR_FILE};
pub use identity::{
    descriptor_distance, descriptor_similarity, descriptors, identity_display, identity_loss,
};
pub use landmarks::{builtin_landmarks, ShapePredictor, LANDMARKS_FILE};
pub use mesh::{builtin_face_mesh, FaceMesh, Mesh, Roi, MESH_FILE, MESH_FIX, MESH_POINTS};
pub use recognition::{
    builtin_face_net, FaceNet, CHIP_SIZE, FACE_NET_FILE, FACE_NET_FIX, SAME_PERSON_DISTANCE,
};

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum FaceError {
    #[error("{path}: {reason}")]
    Model { path: PathBuf, reason: String },
    #[error("{0}")]
    Input(String),
}

/// An 8-bit RGB image, row-major, 3 bytes a pixel.
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    pub rgb: &'a [u8],
    pub width: usize,
    pub height: usize,
}

impl<'a> Image<'a> {
    pub fn new(rgb: &'a [u8], width: usize, height: usize) -> Result<Self, FaceError> {
        if width == 0 || height == 0 || rgb.len() != 3 * width * height {
            return Err(FaceError::Input(format!(
                "an RGB image of {width}×{height} needs {} bytes, got {}",
                3 * width * height,
                rgb.len()
            )));
        }
        Ok(Image { rgb, width, height })
    }
}

/// A model file's bytes; the error names the file, and the fix when it is a built-in one.
fn read_model(
    path: &Path,
    builtin: PathBuf,
    fix: &str,
    expected: &str,
) -> Result<Vec<u8>, FaceError> {
    std::fs::read(path).map_err(|e| FaceError::Model {
        path: path.to_owned(),
        reason: if path == builtin {
            format!("cannot read this built-in model ({e}): {fix}")
        } else {
            format!("cannot read ({e}); expected dlib's {expected}")
        },
    })
}
