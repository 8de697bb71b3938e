//! Per-vertex normals and tangents for meshes whose files do not provide them, and frame
//! construction shared by cameras.

use glam::{Vec2, Vec3};

/// Used where a vertex has no usable normal at all (unreferenced or only degenerate
/// triangles), so every normal stays unit length as the shaders assume.
const FALLBACK_NORMAL: [f32; 3] = [0.0, 0.0, 1.0];

/// Area-weighted smooth normals: unnormalised face normals are proportional to area.
pub(crate) fn smooth_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    welded_normals(positions, indices, &[])
}

/// [`smooth_normals`] where vertex `i` accumulates into, and takes the normal of, vertex
/// `weld[i]`: copies of one surface point split for their UVs or materials then share one
/// normal. An empty `weld` (or an entry out of range) welds nothing.
pub(crate) fn welded_normals(
    positions: &[[f32; 3]],
    indices: &[u32],
    weld: &[u32],
) -> Vec<[f32; 3]> {
    let n = positions.len();
    let rep = |i: usize| {
        weld.get(i)
            .map(|&r| r as usize)
            .filter(|&r| r < n)
            .unwrap_or(i)
    };
    let mut acc = vec![Vec3::ZERO; n];
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let (Some(pa), Some(pb), Some(pc)) = (positions.get(a), positions.get(b), positions.get(c))
        else {
            continue;
        };
        let (pa, pb, pc) = (Vec3::from(*pa), Vec3::from(*pb), Vec3::from(*pc));
        let n = (pb - pa).cross(pc - pa);
        if n.is_finite() {
            for i in [a, b, c] {
                acc[rep(i)] += n;
            }
        }
    }
    (0..n).map(|i| unit_or_fallback(acc[rep(i)])).collect()
}

pub(crate) fn unit_or_fallback(n: Vec3) -> [f32; 3] {
    let u = n.normalize_or_zero();
    if u == Vec3::ZERO {
        FALLBACK_NORMAL
    } else {
        u.to_array()
    }
}

/// glTF handedness: the bitangent `cross(n, t) * w` must point towards decreasing v
/// (glTF's UV origin is the top-left corner while normal maps have +Y up).
pub(crate) fn handedness(n: Vec3, t: Vec3, bitangent_up: Vec3) -> f32 {
    if n.cross(t).dot(bitangent_up) < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Tangents from UV derivatives, accumulated per vertex over the adjacent triangles and
/// orthogonalised against the vertex normal.
pub(crate) fn uv_tangents(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    uvs: &[[f32; 2]],
    indices: &[u32],
) -> Vec<[f32; 4]> {
    let n_verts = positions.len();
    let mut tan = vec![Vec3::ZERO; n_verts];
    let mut bit = vec![Vec3::ZERO; n_verts];
    for tri in indices.chunks_exact(3) {
        let ids = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        if ids.iter().any(|&i| i >= n_verts || i >= uvs.len()) {
            continue;
        }
        let p = ids.map(|i| Vec3::from(positions[i]));
        let t = ids.map(|i| Vec2::from(uvs[i]));
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det.abs() < 1e-20 {
            continue;
        }
        // Weighting by the unnormalised derivative keeps larger triangles more influential.
        let sign = det.signum();
        let dpdu = (e1 * d2.y - e2 * d1.y) * sign;
        let dpdv = (e2 * d1.x - e1 * d2.x) * sign;
        if !dpdu.is_finite() || !dpdv.is_finite() {
            continue;
        }
        for i in ids {
            tan[i] += dpdu;
            bit[i] -= dpdv;
        }
    }
    (0..n_verts)
        .map(|i| {
            let n = Vec3::from(normals.get(i).copied().unwrap_or(FALLBACK_NORMAL));
            let t = (tan[i] - n * n.dot(tan[i])).normalize_or_zero();
            let t = if t == Vec3::ZERO {
                n.any_orthonormal_vector()
            } else {
                t
            };
            let w = handedness(n, t, bit[i]);
            [t.x, t.y, t.z, w]
        })
        .collect()
}

/// `hint` made orthogonal to `forward`; falls back to +Z when `hint` is (nearly) parallel.
pub(crate) fn orthogonal_up(forward: Vec3, hint: Vec3) -> Vec3 {
    let hint = if forward.dot(hint.normalize_or_zero()).abs() > 0.999 || hint == Vec3::ZERO {
        Vec3::Z
    } else {
        hint
    };
    let right = forward.cross(hint).normalize_or_zero();
    if right == Vec3::ZERO {
        // forward is along Z as well as the hint: any perpendicular will do.
        return forward.any_orthonormal_vector();
    }
    right.cross(forward).normalize()
}
