//! The ICT identity modes as displacements of MakeHuman base-mesh vertices.
//!
//! Once per process, every skin vertex of the base mesh's head is matched to a point of the
//! ICT neutral face: the ICT face is scaled and moved onto the base mesh by the eyes, a
//! thin-plate spline through twelve landmarks found on both (nose tip, lips, chin, forehead,
//! cheeks, temples, crown, back of the head, eyes) carries the base mesh's features onto the
//! ICT ones, and the closest point of the ICT skin gives the triangle and barycentrics. A
//! person's displacement at a vertex is then Σ cₘ · modeₘ at that point, scaled into the base
//! mesh's units, faded out where the match is poor (over 0.5-1.5 cm of distance) and below the
//! jaw (12-17 cm under the eyes), so MakeHuman's neck and shoulders, and the garment's fit to
//! them, stay as they were. Eyeballs, teeth and tongue move rigidly with the ICT eyeballs and
//! teeth, and the eyelids with their eyeball.

use std::collections::HashMap;

use super::IctModel;
use crate::makehuman::obj::BaseMesh;

/// Matches farther than this (decimetres) from the ICT skin are not used.
const MATCH_MAX_DM: f32 = 0.15;
/// Matches closer than this are used at full weight.
const MATCH_FULL_DM: f32 = 0.05;
/// The displacement fades out from this far below the eyes (the chin and jaw) to
/// [`NECK_END_DM`], so the neck at the collar, which the garment is fitted to, is MakeHuman's.
const NECK_START_DM: f32 = 1.2;
const NECK_END_DM: f32 = 1.7;
/// Skin this close to an eyeball's centre (the lids) moves with the eyeball, blending to its
/// own match by [`EYE_OUTER_DM`]: closest points do not carry the lid margin exactly onto the
/// ICT one, and lids moving apart from the eyeball open or close the eye.
const EYE_INNER_DM: f32 = 0.15;
const EYE_OUTER_DM: f32 = 0.25;
/// Grid cell of the closest-point search, decimetres.
const CELL_DM: f32 = 0.1;

/// A base-mesh vertex's point on the ICT skin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    pub vertex: u32,
    pub triangle: [u32; 3],
    pub barycentric: [f32; 3],
    /// 0 where the match is not used (skin that only follows an eye).
    pub weight: f32,
    /// The eye (0 at +x, 1 at -x) whose rigid motion this vertex follows, and by how much.
    pub eye: Option<(usize, f32)>,
}

/// The ICT modes carried onto one base mesh.
#[derive(Clone, Debug)]
pub struct IctFace {
    pub model: IctModel,
    pub matches: Vec<Match>,
    /// Base-mesh vertices of the eye at +x and at -x, and of the teeth and tongue.
    eyes: [Vec<u32>; 2],
    mouth: Vec<u32>,
    /// Per mode: the mean displacement of each ICT eyeball and of the ICT teeth (cm).
    eye_means: Vec<[[f32; 3]; 2]>,
    mouth_means: Vec<[f32; 3]>,
    /// Decimetres of the base mesh per centimetre of the ICT model.
    pub scale: f32,
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = sub(a, b);
    dot(d, d).sqrt()
}
fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn mean(points: &[[f32; 3]], idx: &[u32]) -> [f32; 3] {
    let mut c = [0.0f64; 3];
    for &i in idx {
        for (a, x) in c.iter_mut().zip(points[i as usize]) {
            *a += f64::from(x);
        }
    }
    c.map(|x| (x / idx.len().max(1) as f64) as f32)
}

/// Twelve landmarks of a head given its skin points, relative to the eyes' midpoint `e` and
/// their centres (decimetres, MakeHuman's frame). `None` names the one not found.
fn landmarks(skin: &[[f32; 3]], eyes: [[f32; 3]; 2]) -> Result<Vec<[f32; 3]>, &'static str> {
    let e = [0, 1, 2].map(|k| 0.5 * (eyes[0][k] + eyes[1][k]));
    let best = |what: &'static str,
                keep: &dyn Fn([f32; 3]) -> bool,
                key: &dyn Fn([f32; 3]) -> f32|
     -> Result<[f32; 3], &'static str> {
        let mut out: Option<([f32; 3], f32)> = None;
        for &p in skin {
            let q = sub(p, e);
            if keep(q) && out.is_none_or(|(_, k)| key(q) > k) {
                out = Some((p, key(q)));
            }
        }
        out.map(|(p, _)| p).ok_or(what)
    };
    let band = |x: [f32; 2], y: [f32; 2]| {
        move |q: [f32; 3]| (x[0]..=x[1]).contains(&q[0]) && (y[0]..=y[1]).contains(&q[1])
    };
    let front = |q: [f32; 3]| q[2];
    let mid = [-0.05, 0.05];
    Ok(vec![
        eyes[0],
        eyes[1],
        best("nose tip", &band(mid, [-0.45, -0.2]), &front)?,
        best("upper lip", &band(mid, [-0.75, -0.55]), &front)?,
        best("chin", &band(mid, [-1.3, -1.0]), &front)?,
        best("forehead", &band(mid, [0.35, 0.6]), &front)?,
        best("cheek", &band([0.3, 0.45], [-0.5, -0.3]), &front)?,
        best("cheek", &band([-0.45, -0.3], [-0.5, -0.3]), &front)?,
        best("temple", &band([0.0, 2.0], [0.3, 0.6]), &|q| q[0])?,
        best("temple", &band([-2.0, 0.0], [0.3, 0.6]), &|q| -q[0])?,
        best("crown", &band([-0.1, 0.1], [0.0, 3.0]), &|q| q[1])?,
        best("back of the head", &band([-0.1, 0.1], [0.0, 0.5]), &|q| {
            -q[2]
        })?,
    ])
}

/// A 3D thin-plate spline (kernel r) through `from` → `to`: a smooth displacement field.
struct Spline {
    centres: Vec<[f32; 3]>,
    w: Vec<[f64; 3]>,
    affine: [[f64; 3]; 4],
}

impl Spline {
    fn fit(from: &[[f32; 3]], to: &[[f32; 3]]) -> Option<Spline> {
        let n = from.len();
        let m = n + 4;
        // A little smoothing keeps the system well posed if two landmarks nearly coincide.
        let lambda = 1e-3;
        let mut a = vec![vec![0.0f64; m + 3]; m];
        for i in 0..n {
            for j in 0..n {
                a[i][j] = f64::from(dist(from[i], from[j])) + if i == j { lambda } else { 0.0 };
            }
            let p = [1.0, from[i][0], from[i][1], from[i][2]].map(f64::from);
            for k in 0..4 {
                a[i][n + k] = p[k];
                a[n + k][i] = p[k];
            }
            for k in 0..3 {
                a[i][m + k] = f64::from(to[i][k] - from[i][k]);
            }
        }
        // Gauss-Jordan elimination with partial pivoting, in a fixed order.
        for col in 0..m {
            let pivot = (col..m).max_by(|&r, &s| a[r][col].abs().total_cmp(&a[s][col].abs()))?;
            if a[pivot][col].abs() < 1e-12 {
                return None;
            }
            a.swap(col, pivot);
            let inv = 1.0 / a[col][col];
            for v in a[col].iter_mut() {
                *v *= inv;
            }
            let pivot_row = a[col].clone();
            for (r, row) in a.iter_mut().enumerate() {
                let f = row[col];
                if r != col && f != 0.0 {
                    for (x, p) in row.iter_mut().zip(&pivot_row) {
                        *x -= f * p;
                    }
                }
            }
        }
        let row = |r: usize| [a[r][m], a[r][m + 1], a[r][m + 2]];
        Some(Spline {
            centres: from.to_vec(),
            w: (0..n).map(row).collect(),
            affine: [row(n), row(n + 1), row(n + 2), row(n + 3)],
        })
    }

    fn warp(&self, p: [f32; 3]) -> [f32; 3] {
        let q = p.map(f64::from);
        let mut d = self.affine[0];
        // Per component the terms are added in the same order as a row-by-column product.
        for (row, qa) in self.affine[1..].iter().zip(q) {
            for (dk, rk) in d.iter_mut().zip(row) {
                *dk += rk * qa;
            }
        }
        for (c, w) in self.centres.iter().zip(&self.w) {
            let r = f64::from(dist(p, *c));
            for (dk, wk) in d.iter_mut().zip(w) {
                *dk += wk * r;
            }
        }
        [0, 1, 2].map(|k| p[k] + d[k] as f32)
    }
}

/// The closest point of triangle (a, b, c) to p, as barycentrics (Ericson, Real-Time
/// Collision Detection 5.1.5).
fn closest_barycentric(p: [f32; 3], a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [f32; 3] {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
}

fn cell(p: [f32; 3]) -> [i32; 3] {
    p.map(|x| (x / CELL_DM).floor() as i32)
}

/// Triangles by the grid cells their bounding boxes overlap.
struct Grid<'a> {
    points: &'a [[f32; 3]],
    triangles: &'a [[u32; 3]],
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl<'a> Grid<'a> {
    fn new(points: &'a [[f32; 3]], triangles: &'a [[u32; 3]]) -> Grid<'a> {
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            let c = tri.map(|i| cell(points[i as usize]));
            let lo = [0, 1, 2].map(|k| c.iter().map(|q| q[k]).min().unwrap_or(0));
            let hi = [0, 1, 2].map(|k| c.iter().map(|q| q[k]).max().unwrap_or(0));
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        cells.entry([x, y, z]).or_default().push(t as u32);
                    }
                }
            }
        }
        Grid {
            points,
            triangles,
            cells,
        }
    }

    /// The closest skin point within `MATCH_MAX_DM`: (triangle, barycentrics, distance). Ties
    /// go to the first triangle in cell order, so the answer does not depend on hashing.
    fn closest(&self, p: [f32; 3]) -> Option<(u32, [f32; 3], f32)> {
        let r = (MATCH_MAX_DM / CELL_DM).ceil() as i32;
        let c = cell(p);
        let mut best: Option<(u32, [f32; 3], f32)> = None;
        for x in c[0] - r..=c[0] + r {
            for y in c[1] - r..=c[1] + r {
                for z in c[2] - r..=c[2] + r {
                    let Some(tris) = self.cells.get(&[x, y, z]) else {
                        continue;
                    };
                    for &t in tris {
                        let [a, b, cc] =
                            self.triangles[t as usize].map(|i| self.points[i as usize]);
                        let bary = closest_barycentric(p, a, b, cc);
                        let q =
                            [0, 1, 2].map(|k| bary[0] * a[k] + bary[1] * b[k] + bary[2] * cc[k]);
                        let d = dist(p, q);
                        if d <= MATCH_MAX_DM
                            && best.is_none_or(|(bt, _, bd)| d < bd || (d == bd && t < bt))
                        {
                            best = Some((t, bary, d));
                        }
                    }
                }
            }
        }
        best
    }
}

impl IctFace {
    /// Matches `base`'s head to `model`. An error says which landmark or group is missing.
    pub fn new(model: IctModel, base: &BaseMesh) -> Result<IctFace, String> {
        let group = |name: &str| {
            let v = base.vertices_of(name);
            (!v.is_empty())
                .then_some(v)
                .ok_or_else(|| format!("the base mesh has no group {name:?}"))
        };
        let (l, r) = (group("helper-l-eye")?, group("helper-r-eye")?);
        let (cl, cr) = (mean(&base.positions, &l), mean(&base.positions, &r));
        let (eyes, mh_eyes) = if cl[0] >= cr[0] {
            ([l, r], [cl, cr])
        } else {
            ([r, l], [cr, cl])
        };
        let mut mouth = Vec::new();
        for g in ["helper-upper-teeth", "helper-lower-teeth", "helper-tongue"] {
            mouth.extend(group(g)?);
        }
        let ict_eyes = [0, 1].map(|s| model.centroid(&model.eyes[s]));
        let scale = dist(mh_eyes[0], mh_eyes[1]) / dist(ict_eyes[0], ict_eyes[1]);
        let mh_mid = [0, 1, 2].map(|k| 0.5 * (mh_eyes[0][k] + mh_eyes[1][k]));
        let ict_mid = [0, 1, 2].map(|k| 0.5 * (ict_eyes[0][k] + ict_eyes[1][k]));
        let aligned: Vec<[f32; 3]> = model
            .neutral
            .iter()
            .map(|&p| [0, 1, 2].map(|k| (p[k] - ict_mid[k]) * scale + mh_mid[k]))
            .collect();
        let mut ict_skin: Vec<u32> = model.skin.iter().flatten().copied().collect();
        ict_skin.sort_unstable();
        ict_skin.dedup();
        let ict_points: Vec<[f32; 3]> = ict_skin.iter().map(|&i| aligned[i as usize]).collect();
        let body = group("body")?;
        let body_points: Vec<[f32; 3]> = body.iter().map(|&i| base.positions[i as usize]).collect();
        let ict_eyes_aligned = [0, 1].map(|s| mean(&aligned, &model.eyes[s]));
        let to = landmarks(&ict_points, ict_eyes_aligned)
            .map_err(|what| format!("the ICT face's {what} was not found"))?;
        let from = landmarks(&body_points, mh_eyes)
            .map_err(|what| format!("the base mesh's {what} was not found"))?;
        let spline = Spline::fit(&from, &to).ok_or("the landmarks are degenerate")?;

        let grid = Grid::new(&aligned, &model.skin);
        let neck_end = mh_mid[1] - NECK_END_DM;
        let mut matches = Vec::new();
        for &v in &body {
            let p = base.positions[v as usize];
            if p[1] <= neck_end {
                continue;
            }
            // Unmatched skin by an eye still follows the eyeball (weight 0 on its own match).
            let (t, bary, d) =
                grid.closest(spline.warp(p))
                    .unwrap_or((0, [1.0, 0.0, 0.0], MATCH_MAX_DM));
            let weight = (1.0 - smoothstep(MATCH_FULL_DM, MATCH_MAX_DM, d))
                * smoothstep(neck_end, mh_mid[1] - NECK_START_DM, p[1]);
            let (side, near) = if dist(p, mh_eyes[0]) <= dist(p, mh_eyes[1]) {
                (0, dist(p, mh_eyes[0]))
            } else {
                (1, dist(p, mh_eyes[1]))
            };
            let follow = 1.0 - smoothstep(EYE_INNER_DM, EYE_OUTER_DM, near);
            if weight > 1e-3 || follow > 0.0 {
                matches.push(Match {
                    vertex: v,
                    triangle: model.skin[t as usize],
                    barycentric: bary,
                    weight,
                    eye: (follow > 0.0).then_some((side, follow)),
                });
            }
        }
        let eye_means = model
            .modes
            .iter()
            .map(|m| [0, 1].map(|s| mean(m, &model.eyes[s])))
            .collect();
        let mouth_means = model.modes.iter().map(|m| mean(m, &model.mouth)).collect();
        Ok(IctFace {
            model,
            matches,
            eyes,
            mouth,
            eye_means,
            mouth_means,
            scale,
        })
    }

    /// How many identity modes the model has.
    pub fn modes(&self) -> usize {
        self.model.modes.len()
    }

    /// The displacement (decimetres) of each base-mesh vertex the coefficients move, in vertex
    /// order of matches, then eyes, then mouth. More coefficients than modes is an error.
    pub fn offsets(&self, coefficients: &[f64]) -> Result<Vec<(u32, [f32; 3])>, String> {
        if coefficients.len() > self.modes() {
            return Err(format!(
                "{} ICT coefficients for a model of {} identity modes",
                coefficients.len(),
                self.modes()
            ));
        }
        let used: Vec<(usize, f32)> = coefficients
            .iter()
            .enumerate()
            .filter(|(_, c)| **c != 0.0)
            .map(|(m, &c)| (m, c as f32))
            .collect();
        let rigid = |means: &dyn Fn(usize) -> [f32; 3]| {
            let mut d = [0.0f32; 3];
            for &(mode, c) in &used {
                let f = means(mode);
                for k in 0..3 {
                    d[k] += c * f[k];
                }
            }
            d.map(|x| x * self.scale)
        };
        let eyes = [0, 1].map(|side| rigid(&|mode| self.eye_means[mode][side]));
        let mut out = Vec::with_capacity(self.matches.len() + 2000);
        for m in &self.matches {
            let mut d = [0.0f32; 3];
            for &(mode, c) in &used {
                let field = &self.model.modes[mode];
                for (j, &b) in m.triangle.iter().zip(&m.barycentric) {
                    let f = field[*j as usize];
                    for k in 0..3 {
                        d[k] += c * b * f[k];
                    }
                }
            }
            let mut d = d.map(|x| x * self.scale * m.weight);
            if let Some((side, follow)) = m.eye {
                for k in 0..3 {
                    d[k] += follow * (eyes[side][k] - d[k]);
                }
            }
            out.push((m.vertex, d));
        }
        for (vertices, d) in self.eyes.iter().zip(eyes) {
            out.extend(vertices.iter().map(|&v| (v, d)));
        }
        let d = rigid(&|mode| self.mouth_means[mode]);
        out.extend(self.mouth.iter().map(|&v| (v, d)));
        Ok(out)
    }
}
