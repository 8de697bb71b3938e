//! Morph targets (blend shapes): reading their deltas from glTF and applying weights on the CPU.
//!
//! The deltas are decoded here rather than through `gltf`'s `read_morph_targets`, because its
//! sparse-accessor iterator unwraps when the values run out before the indices and its dense
//! reader trusts the accessor's extent; blend-shape exports are commonly sparse, so a hostile or
//! truncated file must produce an error, not a panic.

use std::collections::BTreeMap;

use glam::Vec3;

use super::geometry::{smooth_normals, unit_or_fallback};
use super::{Mesh, MorphTarget, SceneError};

/// Outside this range blend shapes extrapolate into self-intersection; glTF allows any weight
/// but no facial rig authors more than this.
const WEIGHT_MIN: f64 = -1.0;
const WEIGHT_MAX: f64 = 2.0;

/// How many target names an unknown-name error lists, so the message stays readable for rigs
/// with 50+ shapes.
const NAMES_IN_ERROR: usize = 8;

/// Per-target deltas of one primitive, before merging.
pub(crate) struct PrimitiveTarget {
    pub positions: Vec<[f32; 3]>,
    /// `None` when the target has no NORMAL attribute.
    pub normals: Option<Vec<[f32; 3]>>,
}

/// Reads every morph target of `prim`, whose base geometry has `vertex_count` vertices.
pub(crate) fn read_primitive_targets(
    prim: &gltf::Primitive,
    buffers: &[&[u8]],
    vertex_count: usize,
) -> Result<Vec<PrimitiveTarget>, String> {
    let mut out = Vec::new();
    for (t, target) in prim.morph_targets().enumerate() {
        let context = |e: String| format!("primitive {} morph target {t}: {e}", prim.index());
        let positions = match target.positions() {
            Some(a) => read_vec3_f32(&a, buffers, vertex_count).map_err(context)?,
            // A target may displace only normals; its position deltas are then zero.
            None => vec![[0.0; 3]; vertex_count],
        };
        let normals = target
            .normals()
            .map(|a| read_vec3_f32(&a, buffers, vertex_count))
            .transpose()
            .map_err(context)?;
        out.push(PrimitiveTarget { positions, normals });
    }
    Ok(out)
}

/// `extras.targetNames` of a mesh (the de-facto convention of Blender and three.js), when it is
/// an array of exactly `count` strings.
pub(crate) fn target_names(mesh: &gltf::Mesh, count: usize) -> Option<Vec<String>> {
    let raw = mesh.extras().as_ref()?;
    let value: serde_json::Value = serde_json::from_str(raw.get()).ok()?;
    let names = value.get("targetNames")?.as_array()?;
    let names: Option<Vec<String>> = names
        .iter()
        .map(|v| v.as_str().map(str::to_string))
        .collect();
    match names {
        Some(n) if n.len() == count => Some(n),
        _ => {
            tracing::warn!(
                mesh = ?mesh.name(),
                targets = count,
                "extras.targetNames is not an array of {count} strings; naming targets target0.."
            );
            None
        }
    }
}

/// Accumulates the targets of successive merged primitives into whole-mesh targets.
pub(crate) struct MorphMerge {
    /// `None` once the primitives disagreed and the mesh's targets were dropped.
    targets: Option<Vec<MergedTarget>>,
    started: bool,
    vertices: usize,
}

struct MergedTarget {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    any_normals: bool,
}

impl MorphMerge {
    pub(crate) fn new() -> Self {
        MorphMerge {
            targets: Some(Vec::new()),
            started: false,
            vertices: 0,
        }
    }

    /// Appends one primitive's targets (`vertex_count` vertices); `mesh` names it in warnings.
    pub(crate) fn push(&mut self, mesh: &str, prim: Vec<PrimitiveTarget>, vertex_count: usize) {
        let base = self.vertices;
        self.vertices += vertex_count;
        let Some(targets) = self.targets.as_mut() else {
            return;
        };
        if !self.started {
            self.started = true;
            targets.extend(prim.iter().map(|_| MergedTarget {
                positions: Vec::new(),
                normals: Vec::new(),
                any_normals: false,
            }));
        } else if targets.len() != prim.len() {
            // Deltas cannot be concatenated when one primitive's shape list differs: a weight
            // would move only part of the surface and tear it.
            tracing::warn!(
                mesh,
                expected = targets.len(),
                found = prim.len(),
                "primitives of this mesh have different morph target counts; dropping its morph targets"
            );
            self.targets = None;
            return;
        }
        for (merged, p) in targets.iter_mut().zip(prim) {
            merged.positions.extend(p.positions);
            match p.normals {
                Some(n) => {
                    // Earlier primitives without NORMAL deltas leave their normals unchanged.
                    merged.normals.resize(base, [0.0; 3]);
                    merged.normals.extend(n);
                    merged.any_normals = true;
                }
                None if merged.any_normals => {
                    merged.normals.resize(base + vertex_count, [0.0; 3]);
                }
                None => {}
            }
        }
    }

    pub(crate) fn finish(self, names: Option<Vec<String>>) -> Vec<MorphTarget> {
        let Some(targets) = self.targets else {
            return Vec::new();
        };
        let total = self.vertices;
        targets
            .into_iter()
            .enumerate()
            .map(|(i, t)| {
                let mut normal_deltas = t.normals;
                if t.any_normals {
                    normal_deltas.resize(total, [0.0; 3]);
                }
                MorphTarget {
                    name: names
                        .as_ref()
                        .and_then(|n| n.get(i).cloned())
                        .unwrap_or_else(|| format!("target{i}")),
                    position_deltas: t.positions,
                    normal_deltas,
                }
            })
            .collect()
    }
}

/// Decodes a float VEC3 accessor of exactly `expected` elements, dense or sparse, checking
/// every byte range against its buffer first.
fn read_vec3_f32(
    a: &gltf::Accessor,
    buffers: &[&[u8]],
    expected: usize,
) -> Result<Vec<[f32; 3]>, String> {
    use gltf::accessor::{DataType, Dimensions};
    let idx = a.index();
    if a.data_type() != DataType::F32 || a.dimensions() != Dimensions::Vec3 || a.normalized() {
        return Err(format!(
            "accessor {idx} is {:?} {:?}; morph deltas must be float VEC3 (re-export without quantization)",
            a.dimensions(),
            a.data_type()
        ));
    }
    let count = a.count();
    if count != expected {
        return Err(format!(
            "accessor {idx} has {count} elements but the primitive has {expected} vertices"
        ));
    }
    const ELEM: usize = 12;
    // A sparse accessor without a bufferView starts from all zeros (glTF 2.0 §3.6.2.3).
    let mut out = match a.view() {
        Some(view) => {
            let stride = view.stride().unwrap_or(ELEM);
            let span = match count {
                0 => Some(0),
                c => stride.checked_mul(c - 1).and_then(|x| x.checked_add(ELEM)),
            };
            let bytes = view_bytes(&view, a.offset(), span, buffers)
                .ok_or_else(|| format!("accessor {idx} reaches past its bufferView or buffer"))?;
            (0..count)
                .map(|i| vec3_at(bytes, i * stride))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| format!("accessor {idx} reaches past its bufferView"))?
        }
        None => vec![[0.0; 3]; count],
    };
    if let Some(sparse) = a.sparse() {
        use gltf::accessor::sparse::IndexType;
        let n = sparse.count();
        let ind = sparse.indices();
        let width = match ind.index_type() {
            IndexType::U8 => 1,
            IndexType::U16 => 2,
            IndexType::U32 => 4,
        };
        let index_bytes = view_bytes(&ind.view(), ind.offset(), n.checked_mul(width), buffers)
            .ok_or_else(|| format!("sparse indices of accessor {idx} reach past their buffer"))?;
        let vals = sparse.values();
        let value_bytes = view_bytes(&vals.view(), vals.offset(), n.checked_mul(ELEM), buffers)
            .ok_or_else(|| format!("sparse values of accessor {idx} reach past their buffer"))?;
        for k in 0..n {
            let at = k * width;
            let i = match width {
                1 => index_bytes.get(at).map(|&b| b as usize),
                2 => index_bytes
                    .get(at..at + 2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize),
                _ => index_bytes
                    .get(at..at + 4)
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize),
            };
            let v = vec3_at(value_bytes, k * ELEM);
            match (i, v) {
                (Some(i), Some(v)) if i < count => out[i] = v,
                _ => {
                    return Err(format!(
                        "sparse entry {k} of accessor {idx} targets an element outside 0..{count}"
                    ))
                }
            }
        }
    }
    if out.iter().flatten().any(|c| !c.is_finite()) {
        return Err(format!("accessor {idx} contains non-finite deltas"));
    }
    Ok(out)
}

/// `len` bytes of `view` from `offset`, when both the view and its buffer contain them.
fn view_bytes<'b>(
    view: &gltf::buffer::View,
    offset: usize,
    len: Option<usize>,
    buffers: &[&'b [u8]],
) -> Option<&'b [u8]> {
    let end = offset.checked_add(len?)?;
    if end > view.length() {
        return None;
    }
    let buf = buffers.get(view.buffer().index())?;
    let start = view.offset().checked_add(offset)?;
    buf.get(start..view.offset().checked_add(end)?)
}

fn vec3_at(bytes: &[u8], at: usize) -> Option<[f32; 3]> {
    let b = bytes.get(at..at.checked_add(12)?)?;
    let f = |o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    Some([f(0), f(4), f(8)])
}

impl Mesh {
    /// Deforms the mesh in place by the named blend-shape `weights` (absent names weigh 0):
    /// `positions += Σ w·Δp`. Normals take the targets' NORMAL deltas and are renormalised;
    /// when an active target has none they are recomputed as smooth area-weighted normals of
    /// the morphed surface. Tangents are re-orthogonalised against the new normals.
    ///
    /// Weights outside [-1, 2] are clamped with a warning. Apply to an unmorphed copy: the
    /// call is not idempotent, since the deltas add to the current positions.
    pub fn apply_morphs(&mut self, weights: &BTreeMap<String, f64>) -> Result<(), SceneError> {
        let bad = |reason: String| SceneError::BadMorph {
            mesh: self.name.clone(),
            reason,
        };
        let n = self.positions.len();
        let mut active: Vec<(usize, f32)> = Vec::new();
        for (name, &w) in weights {
            let Some(t) = self.morph_targets.iter().position(|t| &t.name == name) else {
                let available: Vec<&str> = self
                    .morph_targets
                    .iter()
                    .take(NAMES_IN_ERROR)
                    .map(|t| t.name.as_str())
                    .collect();
                let more = self.morph_targets.len().saturating_sub(NAMES_IN_ERROR);
                return Err(bad(if available.is_empty() {
                    format!("unknown morph target '{name}'; this mesh has no morph targets")
                } else {
                    format!(
                        "unknown morph target '{name}'; available: {}{}",
                        available.join(", "),
                        if more > 0 {
                            format!(" and {more} more")
                        } else {
                            String::new()
                        }
                    )
                }));
            };
            if !w.is_finite() {
                return Err(bad(format!(
                    "weight of '{name}' is {w}; use a finite number"
                )));
            }
            let clamped = w.clamp(WEIGHT_MIN, WEIGHT_MAX);
            if clamped != w {
                tracing::warn!(mesh = %self.name, target = %name, weight = w, clamped,
                    "morph weight outside [{WEIGHT_MIN}, {WEIGHT_MAX}]; clamping");
            }
            let target = &self.morph_targets[t];
            // The fields are public, so a caller may have edited them out of step.
            if target.position_deltas.len() != n
                || !(target.normal_deltas.is_empty() || target.normal_deltas.len() == n)
            {
                return Err(bad(format!(
                    "target '{name}' has {} position / {} normal deltas for {n} vertices",
                    target.position_deltas.len(),
                    target.normal_deltas.len()
                )));
            }
            if clamped != 0.0 {
                active.push((t, clamped as f32));
            }
        }
        if active.is_empty() {
            // Leaves the geometry bit-identical rather than recomputing normals needlessly.
            return Ok(());
        }

        for &(t, w) in &active {
            for (p, d) in self
                .positions
                .iter_mut()
                .zip(&self.morph_targets[t].position_deltas)
            {
                *p = (Vec3::from(*p) + w * Vec3::from(*d)).to_array();
            }
        }
        let all_have_normals = active
            .iter()
            .all(|&(t, _)| !self.morph_targets[t].normal_deltas.is_empty());
        if all_have_normals && self.normals.len() == n {
            let mut acc: Vec<Vec3> = self.normals.iter().map(|v| Vec3::from(*v)).collect();
            for &(t, w) in &active {
                for (a, d) in acc.iter_mut().zip(&self.morph_targets[t].normal_deltas) {
                    *a += w * Vec3::from(*d);
                }
            }
            self.normals = acc.into_iter().map(unit_or_fallback).collect();
        } else {
            self.normals = smooth_normals(&self.positions, &self.indices);
        }

        for (t, nrm) in self.tangents.iter_mut().zip(&self.normals) {
            let xyz = Vec3::new(t[0], t[1], t[2]);
            // All-zero tangents mark a mesh without UVs; they stay zero.
            if xyz == Vec3::ZERO {
                continue;
            }
            let nv = Vec3::from(*nrm);
            let o = (xyz - nv * nv.dot(xyz)).normalize_or_zero();
            let o = if o == Vec3::ZERO || !o.is_finite() {
                nv.any_orthonormal_vector()
            } else {
                o
            };
            *t = [o.x, o.y, o.z, t[3]];
        }
        Ok(())
    }
}
