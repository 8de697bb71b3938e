//! [`Strands::ribbon_mesh`]: strands as camera-facing ribbons for the triangle renderer.

use glam::Vec3;
use lightfarm_render::scene::Mesh;

use super::polyline::any_perpendicular;
use super::Strands;

impl Strands {
    /// Camera-facing ribbons: each segment becomes a quad (two triangles, four vertices of its
    /// own) of the local width, lying in the plane that contains the segment and faces `eye`
    /// (the camera position). Vertex normals are perpendicular to the segment and point to the
    /// eye's side; uv is (across 0..1, along root 0 .. tip 1 by arc length); the tangent is the
    /// across direction. This is how strands are rendered until the renderer has a real hair
    /// primitive; the ribbons only face the camera they were built for.
    pub fn ribbon_mesh(&self, eye: Vec3, name: &str) -> Mesh {
        // One quad per segment with its own four vertices: a ribbon shared between segments
        // twists into a bow tie wherever the strand turns through the view direction.
        let segments = self.segment_count();
        let mut positions = Vec::with_capacity(4 * segments);
        let mut normals = Vec::with_capacity(4 * segments);
        let mut uvs = Vec::with_capacity(4 * segments);
        let mut tangents = Vec::with_capacity(4 * segments);
        let mut indices = Vec::with_capacity(6 * segments);
        for i in 0..self.strand_count() {
            let (pts, widths) = self.strand(i);
            let n = pts.len();
            if n < 2 {
                continue;
            }
            let total: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
            let along = |arc: f32, j: usize| {
                if total > 0.0 {
                    (arc / total).min(1.0)
                } else {
                    j as f32 / (n - 1) as f32
                }
            };
            let mut arc = 0.0f32;
            let mut last_tangent = Vec3::Y;
            for j in 0..n - 1 {
                let (a, b) = (pts[j], pts[j + 1]);
                let length = a.distance(b);
                let t = (b - a).try_normalize().unwrap_or(last_tangent);
                last_tangent = t;
                let view = (eye - 0.5 * (a + b)).try_normalize().unwrap_or(Vec3::Z);
                let side = t
                    .cross(view)
                    .try_normalize()
                    .unwrap_or_else(|| any_perpendicular(t));
                // side × t is the part of `view` perpendicular to the segment: it faces the
                // eye, and the triangles below are counter-clockwise seen from there.
                let normal = side.cross(t).try_normalize().unwrap_or(view);
                let (v0, v1) = (along(arc, j), along(arc + length, j + 1));
                arc += length;
                let base = positions.len() as u32;
                for (p, w, v) in [(a, widths[j], v0), (b, widths[j + 1], v1)] {
                    for (u, s) in [(0.0f32, -0.5 * w), (1.0, 0.5 * w)] {
                        positions.push((p + side * s).to_array());
                        normals.push(normal.to_array());
                        uvs.push([u, v]);
                        // glTF: normal × tangent × w must point towards decreasing v; normal ×
                        // side is the strand direction (increasing v), hence w = -1.
                        tangents.push([side.x, side.y, side.z, -1.0]);
                    }
                }
                indices.extend_from_slice(&[
                    base,
                    base + 1,
                    base + 2,
                    base + 1,
                    base + 3,
                    base + 2,
                ]);
            }
        }
        let triangles = indices.len() / 3;
        Mesh {
            name: name.to_string(),
            positions,
            normals,
            uvs,
            tangents,
            indices,
            triangle_materials: vec![0; triangles],
            morph_targets: Vec::new(),
        }
    }
}
