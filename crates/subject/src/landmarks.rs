//! Anatomical landmarks of a head in the canonical frame, and the skin surface generators grow on.

use glam::Vec3;

/// Points on a head in the canonical frame (metres, +Y up, face towards +Z). "Left" is the
/// subject's left, which is +X when the face looks down +Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landmarks {
    /// Centre of the left eyeball.
    pub eye_left: Vec3,
    /// Centre of the right eyeball.
    pub eye_right: Vec3,
    /// Outermost skin point on the left side at eye height, a little behind the eyes: where a
    /// glasses temple or a headphone cup rests (the top of the ear's attachment).
    pub ear_left: Vec3,
    pub ear_right: Vec3,
    /// Frontmost skin point on the midline at eye height (where glasses sit on the nose).
    pub nose_bridge: Vec3,
    /// Highest skin point of the head.
    pub crown: Vec3,
}

impl Landmarks {
    /// Midpoint of the eye centres.
    pub fn eye_centre(&self) -> Vec3 {
        (self.eye_left + self.eye_right) * 0.5
    }

    /// Distance between the eye centres (interpupillary distance at rest).
    pub fn eye_distance(&self) -> f32 {
        self.eye_left.distance(self.eye_right)
    }
}

/// The skin of a head: what hair roots are placed on and what strands must stay outside of.
/// Triangles index `positions`/`normals`; all are skin (eyes, teeth and the like are left out).
#[derive(Clone, Debug, Default)]
pub struct HeadSurface {
    pub positions: Vec<Vec3>,
    /// Unit vertex normals pointing out of the head.
    pub normals: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}
