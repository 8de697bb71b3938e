//! Analytic meshes for tests and calibration subjects; all use material 0.

use std::collections::HashMap;
use std::f32::consts::PI;

use glam::Vec3;

use super::geometry::handedness;
use super::Mesh;

/// Guards against meshes too large to be meant (20 * 4^9 ≈ 5M triangles).
const MAX_ICO_SUBDIVISIONS: u32 = 9;

/// Latitude/longitude sphere centred at the origin, poles on ±Y, u = 0.5 on +Z.
pub fn uv_sphere(radius: f32, segments: u32, rings: u32) -> Mesh {
    let segments = segments.max(3);
    let rings = rings.max(2);
    let mut b = Builder::default();
    for r in 0..=rings {
        let v = r as f32 / rings as f32;
        for s in 0..=segments {
            let u = s as f32 / segments as f32;
            let theta = v * PI;
            let phi = (u - 0.5) * 2.0 * PI;
            let dir = Vec3::new(
                theta.sin() * phi.sin(),
                theta.cos(),
                theta.sin() * phi.cos(),
            );
            b.sphere_vertex(dir, radius, [u, v], phi);
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let a = r * row + s;
            let (below, next) = (a + row, a + 1);
            // The triangles touching a pole would be degenerate; leave them out.
            if r != 0 {
                b.indices.extend([a, below, next]);
            }
            if r != rings - 1 {
                b.indices.extend([next, below, below + 1]);
            }
        }
    }
    b.finish("uv_sphere")
}

/// Subdivided icosahedron; every vertex is normalised onto the sphere. UVs are the spherical
/// mapping of [`uv_sphere`] without a duplicated seam, so they wrap across it.
pub fn icosphere(radius: f32, subdivisions: u32) -> Mesh {
    let t = (1.0 + 5.0f32.sqrt()) / 2.0;
    let mut dirs: Vec<Vec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| Vec3::from(*p).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions.min(MAX_ICO_SUBDIVISIONS) {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, dirs: &mut Vec<Vec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *midpoints.entry(key).or_insert_with(|| {
                dirs.push((dirs[a as usize] + dirs[b as usize]).normalize());
                (dirs.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = mid(a, b, &mut dirs);
            let bc = mid(b, c, &mut dirs);
            let ca = mid(c, a, &mut dirs);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    let mut b = Builder::default();
    for d in dirs {
        let phi = d.x.atan2(d.z);
        let u = 0.5 + phi / (2.0 * PI);
        let v = d.y.clamp(-1.0, 1.0).acos() / PI;
        b.sphere_vertex(d, radius, [u, v], phi);
    }
    b.indices = tris.into_iter().flatten().collect();
    b.finish("icosphere")
}

/// Rectangle in the XY plane facing +Z, centred at the origin; uv (0,0) at the top-left.
pub fn quad(width: f32, height: f32) -> Mesh {
    let (hw, hh) = (width * 0.5, height * 0.5);
    let corners = [
        ([-hw, hh, 0.0], [0.0, 0.0]),
        ([-hw, -hh, 0.0], [0.0, 1.0]),
        ([hw, -hh, 0.0], [1.0, 1.0]),
        ([hw, hh, 0.0], [1.0, 0.0]),
    ];
    Mesh {
        name: "quad".to_string(),
        positions: corners.iter().map(|c| c.0).collect(),
        normals: vec![[0.0, 0.0, 1.0]; 4],
        uvs: corners.iter().map(|c| c.1).collect(),
        // Bitangent cross(+Z, +X) = +Y points towards decreasing v, hence w = +1.
        tangents: vec![[1.0, 0.0, 0.0, 1.0]; 4],
        indices: vec![0, 1, 2, 0, 2, 3],
        triangle_materials: vec![0; 2],
        morph_targets: Vec::new(),
    }
}

/// Closed axis-aligned box centred at the origin with side lengths `size`: six faces of two
/// triangles each, flat outward normals (a semi-infinite slab for subsurface tests when it is large against the
/// medium's mean free path).
pub fn cuboid(size: Vec3) -> Mesh {
    let h = size * 0.5;
    let mut m = Mesh {
        name: "cuboid".to_string(),
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        tangents: Vec::new(),
        indices: Vec::new(),
        triangle_materials: Vec::new(),
        morph_targets: Vec::new(),
    };
    // (normal, tangent u, bitangent v): corners n·h ± u·h ± v·h, counter-clockwise seen from outside.
    let faces = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    for (n, u, v) in faces {
        let base = m.positions.len() as u32;
        for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = n * h + u * h * a + v * h * b;
            m.positions.push(p.to_array());
            m.normals.push(n.to_array());
            m.uvs.push([(a + 1.0) * 0.5, (1.0 - b) * 0.5]);
            m.tangents.push([u.x, u.y, u.z, 1.0]);
        }
        m.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    m.triangle_materials = vec![0; m.indices.len() / 3];
    m
}

#[derive(Default)]
struct Builder {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    tangents: Vec<[f32; 4]>,
    indices: Vec<u32>,
}

impl Builder {
    /// `dir` is the unit outward normal; `phi` the longitude, increasing with u.
    fn sphere_vertex(&mut self, dir: Vec3, radius: f32, uv: [f32; 2], phi: f32) {
        // d(position)/d(phi) direction, defined even at the poles.
        let tangent = Vec3::new(phi.cos(), 0.0, -phi.sin());
        // v grows from +Y to -Y, so "decreasing v" is the direction towards +Y.
        let towards_north = (Vec3::Y - dir * dir.y).normalize_or_zero();
        let w = if towards_north == Vec3::ZERO {
            1.0
        } else {
            handedness(dir, tangent, towards_north)
        };
        self.positions.push((dir * radius).to_array());
        self.normals.push(dir.to_array());
        self.uvs.push(uv);
        self.tangents.push([tangent.x, tangent.y, tangent.z, w]);
    }

    fn finish(self, name: &str) -> Mesh {
        let triangles = self.indices.len() / 3;
        Mesh {
            name: name.to_string(),
            positions: self.positions,
            normals: self.normals,
            uvs: self.uvs,
            tangents: self.tangents,
            indices: self.indices,
            triangle_materials: vec![0; triangles],
            morph_targets: Vec::new(),
        }
    }
}
