//! The MakeHuman base mesh (hm08) as Wavefront OBJ: positions, UVs and polygon faces with the
//! group each belongs to.
//!
//! General OBJ crates re-index vertices per object, but MakeHuman targets address the file's
//! global vertex numbers, and the joint groups are only vertex sets; so this reads the subset
//! hm08 uses (`v`, `vt`, `g`, `f` with `v/vt` corners) and keeps the file's numbering.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{model_error, IdentityError};

/// A polygon (triangle or quad in hm08): corners as (vertex, uv) indices, 0-based.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    pub group: u16,
    pub corners: Vec<(u32, u32)>,
}

#[derive(Clone, Debug)]
pub struct BaseMesh {
    /// Decimetres, +Y up, facing +Z (MakeHuman's units).
    pub positions: Vec<[f32; 3]>,
    /// OBJ convention: v = 0 at the bottom of the image.
    pub uvs: Vec<[f32; 2]>,
    pub faces: Vec<Face>,
    /// Group names, indexed by [`Face::group`].
    pub groups: Vec<String>,
}

impl BaseMesh {
    /// Parses OBJ text; `path` only labels errors, which name the line.
    pub fn parse(text: &str, path: &Path) -> Result<BaseMesh, IdentityError> {
        let mut mesh = BaseMesh {
            positions: Vec::new(),
            uvs: Vec::new(),
            faces: Vec::new(),
            groups: Vec::new(),
        };
        let mut group_ids: BTreeMap<String, u16> = BTreeMap::new();
        let mut group: Option<u16> = None;
        for (n, line) in text.lines().enumerate() {
            let at = || format!("line {}", n + 1);
            let mut it = line.split_whitespace();
            let Some(tag) = it.next() else { continue };
            let floats =
                |it: std::str::SplitWhitespace<'_>, k: usize| -> Result<Vec<f32>, IdentityError> {
                    let v: Vec<f32> = it
                        .take(k)
                        .map(|s| s.parse::<f32>())
                        .collect::<Result<_, _>>()
                        .map_err(|e| model_error(path, at(), format!("bad number: {e}")))?;
                    if v.len() != k || v.iter().any(|x| !x.is_finite()) {
                        return Err(model_error(
                            path,
                            at(),
                            format!("expected {k} finite numbers"),
                        ));
                    }
                    Ok(v)
                };
            match tag {
                "v" => {
                    let v = floats(it, 3)?;
                    mesh.positions.push([v[0], v[1], v[2]]);
                }
                "vt" => {
                    let v = floats(it, 2)?;
                    mesh.uvs.push([v[0], v[1]]);
                }
                "g" | "o" => {
                    let name = line[tag.len()..].trim().to_owned();
                    let next = group_ids.len();
                    let id = *group_ids.entry(name.clone()).or_insert_with(|| {
                        mesh.groups.push(name);
                        next as u16
                    });
                    group = Some(id);
                }
                "f" => {
                    // Faces before any `g` line (the eye proxy has none) form group "".
                    let g = match group {
                        Some(g) => g,
                        None => {
                            let next = group_ids.len();
                            let id = *group_ids.entry(String::new()).or_insert_with(|| {
                                mesh.groups.push(String::new());
                                next as u16
                            });
                            group = Some(id);
                            id
                        }
                    };
                    let mut corners = Vec::with_capacity(4);
                    for tok in it {
                        let mut p = tok.split('/');
                        let idx = |s: Option<&str>,
                                   what: &str,
                                   len: usize|
                         -> Result<u32, IdentityError> {
                            let s = s.filter(|s| !s.is_empty()).ok_or_else(|| {
                                model_error(
                                    path,
                                    at(),
                                    format!("corner {tok:?} has no {what} index"),
                                )
                            })?;
                            let i: usize = s.parse().map_err(|_| {
                                model_error(path, at(), format!("corner {tok:?}: bad {what} index"))
                            })?;
                            if i == 0 || i > len {
                                return Err(model_error(
                                    path,
                                    at(),
                                    format!("corner {tok:?}: {what} index {i} outside 1..={len}"),
                                ));
                            }
                            Ok((i - 1) as u32)
                        };
                        let v = idx(p.next(), "vertex", mesh.positions.len())?;
                        let t = idx(p.next(), "uv", mesh.uvs.len())?;
                        corners.push((v, t));
                    }
                    if corners.len() < 3 {
                        return Err(model_error(path, at(), "a face with fewer than 3 corners"));
                    }
                    mesh.faces.push(Face { group: g, corners });
                }
                _ => {}
            }
        }
        if mesh.positions.is_empty() || mesh.faces.is_empty() {
            return Err(model_error(path, "mesh", "no vertices or no faces"));
        }
        Ok(mesh)
    }

    pub fn group(&self, name: &str) -> Option<u16> {
        self.groups.iter().position(|g| g == name).map(|i| i as u16)
    }

    /// Faces of group `name`.
    pub fn faces_of<'a>(&'a self, name: &str) -> impl Iterator<Item = &'a Face> + 'a {
        let g = self.group(name);
        self.faces.iter().filter(move |f| Some(f.group) == g)
    }

    /// The distinct vertices of group `name`, sorted.
    pub fn vertices_of(&self, name: &str) -> Vec<u32> {
        let mut v: Vec<u32> = self
            .faces_of(name)
            .flat_map(|f| f.corners.iter().map(|c| c.0))
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    }
}

/// Fan triangulation of a polygon's corners.
pub fn triangles(face: &Face) -> impl Iterator<Item = [(u32, u32); 3]> + '_ {
    (1..face.corners.len() - 1)
        .map(move |k| [face.corners[0], face.corners[k], face.corners[k + 1]])
}
