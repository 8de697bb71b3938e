//! glTF line primitives to [`Curves`]: a `LINE_STRIP` (mode 3) or `LINES` (mode 1) primitive
//! with a per-vertex `_RADIUS` (float SCALAR, metres) is one curve set of fibres.
//!
//! - `LINE_STRIP`: one strand over the primitive's vertex sequence (through its indices when it
//!   has them).
//! - `LINES`: one segment per vertex pair; consecutive pairs that share an endpoint (the second
//!   vertex of pair k is the first of pair k + 1: the same index, or without indices the same
//!   position and radius, bit for bit) continue one strand, anything else starts a new one. This
//!   is what [`super::write_glb`] writes: one indexed `LINES` primitive per curve set.
//!
//! The primitive's material must have `extras.lightfarm.model = "hair"`: the renderer has a fibre
//! BSDF only for hair. Curves are read in object space per mesh ([`read_mesh_curves`]) and baked
//! into world space per node that instances the mesh ([`to_world`]).

use std::path::Path;

use glam::{Mat3, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};

use super::load::check_accessor;
use super::{Curves, Material, MaterialModel, SceneError, MAX_CURVE_SEGMENTS};

/// The custom attribute holding the fibre radius, as it appears in the file.
pub(crate) const RADIUS_ATTRIBUTE: &str = "_RADIUS";

/// Whether `mode` is one the curve loader reads (the triangle loader skips these).
pub(super) fn is_curve_mode(mode: Mode) -> bool {
    matches!(mode, Mode::Lines | Mode::LineStrip)
}

/// The curve sets of `mesh`'s line primitives, in object space and primitive order; every set
/// satisfies [`Curves::validate`].
pub(super) fn read_mesh_curves(
    path: &Path,
    mesh: &gltf::Mesh,
    mesh_name: &str,
    buffers: &[&[u8]],
    materials: &[Material],
) -> Result<Vec<Curves>, SceneError> {
    let mut out = Vec::new();
    for prim in mesh.primitives() {
        if !is_curve_mode(prim.mode()) {
            continue;
        }
        let bad = |reason: String| SceneError::BadPrimitive {
            path: path.to_path_buf(),
            mesh: mesh_name.to_string(),
            reason: format!(
                "primitive {} ({}): {reason}",
                prim.index(),
                mode_name(prim.mode())
            ),
        };
        out.push(read_primitive(&prim, mesh_name, buffers, materials).map_err(bad)?);
    }
    Ok(out)
}

fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Lines => "LINES",
        Mode::LineStrip => "LINE_STRIP",
        _ => "not lines",
    }
}

fn read_primitive(
    prim: &gltf::Primitive,
    mesh_name: &str,
    buffers: &[&[u8]],
    materials: &[Material],
) -> Result<Curves, String> {
    let radius_semantic = Semantic::Extras(RADIUS_ATTRIBUTE[1..].to_string());
    let Some(radius_accessor) = prim.get(&radius_semantic) else {
        let present: Vec<String> = prim.attributes().map(|(s, _)| s.to_string()).collect();
        return Err(format!(
            "lines without a {RADIUS_ATTRIBUTE} attribute (it has {}); line primitives are \
             fibres and need a float SCALAR {RADIUS_ATTRIBUTE} per vertex, in metres",
            present.join(", ")
        ));
    };
    let material = curve_material(prim, materials)?;
    let Some(position_accessor) = prim.get(&Semantic::Positions) else {
        return Err("no POSITION attribute".to_string());
    };
    // From the counts in the JSON, before any data is read, so that a hostile count is
    // refused as what it is.
    let vertex_count = prim
        .indices()
        .map_or(position_accessor.count(), |a| a.count());
    let segments = match prim.mode() {
        Mode::LineStrip => vertex_count.saturating_sub(1),
        _ => vertex_count / 2,
    };
    if segments > MAX_CURVE_SEGMENTS {
        return Err(format!(
            "{segments} segments, more than the {MAX_CURVE_SEGMENTS} a curve set may have \
             (absurd segment counts are refused); split the fibres over several primitives"
        ));
    }
    for (_, accessor) in prim.attributes() {
        check_accessor(&accessor, buffers)?;
    }
    if let Some(a) = prim.indices() {
        check_accessor(&a, buffers)?;
    }
    if radius_accessor.data_type() != DataType::F32
        || radius_accessor.dimensions() != Dimensions::Scalar
    {
        return Err(format!(
            "{RADIUS_ATTRIBUTE} is a {:?} {:?} accessor; it must be a float (5126) SCALAR, \
             the radius in metres",
            radius_accessor.data_type(),
            radius_accessor.dimensions()
        ));
    }
    if position_accessor.data_type() != DataType::F32
        || position_accessor.dimensions() != Dimensions::Vec3
    {
        return Err(format!(
            "POSITION is a {:?} {:?} accessor; it must be a float (5126) VEC3",
            position_accessor.data_type(),
            position_accessor.dimensions()
        ));
    }
    let get = |b: gltf::Buffer| buffers.get(b.index()).copied();
    let positions: Vec<[f32; 3]> = gltf::accessor::Iter::<[f32; 3]>::new(position_accessor, get)
        .ok_or("POSITION does not fit its buffer")?
        .collect();
    let radii: Vec<f32> = gltf::accessor::Iter::<f32>::new(radius_accessor, get)
        .ok_or_else(|| format!("{RADIUS_ATTRIBUTE} does not fit its buffer"))?
        .collect();
    let n = positions.len();
    if radii.len() != n {
        return Err(format!(
            "{RADIUS_ATTRIBUTE} has {} elements for {n} vertices; give every vertex one radius",
            radii.len()
        ));
    }
    if let Some((i, p)) = positions
        .iter()
        .enumerate()
        .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
    {
        return Err(format!(
            "vertex {i} has POSITION {p:?}, which is not finite"
        ));
    }
    if let Some((i, r)) = radii
        .iter()
        .enumerate()
        .find(|(_, r)| !(r.is_finite() && **r > 0.0))
    {
        return Err(format!(
            "vertex {i} has {RADIUS_ATTRIBUTE} {r}; radii must be finite and > 0 (metres)"
        ));
    }
    let indexed = prim.indices().is_some();
    let indices: Vec<u32> = match prim.reader(get).read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if let Some(&i) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(format!(
            "index {i} is out of range: there are only {n} vertices"
        ));
    }
    let mut curves = Curves {
        name: format!("{mesh_name}/{}", prim.index()),
        material,
        ..Curves::default()
    };
    let push = |c: &mut Curves, v: u32| {
        c.points.push(positions[v as usize]);
        c.radii.push(radii[v as usize]);
    };
    curves.offsets.push(0);
    if prim.mode() == Mode::LineStrip {
        if indices.len() < 2 {
            return Err(format!(
                "a strand of {} point; a strand needs at least 2",
                indices.len()
            ));
        }
        for &v in &indices {
            push(&mut curves, v);
        }
        curves.offsets.push(curves.points.len() as u32);
    } else {
        if !indices.len().is_multiple_of(2) {
            return Err(format!(
                "{} {}, not a multiple of 2 (LINES takes vertex pairs)",
                indices.len(),
                if indexed { "indices" } else { "vertices" }
            ));
        }
        // Where pair k ends and pair k + 1 starts on the same vertex, the strand goes on.
        let same_vertex = |a: u32, b: u32| {
            if indexed {
                a == b
            } else {
                let (a, b) = (a as usize, b as usize);
                positions[a].map(f32::to_bits) == positions[b].map(f32::to_bits)
                    && radii[a].to_bits() == radii[b].to_bits()
            }
        };
        let mut previous_end: Option<u32> = None;
        for pair in indices.chunks_exact(2) {
            let (a, b) = (pair[0], pair[1]);
            let chained = previous_end.is_some_and(|e| same_vertex(e, a));
            if !chained {
                if previous_end.is_some() {
                    curves.offsets.push(curves.points.len() as u32);
                }
                push(&mut curves, a);
            }
            push(&mut curves, b);
            previous_end = Some(b);
        }
        curves.offsets.push(curves.points.len() as u32);
    }
    curves.validate()?;
    Ok(curves)
}

/// The material index of a line primitive, which must be a `hair` material.
fn curve_material(prim: &gltf::Primitive, materials: &[Material]) -> Result<u32, String> {
    let fix = "set extras.lightfarm.model = \"hair\" on it (the renderer has a fibre BSDF only \
               for hair; see README.md, Hair as fibres)";
    let Some(index) = prim.material().index() else {
        return Err(format!(
            "lines (fibres) without a material; give them a material and {fix}"
        ));
    };
    let m = materials
        .get(index)
        .ok_or_else(|| format!("material {index} does not exist"))?;
    if m.model != MaterialModel::Hair {
        return Err(format!(
            "lines (fibres) with material '{}' of model \"{}\"; {fix}",
            m.name, m.model
        ));
    }
    Ok(index as u32)
}

/// `curves` (object space) placed by the node transform `global`: points transformed, radii
/// scaled by the cube root of |det| of its linear part. The identity leaves every bit as it is.
pub(super) fn to_world(curves: &Curves, global: Mat4) -> Result<Curves, String> {
    if global == Mat4::IDENTITY {
        return Ok(curves.clone());
    }
    let scale = Mat3::from_mat4(global).determinant().abs().cbrt();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(format!(
            "curves '{}' are instanced with a singular or non-finite transform (radius scale \
             {scale}); give the node an invertible transform",
            curves.name
        ));
    }
    let world = Curves {
        name: curves.name.clone(),
        points: curves
            .points
            .iter()
            .map(|p| global.transform_point3(Vec3::from(*p)).to_array())
            .collect(),
        radii: curves.radii.iter().map(|r| r * scale).collect(),
        offsets: curves.offsets.clone(),
        material: curves.material,
    };
    world.validate().map_err(|reason| {
        format!(
            "curves '{}' after the node transform: {reason}; check the node transform",
            curves.name
        )
    })?;
    Ok(world)
}
