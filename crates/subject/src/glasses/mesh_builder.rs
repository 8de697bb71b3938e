//! Glasses: the triangle-mesh builder the procedural frames are assembled with (see the parent
//! module).

#[allow(unused_imports)]
use super::*;

#[derive(Default)]
pub(super) struct MeshBuilder {
    pub(super) positions: Vec<Vec3>,
    pub(super) normals: Vec<Vec3>,
    pub(super) indices: Vec<u32>,
}

impl MeshBuilder {
    pub(super) fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.positions.push(p);
        self.normals.push(n);
        (self.positions.len() - 1) as u32
    }

    /// Winds the triangle so its face agrees with its vertex normals, which every builder here
    /// sets outward; the renderer and the closed-mesh tests rely on consistent winding.
    pub(super) fn tri(&mut self, a: u32, b: u32, c: u32) {
        let p = |i: u32| self.positions[i as usize];
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        let normals =
            self.normals[a as usize] + self.normals[b as usize] + self.normals[c as usize];
        if face.dot(normals) < 0.0 {
            self.indices.extend([a, c, b]);
        } else {
            self.indices.extend([a, b, c]);
        }
    }

    /// `a b c d` in order around the quad.
    pub(super) fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.tri(a, b, c);
        self.tri(a, c, d);
    }

    pub(super) fn finish(self, name: &str) -> Mesh {
        let n = self.positions.len();
        Mesh {
            name: name.to_string(),
            positions: self.positions.iter().map(|p| p.to_array()).collect(),
            normals: self.normals.iter().map(|p| p.to_array()).collect(),
            uvs: vec![[0.0; 2]; n],
            tangents: vec![[0.0; 4]; n],
            triangle_materials: vec![0; self.indices.len() / 3],
            indices: self.indices,
            morph_targets: Vec::new(),
        }
    }
}
