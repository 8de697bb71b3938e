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

/// Closest point on a triangle (Ericson, Real-Time Collision Detection, section 5.1.5).
pub fn closest_on_triangle(p: Vec3, [a, b, c]: [Vec3; 3]) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_regions() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        // Above the face: the foot of the perpendicular.
        assert_eq!(
            closest_on_triangle(Vec3::new(0.25, 0.25, 1.0), tri),
            Vec3::new(0.25, 0.25, 0.0)
        );
        // Beyond a vertex, beyond an edge.
        assert_eq!(
            closest_on_triangle(Vec3::new(-1.0, -1.0, 0.0), tri),
            Vec3::ZERO
        );
        assert_eq!(
            closest_on_triangle(Vec3::new(0.5, -2.0, 0.0), tri),
            Vec3::new(0.5, 0.0, 0.0)
        );
        let hyp = closest_on_triangle(Vec3::new(1.0, 1.0, 0.0), tri);
        assert!((hyp - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
    }
}
