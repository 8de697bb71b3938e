//! The identity loss of section 4.3 and the identity metric of Table 4: dlib descriptors of the
//! input portrait and of its relighting, on chips cut by the input's face alignment.

use burn::prelude::*;

use crate::{face_chips, Alignment, FaceNet};

/// What the face-recognition network sees of a linear HDR image ([B, 3, H, W]) and its mask
/// ([B, 1, H, W]): exposure set so the masked mean is 0.5 (a relighting may be brighter or
/// darker than its input without being another person), gamma 2.2, values 0..255 as dlib
/// expects.
pub fn identity_display(x: Tensor<4>, mask: Tensor<4>) -> Tensor<4> {
    let masked = x.clone() * mask.clone();
    let total = masked.sum_dim(1).sum_dim(2).sum_dim(3).div_scalar(3.0);
    let area = mask.sum_dim(2).sum_dim(3).clamp_min(1.0);
    let mean = (total / area).clamp_min(1e-6);
    (x / mean.mul_scalar(2.0))
        .clamp(1e-4, 1.0)
        .powf_scalar(1.0 / 2.2)
        .mul_scalar(255.0)
}

/// dlib descriptors ([B, 128]) of display images (from [`identity_display`]), each cut by its
/// alignment.
pub fn descriptors(net: &FaceNet, display: Tensor<4>, faces: &[Alignment]) -> Tensor<2> {
    net.embed(face_chips(display, faces))
}

/// The identity loss: mean L1 between the descriptors of the input and of the relit image.
pub fn identity_loss(
    net: &FaceNet,
    input: Tensor<4>,
    relit: Tensor<4>,
    mask: Tensor<4>,
    faces: &[Alignment],
) -> Tensor<1> {
    let a = descriptors(net, identity_display(input, mask.clone()), faces);
    let b = descriptors(net, identity_display(relit, mask), faces);
    (a - b).abs().mean()
}

/// Euclidean distance between the descriptors of each pair ([B, 128] each → [B]); dlib calls
/// two faces the same person below [`crate::SAME_PERSON_DISTANCE`].
pub fn descriptor_distance(a: Tensor<2>, b: Tensor<2>) -> Tensor<1> {
    let [n, _] = a.dims();
    (a - b).powi_scalar(2).sum_dim(1).sqrt().reshape([n])
}

/// Cosine similarity of the descriptors of each pair ([B, 128] each → [B]), the paper's
/// identity score (↑).
pub fn descriptor_similarity(a: Tensor<2>, b: Tensor<2>) -> Tensor<1> {
    let [n, _] = a.dims();
    let dot = (a.clone() * b.clone()).sum_dim(1);
    let norms = a.powi_scalar(2).sum_dim(1).sqrt() * b.powi_scalar(2).sum_dim(1).sqrt();
    (dot / norms.clamp_min(1e-12)).reshape([n])
}
