//! dlib's 5-point face landmarks (`shape_predictor_5_face_landmarks.dat`, Davis King, public
//! domain): a cascade of regression-tree forests (Kazemi & Sullivan 2014) that moves a mean
//! shape, placed in a detection box, onto the corners of both eyes and the base of the nose.
//! Each cascade reads grey levels at points fixed relative to the current shape, compares pairs
//! of them in every tree, and adds the reached leaves' offsets to the shape.

use std::path::{Path, PathBuf};

use crate::detect::Detection;
use crate::dlib::Reader;
use crate::{FaceError, Image};

/// Where `./scripts/fetch-models.sh` installs the landmark model, relative to the asset
/// directory.
pub const LANDMARKS_FILE: &str = "models/dlib/shape_predictor_5_face_landmarks.dat";

/// The built-in landmark model in the asset pack.
pub fn builtin_landmarks() -> PathBuf {
    lightfarm_scene::catalog::builtin_assets_dir().join(LANDMARKS_FILE)
}

struct Tree {
    /// (feature a, feature b, threshold): go left when value a − value b > threshold.
    splits: Vec<(usize, usize, f32)>,
    /// One shape offset per leaf, `2 × parts` values each, concatenated.
    leaves: Vec<f32>,
}

struct Cascade {
    trees: Vec<Tree>,
    /// Each feature point: the shape point it hangs from and its offset in the mean shape.
    anchors: Vec<(usize, [f32; 2])>,
}

/// The landmark predictor.
pub struct ShapePredictor {
    /// The mean shape in box coordinates ((0, 0) top-left, (1, 1) bottom-right corner).
    initial: Vec<[f32; 2]>,
    cascades: Vec<Cascade>,
}

impl ShapePredictor {
    pub fn load(path: &Path) -> Result<Self, FaceError> {
        let bytes = crate::read_model(
            path,
            builtin_landmarks(),
            crate::recognition::FACE_NET_FIX,
            "shape_predictor_5_face_landmarks.dat",
        )?;
        Self::parse(&mut Reader::new(path, &bytes))
    }

    fn parse(r: &mut Reader<'_>) -> Result<Self, FaceError> {
        r.version("the shape predictor", &[1])?;
        let initial = r.column()?;
        if initial.is_empty() || initial.len() % 2 != 0 {
            return Err(r.error(format!("initial shape of {} values", initial.len())));
        }
        let parts = initial.len() / 2;
        let initial: Vec<[f32; 2]> = initial.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
        let n_cascades = r.size("cascades", 1000)?;
        let mut forests = Vec::with_capacity(n_cascades);
        for _ in 0..n_cascades {
            let n_trees = r.size("trees", 100_000)?;
            let mut trees = Vec::with_capacity(n_trees);
            for _ in 0..n_trees {
                let n_splits = r.size("splits", 1 << 16)?;
                let mut splits = Vec::with_capacity(n_splits);
                for _ in 0..n_splits {
                    let a = r.size("feature index", 1 << 20)?;
                    let b = r.size("feature index", 1 << 20)?;
                    splits.push((a, b, r.float()?));
                }
                let n_leaves = r.size("leaves", 1 << 17)?;
                if n_leaves != n_splits + 1 || !n_leaves.is_power_of_two() {
                    return Err(r.error(format!(
                        "a tree of {n_splits} splits and {n_leaves} leaves is not complete"
                    )));
                }
                let mut leaves = Vec::with_capacity(n_leaves * 2 * parts);
                for _ in 0..n_leaves {
                    let leaf = r.column()?;
                    if leaf.len() != 2 * parts {
                        return Err(r.error(format!(
                            "a leaf of {} values for {parts} points",
                            leaf.len()
                        )));
                    }
                    leaves.extend(leaf);
                }
                trees.push(Tree { splits, leaves });
            }
            forests.push(trees);
        }
        let anchor_idx: Vec<Vec<usize>> = r.list(|r| r.list(|r| r.size("anchor", 1 << 20)))?;
        let deltas: Vec<Vec<[f32; 2]>> = r.list(|r| r.list(|r| Ok([r.float()?, r.float()?])))?;
        if anchor_idx.len() != n_cascades || deltas.len() != n_cascades {
            return Err(r.error("feature points for a different number of cascades"));
        }
        let mut cascades = Vec::with_capacity(n_cascades);
        for ((trees, idx), delta) in forests.into_iter().zip(anchor_idx).zip(deltas) {
            if idx.len() != delta.len() || idx.iter().any(|&i| i >= parts) {
                return Err(r.error("feature points that hang from no shape point"));
            }
            let features = idx.len();
            if trees
                .iter()
                .flat_map(|t| &t.splits)
                .any(|&(a, b, _)| a >= features || b >= features)
            {
                return Err(r.error(format!("a split reads past the {features} feature points")));
            }
            cascades.push(Cascade {
                trees,
                anchors: idx.into_iter().zip(delta).collect(),
            });
        }
        if !r.at_end() {
            return Err(r.error("unexpected data after the shape predictor"));
        }
        Ok(ShapePredictor { initial, cascades })
    }

    /// The landmarks of the face in `bbox`, in image pixel coordinates.
    pub fn predict(&self, image: &Image<'_>, bbox: &Detection) -> Vec<[f32; 2]> {
        let gray: Vec<u8> = image
            .rgb
            .chunks_exact(3)
            .map(|p| ((u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2])) / 3) as u8)
            .collect();
        // dlib's rectangles are inclusive: the box spans width − 1 pixel steps.
        let (x0, y0) = (bbox.left.round(), bbox.top.round());
        let (sx, sy) = (bbox.width.round() - 1.0, bbox.height.round() - 1.0);
        let to_image = |p: [f32; 2]| [x0 + p[0] * sx, y0 + p[1] * sy];
        let parts = self.initial.len();
        let mut shape = self.initial.clone();
        let mut values = Vec::new();
        for cascade in &self.cascades {
            // The similarity (rotation and scale only) that takes the mean shape to the
            // current one carries each feature point's offset along.
            let m = similarity(&self.initial, &shape);
            values.clear();
            values.extend(cascade.anchors.iter().map(|&(a, d)| {
                let p = [
                    m.a * d[0] - m.b * d[1] + shape[a][0],
                    m.b * d[0] + m.a * d[1] + shape[a][1],
                ];
                let [x, y] = to_image(p);
                let (x, y) = ((x + 0.5).floor(), (y + 0.5).floor());
                if x >= 0.0 && y >= 0.0 && (x as usize) < image.width && (y as usize) < image.height
                {
                    f32::from(gray[y as usize * image.width + x as usize])
                } else {
                    0.0
                }
            }));
            for tree in &cascade.trees {
                let mut i = 0;
                while i < tree.splits.len() {
                    let (a, b, t) = tree.splits[i];
                    i = if values[a] - values[b] > t {
                        2 * i + 1
                    } else {
                        2 * i + 2
                    };
                }
                let leaf = &tree.leaves[(i - tree.splits.len()) * 2 * parts..][..2 * parts];
                for (p, d) in shape.iter_mut().zip(leaf.chunks_exact(2)) {
                    p[0] += d[0];
                    p[1] += d[1];
                }
            }
        }
        shape.into_iter().map(to_image).collect()
    }
}

/// A 2-D similarity x' = [a −b; b a] x + t.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Similarity {
    pub a: f32,
    pub b: f32,
    pub t: [f32; 2],
}

impl Similarity {
    pub fn apply(&self, p: [f32; 2]) -> [f32; 2] {
        [
            self.a * p[0] - self.b * p[1] + self.t[0],
            self.b * p[0] + self.a * p[1] + self.t[1],
        ]
    }

    /// Pixels of the output per pixel of the input.
    pub fn scale(&self) -> f32 {
        self.a.hypot(self.b)
    }
}

/// The least-squares similarity taking `from` onto `to` (Umeyama 1991 in 2-D, where it has a
/// closed form; a reflection is never the answer for point sets of the same handedness).
pub(crate) fn similarity(from: &[[f32; 2]], to: &[[f32; 2]]) -> Similarity {
    let n = from.len().max(1) as f32;
    let mean = |ps: &[[f32; 2]]| {
        let s = ps
            .iter()
            .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
        [s[0] / n, s[1] / n]
    };
    let (mf, mt) = (mean(from), mean(to));
    let (mut dot, mut cross, mut norm) = (0f32, 0f32, 0f32);
    for (p, q) in from.iter().zip(to) {
        let (px, py) = (p[0] - mf[0], p[1] - mf[1]);
        let (qx, qy) = (q[0] - mt[0], q[1] - mt[1]);
        dot += px * qx + py * qy;
        cross += px * qy - py * qx;
        norm += px * px + py * py;
    }
    let (a, b) = if norm > 0.0 {
        (dot / norm, cross / norm)
    } else {
        (1.0, 0.0)
    };
    Similarity {
        a,
        b,
        t: [
            mt[0] - (a * mf[0] - b * mf[1]),
            mt[1] - (b * mf[0] + a * mf[1]),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn similarity_recovers_a_rotation_scale_and_shift() {
        let from = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [3.0, 1.0]];
        let truth = Similarity {
            a: 1.5 * 0.3f32.cos(),
            b: 1.5 * 0.3f32.sin(),
            t: [4.0, -2.0],
        };
        let to: Vec<[f32; 2]> = from.iter().map(|&p| truth.apply(p)).collect();
        let got = similarity(&from, &to);
        assert!((got.a - truth.a).abs() < 1e-5 && (got.b - truth.b).abs() < 1e-5);
        assert!((got.t[0] - 4.0).abs() < 1e-4 && (got.t[1] + 2.0).abs() < 1e-4);
        assert!((got.scale() - 1.5).abs() < 1e-5);
    }
}
