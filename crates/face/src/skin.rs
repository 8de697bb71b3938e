//! The face's skin from its mesh: the face oval minus the eyes, the eyebrows and the lips, the
//! region the real-photo lighting metric fits its spherical harmonics to (the paper uses a
//! face parser, of which there is none offline).
//!
//! The polygons are MediaPipe's contour lists (`face_mesh_connections.py`, Apache-2.0), each
//! edge set chained into one closed outline.

use crate::mesh::Mesh;

/// The face's outline, from the top of the forehead round the image-left side and back.
pub const FACE_OVAL: [usize; 36] = [
    10, 338, 297, 332, 284, 251, 389, 356, 454, 323, 361, 288, 397, 365, 379, 378, 400, 377, 152,
    148, 176, 149, 150, 136, 172, 58, 132, 93, 234, 127, 162, 21, 54, 103, 67, 109,
];
/// The subject's left eye: lower lid from the outer corner, then the upper lid back.
pub const LEFT_EYE: [usize; 16] = [
    263, 249, 390, 373, 374, 380, 381, 382, 362, 398, 384, 385, 386, 387, 388, 466,
];
/// The subject's right eye, the same way.
pub const RIGHT_EYE: [usize; 16] = [
    33, 7, 163, 144, 145, 153, 154, 155, 133, 173, 157, 158, 159, 160, 161, 246,
];
/// The outer outline of the lips: lower lip left to right, upper lip back.
pub const LIPS: [usize; 20] = [
    61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291, 409, 270, 269, 267, 0, 37, 39, 40, 185,
];
/// The subject's left eyebrow: its lower edge outwards-in, its upper edge back.
pub const LEFT_EYEBROW: [usize; 10] = [276, 283, 282, 295, 285, 336, 296, 334, 293, 300];
/// The subject's right eyebrow, the same way.
pub const RIGHT_EYEBROW: [usize; 10] = [46, 53, 52, 65, 55, 107, 66, 105, 63, 70];

/// Whether (x, y) is inside the closed polygon of mesh points `outline` (even-odd rule).
pub fn inside(mesh: &Mesh, outline: &[usize], x: f32, y: f32) -> bool {
    let p = &mesh.points;
    let mut within = false;
    let mut j = outline.len() - 1;
    for i in 0..outline.len() {
        let (a, b) = (p[outline[i]], p[outline[j]]);
        if (a[1] > y) != (b[1] > y) && x < a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]) {
            within = !within;
        }
        j = i;
    }
    within
}

/// Whether (x, y) is skin: inside the face oval and outside the eyes, eyebrows and lips.
pub fn is_skin(mesh: &Mesh, x: f32, y: f32) -> bool {
    inside(mesh, &FACE_OVAL, x, y)
        && ![
            &LEFT_EYE[..],
            &RIGHT_EYE,
            &LIPS,
            &LEFT_EYEBROW,
            &RIGHT_EYEBROW,
        ]
        .iter()
        .any(|o| inside(mesh, o, x, y))
}

/// The skin of a width×height image, 1 or 0 per pixel (tested at pixel centres), row-major.
pub fn skin_mask(mesh: &Mesh, width: usize, height: usize) -> Vec<f32> {
    (0..width * height)
        .map(|i| {
            let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
            f32::from(u8::from(is_skin(mesh, x, y)))
        })
        .collect()
}
