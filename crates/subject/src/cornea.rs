//! Clear corneas over the irises of heads whose eyeball is one closed ball.
//!
//! ICT FaceKit's sclera is a whole eyeball: its front cap lies in front of the iris (1.3 mm in
//! front of it on the built-in ICT heads), so an opaque sclera hides the iris. That cap is the
//! cornea's place. [`clear_corneas`] gives the sclera triangles in front of each iris the
//! `cornea` model (a thin-walled clear sheet), so the iris shows through it as through a real
//! cornea. MakeHuman heads have a cornea mesh of their own and are mapped by name instead
//! (`head::assign_head_materials`).

use glam::Vec3;
use lightfarm_render::scene::{Material, MaterialModel, Mesh, Scene};

/// Lower-cased material names of an eyeball mesh that may cover an iris.
const EYEBALL_NAMES: [&str; 2] = ["sclera", "eyeball"];
const IRIS_NAME: &str = "iris";

/// What [`clear_corneas`] changed, per eye found.
#[derive(Clone, Debug, PartialEq)]
pub struct CorneaCap {
    pub mesh: usize,
    /// Object space: the eyeball's centre (its bounding-box centre) and the unit axis through
    /// the iris's centroid.
    pub eyeball_centre: Vec3,
    pub axis: Vec3,
    /// The largest distance of an iris vertex from the axis.
    pub iris_radius: f32,
    /// Triangles given the cornea material.
    pub triangles: usize,
}

/// Connected groups of `triangles` (indices into `mesh`'s triangle list) sharing vertices.
fn components(mesh: &Mesh, triangles: &[usize]) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..mesh.positions.len()).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let vertices = |t: usize| {
        mesh.indices[3 * t..3 * t + 3]
            .iter()
            .map(|&v| v as usize)
            .filter(|&v| v < mesh.positions.len())
    };
    for &t in triangles {
        let mut first = None;
        for v in vertices(t) {
            let r = root(&mut parent, v);
            match first {
                None => first = Some(r),
                Some(f) => parent[r] = f,
            }
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for &t in triangles {
        if let Some(v) = vertices(t).next() {
            groups.entry(root(&mut parent, v)).or_default().push(t);
        }
    }
    groups.into_values().collect()
}

fn triangle_vertices(mesh: &Mesh, t: usize) -> impl Iterator<Item = Vec3> + '_ {
    mesh.indices[3 * t..3 * t + 3]
        .iter()
        .filter_map(|&v| mesh.positions.get(v as usize))
        .map(|p| Vec3::from(*p))
}

fn centroid(mesh: &Mesh, t: usize) -> Vec3 {
    triangle_vertices(mesh, t).sum::<Vec3>() / 3.0
}

fn bounds_centre(mesh: &Mesh, triangles: &[usize]) -> Vec3 {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &t in triangles {
        for p in triangle_vertices(mesh, t) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo + hi) * 0.5
}

/// Gives every eyeball (materials named sclera / eyeball) that covers an iris (material iris) in
/// the same mesh a clear cornea: the eyeball's triangles in front of its centre (along the axis
/// from the centre through the iris's centroid) and within the iris's radius of that axis get a
/// new material `cornea` of model [`MaterialModel::Cornea`]. Each iris goes with the nearest
/// eyeball. A scene that already has a `cornea` model, or no iris inside an eyeball, is left
/// as it is. Returns what changed.
pub fn clear_corneas(scene: &mut Scene) -> Vec<CorneaCap> {
    if scene
        .materials
        .iter()
        .any(|m| m.model == MaterialModel::Cornea)
    {
        return Vec::new();
    }
    let named = |names: &[&str]| -> Vec<bool> {
        scene
            .materials
            .iter()
            .map(|m| {
                let n = m.name.to_ascii_lowercase();
                names.iter().any(|k| n == *k)
            })
            .collect()
    };
    let (is_eyeball, is_iris) = (named(&EYEBALL_NAMES), named(&[IRIS_NAME]));
    let cornea_index = scene.materials.len() as u32;
    let mut caps = Vec::new();
    for (mesh_index, mesh) in scene.meshes.iter_mut().enumerate() {
        let of = |flags: &[bool]| -> Vec<usize> {
            (0..mesh.triangle_count())
                .filter(|&t| {
                    mesh.triangle_materials
                        .get(t)
                        .is_some_and(|&m| flags.get(m as usize).copied().unwrap_or(false))
                })
                .collect()
        };
        let (eyeball_tris, iris_tris) = (of(&is_eyeball), of(&is_iris));
        if eyeball_tris.is_empty() || iris_tris.is_empty() {
            continue;
        }
        let eyeballs: Vec<(Vec3, Vec<usize>)> = components(mesh, &eyeball_tris)
            .into_iter()
            .map(|group| (bounds_centre(mesh, &group), group))
            .collect();
        for iris in components(mesh, &iris_tris) {
            let c = iris.iter().map(|&t| centroid(mesh, t)).sum::<Vec3>() / iris.len() as f32;
            let Some((centre, ball)) = eyeballs
                .iter()
                .min_by(|a, b| a.0.distance(c).total_cmp(&b.0.distance(c)))
            else {
                continue;
            };
            let Some(axis) = (c - *centre).try_normalize() else {
                continue;
            };
            let radial = |p: Vec3| {
                let v = p - *centre;
                (v - axis * v.dot(axis)).length()
            };
            let radius = iris
                .iter()
                .flat_map(|&t| triangle_vertices(mesh, t).collect::<Vec<_>>())
                .map(radial)
                .fold(0.0f32, f32::max);
            let mut count = 0;
            for &t in ball {
                let q = centroid(mesh, t);
                if (q - *centre).dot(axis) > 0.0 && radial(q) < radius {
                    mesh.triangle_materials[t] = cornea_index;
                    count += 1;
                }
            }
            if count > 0 {
                caps.push(CorneaCap {
                    mesh: mesh_index,
                    eyeball_centre: *centre,
                    axis,
                    iris_radius: radius,
                    triangles: count,
                });
            }
        }
    }
    if !caps.is_empty() {
        let mut cornea = Material {
            name: "cornea".into(),
            ..Material::default()
        };
        cornea.apply_model(MaterialModel::Cornea);
        scene.materials.push(cornea);
    }
    caps
}
