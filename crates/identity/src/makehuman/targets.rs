//! MakeHuman targets: sparse per-vertex offsets of the base mesh.
//!
//! Two encodings are read. The compiled set in the `makehuman` 1.3.2 wheel,
//! `makehuman/data/targets.npz`: per target `targets/<group>/<name>.index` (uint16 vertex
//! numbers) and `.vector` (int16 × 3, thousandths of a decimetre). And the text `.target` files
//! of the Face Units pack: `vertex dx dy dz` lines in decimetres, `#` comments.

use std::collections::BTreeMap;
use std::io::{Read, Seek};
use std::path::Path;

use crate::error::{model_error, IdentityError};

/// One target: `positions[indices[i]] += weight * deltas[i]` (decimetres).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Target {
    pub indices: Vec<u32>,
    pub deltas: Vec<[f32; 3]>,
}

impl Target {
    /// Adds `weight` times the target to `positions`; an index outside them is an error.
    pub fn apply(&self, positions: &mut [[f32; 3]], weight: f32) -> Result<(), String> {
        if weight == 0.0 {
            return Ok(());
        }
        let n = positions.len();
        for (&i, d) in self.indices.iter().zip(&self.deltas) {
            let p = positions
                .get_mut(i as usize)
                .ok_or_else(|| format!("vertex {i} is outside the base mesh's {n} vertices"))?;
            for k in 0..3 {
                p[k] += weight * d[k];
            }
        }
        Ok(())
    }
}

/// Targets by name, `<group>/<name>` without the `targets/` prefix, e.g.
/// `macrodetails/african-female-young` or `nose/nose-scale-horiz-incr`.
pub type Targets = BTreeMap<String, Target>;

/// Thousandths of a decimetre per int16 step in the compiled set.
const NPZ_UNIT_DM: f32 = 1e-3;

fn widen<T: Into<i64>>(v: Vec<T>) -> Vec<i64> {
    v.into_iter().map(Into::into).collect()
}

/// Reads every target of a compiled `targets.npz` (the licence entry, a pickled object array,
/// is skipped: nothing here unpickles).
pub fn read_npz<R: Read + Seek>(reader: R, path: &Path) -> Result<Targets, IdentityError> {
    let bad = |what: &str, reason: String| model_error(path, what, reason);
    let mut npz = npyz::npz::NpzArchive::new(reader)
        .map_err(|e| bad("archive", format!("not a zip/npz file ({e})")))?;
    let names: Vec<String> = npz
        .array_names()
        .filter_map(|n| n.strip_suffix(".index"))
        .map(str::to_owned)
        .collect();
    if names.is_empty() {
        return Err(bad(
            "archive",
            "no `<name>.index` arrays: not a MakeHuman target set".into(),
        ));
    }
    let mut out = Targets::new();
    for name in names {
        let mut read = |suffix: &str| -> Result<(Vec<u64>, Vec<i64>), IdentityError> {
            let entry = format!("{name}.{suffix}");
            let file = npz
                .by_name(&entry)
                .map_err(|e| bad(&entry, e.to_string()))?
                .ok_or_else(|| bad(&entry, "missing (every .index needs its .vector)".into()))?;
            let shape = file.shape().to_vec();
            let values = match file.dtype().descr().trim_matches('\'') {
                "<u2" => file.into_vec::<u16>().map(widen),
                "<i2" => file.into_vec::<i16>().map(widen),
                "<u4" => file.into_vec::<u32>().map(widen),
                "<i4" => file.into_vec::<i32>().map(widen),
                other => {
                    return Err(bad(
                        &entry,
                        format!("dtype {other}; expected 16- or 32-bit integers"),
                    ))
                }
            }
            .map_err(|e| bad(&entry, e.to_string()))?;
            Ok((shape, values))
        };
        let (ishape, index) = read("index")?;
        let (vshape, vector) = read("vector")?;
        let n = index.len();
        if ishape.len() != 1 || vshape != [n as u64, 3] {
            return Err(bad(
                &name,
                format!(
                    "index shape {ishape:?} and vector shape {vshape:?}; expected (n,) and (n, 3)"
                ),
            ));
        }
        let indices = index
            .iter()
            .map(|&i| {
                u32::try_from(i).map_err(|_| bad(&name, format!("negative vertex index {i}")))
            })
            .collect::<Result<Vec<u32>, _>>()?;
        let deltas = vector
            .chunks_exact(3)
            .map(|d| [d[0], d[1], d[2]].map(|x| x as f32 * NPZ_UNIT_DM))
            .collect();
        let key = name.strip_prefix("targets/").unwrap_or(&name).to_owned();
        out.insert(key, Target { indices, deltas });
    }
    Ok(out)
}

/// Parses a text `.target` file (`vertex dx dy dz` per line).
pub fn parse_text(text: &str, path: &Path) -> Result<Target, IdentityError> {
    let mut t = Target::default();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |reason: &str| model_error(path, format!("line {}", n + 1), reason);
        let mut it = line.split_whitespace();
        let i: u32 = it
            .next()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| bad("expected a vertex number first"))?;
        let d: Vec<f32> = it
            .map(|s| s.parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad("bad offset"))?;
        if d.len() != 3 || d.iter().any(|x| !x.is_finite()) {
            return Err(bad("expected `vertex dx dy dz`"));
        }
        t.indices.push(i);
        t.deltas.push([d[0], d[1], d[2]]);
    }
    if t.indices.is_empty() {
        return Err(model_error(path, "target", "no offsets"));
    }
    Ok(t)
}
