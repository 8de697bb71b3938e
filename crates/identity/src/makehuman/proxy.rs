//! MakeHuman proxies (`.mhclo`): a mesh whose every vertex rides three base-mesh vertices,
//! so it follows any shape of the body. The eyes are one.
//!
//! The fitting rule is MakeHuman's (`proxy.py`): vertex = Σ wᵢ·body[refᵢ] + offset ⊙ scale,
//! where each axis of the offset is scaled by the body's extent between two reference vertices
//! over the extent when the proxy was made (`x_scale a b ref`).

use std::path::Path;

use crate::error::{model_error, IdentityError};

#[derive(Clone, Debug, PartialEq)]
pub struct Proxy {
    pub refs: Vec<[u32; 3]>,
    pub weights: Vec<[f32; 3]>,
    pub offsets: Vec<[f32; 3]>,
    /// Per axis: the two body vertices and the reference extent (decimetres).
    pub scales: [Option<(u32, u32, f32)>; 3],
}

impl Proxy {
    pub fn parse(text: &str, path: &Path) -> Result<Proxy, IdentityError> {
        let mut p = Proxy {
            refs: vec![],
            weights: vec![],
            offsets: vec![],
            scales: [None; 3],
        };
        let mut in_verts = false;
        for (n, line) in text.lines().enumerate() {
            let s = line.trim();
            if s.is_empty() || s.starts_with('#') {
                continue;
            }
            let bad = |r: &str| model_error(path, format!("line {}", n + 1), r);
            let f: Vec<&str> = s.split_whitespace().collect();
            match f[0] {
                "x_scale" | "y_scale" | "z_scale" => {
                    let axis = usize::from(f[0].as_bytes()[0] - b'x');
                    let (Some(a), Some(b), Some(r)) = (
                        f.get(1).and_then(|v| v.parse().ok()),
                        f.get(2).and_then(|v| v.parse().ok()),
                        f.get(3).and_then(|v| v.parse::<f32>().ok()),
                    ) else {
                        return Err(bad("expected `x_scale vertex vertex extent`"));
                    };
                    if !(r.is_finite() && r > 0.0) {
                        return Err(bad("the reference extent must be > 0"));
                    }
                    p.scales[axis] = Some((a, b, r));
                }
                "verts" => in_verts = true,
                "delete_verts" | "weights" => in_verts = false,
                first if in_verts && first.starts_with(|c: char| c.is_ascii_digit()) => {
                    let nums = |range: std::ops::Range<usize>| -> Option<Vec<f32>> {
                        f.get(range)?
                            .iter()
                            .map(|v| v.parse::<f32>().ok().filter(|x| x.is_finite()))
                            .collect()
                    };
                    if f.len() == 1 {
                        let v: u32 = first.parse().map_err(|_| bad("bad vertex number"))?;
                        p.refs.push([v; 3]);
                        p.weights.push([1.0, 0.0, 0.0]);
                        p.offsets.push([0.0; 3]);
                    } else if f.len() >= 9 {
                        let r = nums(0..3).ok_or_else(|| bad("bad vertex numbers"))?;
                        let w = nums(3..6).ok_or_else(|| bad("bad weights"))?;
                        let o = nums(6..9).ok_or_else(|| bad("bad offset"))?;
                        p.refs.push([r[0] as u32, r[1] as u32, r[2] as u32]);
                        p.weights.push([w[0], w[1], w[2]]);
                        p.offsets.push([o[0], o[1], o[2]]);
                    } else {
                        return Err(bad("a vertex line needs 1 or 9 numbers"));
                    }
                }
                _ => {}
            }
        }
        if p.refs.is_empty() {
            return Err(model_error(path, "verts", "no proxy vertices"));
        }
        Ok(p)
    }

    /// The proxy's vertices on a body with `body` positions.
    pub fn fit(&self, body: &[[f32; 3]]) -> Result<Vec<[f32; 3]>, String> {
        let get = |i: u32| {
            body.get(i as usize)
                .copied()
                .ok_or_else(|| format!("proxy refers to body vertex {i} of {}", body.len()))
        };
        let mut scale = [1.0f32; 3];
        for (axis, s) in self.scales.iter().enumerate() {
            if let Some((a, b, r)) = *s {
                scale[axis] = (get(a)?[axis] - get(b)?[axis]).abs() / r;
            }
        }
        self.refs
            .iter()
            .zip(&self.weights)
            .zip(&self.offsets)
            .map(|((r, w), o)| {
                let mut v = [0.0f32; 3];
                for k in 0..3 {
                    let p = get(r[k])?;
                    for a in 0..3 {
                        v[a] += w[k] * p[a];
                    }
                }
                for a in 0..3 {
                    v[a] += o[a] * scale[a];
                }
                Ok(v)
            })
            .collect()
    }
}
