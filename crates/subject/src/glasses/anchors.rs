//! Glasses: the anchors of a glasses model, found from its geometry alone (see the parent module).

#[allow(unused_imports)]
use super::*;

// ---------------------------------------------------------------------------------------------
// Anchors
// ---------------------------------------------------------------------------------------------

/// Temples are what lies behind this fraction of the model's depth; nose pads and hinges do not.
const TEMPLE_DEPTH_FRACTION: f32 = 0.3;
/// Depth bins of the temple profile the ear bend is found on.
const TEMPLE_BINS: usize = 48;
/// A temple whose profile rises less than this fraction of its length above the chord from its
/// front to its end has no ear bend worth the name; its rearmost part is the rest point.
const EAR_BEND_MIN_RISE: f32 = 0.04;

fn asset_error(reason: impl Into<String>) -> SubjectError {
    SubjectError::Asset {
        asset: "glasses model".to_string(),
        reason: reason.into(),
    }
}

/// Which materials are lenses: the transmissive ones, narrowed to those named "lens" when
/// transmissive nose pads also exist (the Khronos sunglasses have them), or by name alone when a
/// file carries no transmission.
pub(super) fn lens_materials(scene: &Scene) -> Vec<bool> {
    let named = |m: &Material| m.name.to_ascii_lowercase().contains("lens");
    let transmissive: Vec<bool> = scene
        .materials
        .iter()
        .map(|m| m.transmission > 0.0)
        .collect();
    let both: Vec<bool> = scene
        .materials
        .iter()
        .map(|m| m.transmission > 0.0 && named(m))
        .collect();
    if both.iter().any(|&b| b) {
        both
    } else if transmissive.iter().any(|&b| b) {
        transmissive
    } else {
        scene.materials.iter().map(named).collect()
    }
}

/// Finds a model's anchors from its geometry: the lens triangles (see [`lens_materials`]), the
/// lens plane (least-variance axis of the lens surface), the temples (what lies far behind it),
/// and +Y only to tell up from down (glTF's convention; −Y-up files would come out upside down
/// and left-right mirrored, Z-up files are detected).
pub fn glasses_anchors(scene: &Scene) -> Result<GlassesAnchors, SubjectError> {
    let is_lens = lens_materials(scene);
    let mut lens: Vec<[Vec3; 3]> = Vec::new();
    let mut other: Vec<[Vec3; 3]> = Vec::new();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        let world: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| inst.transform.transform_point3(Vec3::from(*p)))
            .collect();
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let corner = |k: usize| world.get(tri[k] as usize).copied();
            let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
                return Err(asset_error(format!(
                    "mesh '{}' has a vertex index out of range",
                    mesh.name
                )));
            };
            let material = mesh.triangle_materials.get(t).copied().unwrap_or(u32::MAX);
            if is_lens.get(material as usize).copied().unwrap_or(false) {
                lens.push([a, b, c]);
            } else {
                other.push([a, b, c]);
            }
        }
    }
    if lens.is_empty() {
        return Err(asset_error(
            "no lens triangles: no material has KHR_materials_transmission > 0 or a name \
             containing \"lens\"",
        ));
    }
    if other.is_empty() {
        return Err(asset_error(
            "no frame or temple triangles besides the lenses, so the temples cannot be found",
        ));
    }
    let stats =
        SurfaceStats::of(&lens).ok_or_else(|| asset_error("the lens triangles have no area"))?;
    let centre = stats.centroid;
    let normal = stats.least_variance_axis();

    // The temples reach far behind the lenses; the frame front hardly at all in front.
    let (lo, hi) = other
        .iter()
        .flatten()
        .map(|p| (*p - centre).dot(normal))
        .fold((0.0f32, 0.0f32), |(lo, hi), d| (lo.min(d), hi.max(d)));
    let forward = if -lo > hi { normal } else { -normal };

    let hint = if Vec3::Y.dot(forward).abs() < 0.9 {
        Vec3::Y
    } else {
        // A Z-up file looks along ±Y; +Z is then its up.
        Vec3::Z
    };
    let up0 = (hint - forward * hint.dot(forward)).normalize();
    let left0 = up0.cross(forward);
    let (l, r) = split_centroids(&lens, centre, left0)
        .ok_or_else(|| asset_error("all lens triangles lie on one side; need two lenses"))?;
    let across = (l - r) - forward * (l - r).dot(forward);
    let left = across.try_normalize().unwrap_or(left0);
    let up = forward.cross(left);
    // Split again across the refined axis so a tilted model is halved where its lenses are.
    let (lens_left, lens_right) = split_centroids(&lens, centre, left).unwrap_or((l, r));

    let frame = Frame {
        origin: (lens_left + lens_right) * 0.5,
        left,
        up,
        forward,
    };
    let local: Vec<[Vec3; 3]> = other.iter().map(|t| t.map(|p| frame.coords(p))).collect();
    let max_depth = local.iter().flatten().map(|c| c.z).fold(0.0f32, f32::max);
    let temple: Vec<[Vec3; 3]> = local
        .into_iter()
        .filter(|t| t.iter().all(|c| c.z > TEMPLE_DEPTH_FRACTION * max_depth))
        .collect();
    let ear_left = ear_point(&temple, 1.0)
        .ok_or_else(|| asset_error("no temple reaches back on the wearer's left"))?;
    let ear_right = ear_point(&temple, -1.0)
        .ok_or_else(|| asset_error("no temple reaches back on the wearer's right"))?;
    Ok(GlassesAnchors {
        lens_left,
        lens_right,
        ear_left: frame.point(ear_left),
        ear_right: frame.point(ear_right),
        forward,
        up,
    })
}

/// Orthonormal axes at the lens centre: coordinates are (lateral, height, depth behind).
struct Frame {
    origin: Vec3,
    left: Vec3,
    up: Vec3,
    forward: Vec3,
}

impl Frame {
    fn coords(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.left), d.dot(self.up), -d.dot(self.forward))
    }

    fn point(&self, c: Vec3) -> Vec3 {
        self.origin + self.left * c.x + self.up * c.y - self.forward * c.z
    }
}

/// The rest point of one temple (`side` +1 = left) in frame coordinates. The temple's top and
/// bottom outlines are traced per depth bin from points along its triangle edges (vertices
/// alone would leave bins holding only half a cross-section); the rest point is the middle of
/// the bin whose top rises most above the chord from the temple's front to its end, i.e. where
/// it bends down around the ear, or of the rearmost bin when the temple is straight.
fn ear_point(temple: &[[Vec3; 3]], side: f32) -> Option<Vec3> {
    let tris: Vec<&[Vec3; 3]> = temple
        .iter()
        .filter(|t| t.iter().all(|c| c.x * side > 0.0))
        .collect();
    let (lo, hi) = tris
        .iter()
        .flat_map(|t| t.iter())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), c| {
            (lo.min(c.z), hi.max(c.z))
        });
    if tris.is_empty() {
        return None;
    }
    let width = ((hi - lo) / TEMPLE_BINS as f32).max(1e-6);
    // Per bin: lowest and highest height, lowest and highest lateral offset.
    let mut bins = vec![
        [
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY
        ];
        TEMPLE_BINS
    ];
    for t in &tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let steps =
                (((b.z - a.z).abs() / (0.5 * width)).ceil() as usize).clamp(1, 4 * TEMPLE_BINS);
            for i in 0..=steps {
                let c = a + (b - a) * (i as f32 / steps as f32);
                let bin = (((c.z - lo) / width) as usize).min(TEMPLE_BINS - 1);
                let e = &mut bins[bin];
                *e = [e[0].min(c.y), e[1].max(c.y), e[2].min(c.x), e[3].max(c.x)];
            }
        }
    }
    // (depth, top, middle point) of each bin that holds part of the temple.
    let profile: Vec<(f32, f32, Vec3)> = bins
        .iter()
        .enumerate()
        .filter(|(_, e)| e[0] <= e[1])
        .map(|(i, e)| {
            let depth = lo + (i as f32 + 0.5) * width;
            (
                depth,
                e[1],
                Vec3::new(0.5 * (e[2] + e[3]), 0.5 * (e[0] + e[1]), depth),
            )
        })
        .collect();
    let (first, last) = (*profile.first()?, *profile.last()?);
    let length = last.0 - first.0;
    if length <= 0.0 {
        return Some(last.2);
    }
    let rise =
        |b: &(f32, f32, Vec3)| b.1 - (first.1 + (last.1 - first.1) * (b.0 - first.0) / length);
    let knee = profile
        .iter()
        .max_by(|a, b| rise(a).total_cmp(&rise(b)))
        .copied()
        .unwrap_or(last);
    Some(if rise(&knee) > EAR_BEND_MIN_RISE * length {
        knee.2
    } else {
        last.2
    })
}

/// Area-weighted centroids of the triangles on the +`axis` and −`axis` sides of `centre`.
fn split_centroids(tris: &[[Vec3; 3]], centre: Vec3, axis: Vec3) -> Option<(Vec3, Vec3)> {
    let mut sums = [(Vec3::ZERO, 0.0f32); 2];
    for t in tris {
        let g = (t[0] + t[1] + t[2]) / 3.0;
        let area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        let k = usize::from((g - centre).dot(axis) < 0.0);
        sums[k].0 += g * area;
        sums[k].1 += area;
    }
    let [(pl, al), (pr, ar)] = sums;
    (al > 0.0 && ar > 0.0).then(|| (pl / al, pr / ar))
}

/// Area moments of a triangle set.
struct SurfaceStats {
    centroid: Vec3,
    /// Covariance of the surface about its centroid (per unit area).
    covariance: [[f64; 3]; 3],
}

impl SurfaceStats {
    fn of(tris: &[[Vec3; 3]]) -> Option<SurfaceStats> {
        // Moments about the first vertex keep f64 sums well conditioned far from the origin.
        let origin = tris.first()?[0].as_dvec3();
        let mut area = 0.0f64;
        let mut first = DVec3::ZERO;
        let mut second = [[0.0f64; 3]; 3];
        for t in tris {
            let [a, b, c] = t.map(|v| v.as_dvec3() - origin);
            let w = 0.5 * (b - a).cross(c - a).length();
            let s = a + b + c;
            area += w;
            first += s * (w / 3.0);
            // Exact second moment of a triangle: A/12 (a aᵀ + b bᵀ + c cᵀ + s sᵀ).
            for (i, row) in second.iter_mut().enumerate() {
                for (j, m) in row.iter_mut().enumerate() {
                    *m += w / 12.0 * (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + s[i] * s[j]);
                }
            }
        }
        if area.is_nan() || area <= 0.0 {
            return None;
        }
        let mean = first / area;
        let mut covariance = [[0.0; 3]; 3];
        for (i, row) in covariance.iter_mut().enumerate() {
            for (j, m) in row.iter_mut().enumerate() {
                *m = second[i][j] / area - mean[i] * mean[j];
            }
        }
        Some(SurfaceStats {
            centroid: (origin + mean).as_vec3(),
            covariance,
        })
    }

    /// Unit eigenvector of the smallest eigenvalue (the normal of a best-fit plane).
    fn least_variance_axis(&self) -> Vec3 {
        let (values, vectors) = symmetric_eigen(self.covariance);
        let k = (0..3)
            .min_by(|&a, &b| values[a].total_cmp(&values[b]))
            .unwrap_or(2);
        DVec3::new(vectors[0][k], vectors[1][k], vectors[2][k])
            .as_vec3()
            .normalize_or(Vec3::Z)
    }
}

/// Cyclic Jacobi eigen-decomposition of a symmetric 3×3 matrix: eigenvalues and the
/// eigenvectors as the columns of the second result.
fn symmetric_eigen(m: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2);
        if off <= 1e-30 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (rp, rq) = (row[p], row[q]);
                row[p] = c * rp - s * rq;
                row[q] = s * rp + c * rq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * row_p[k] - s * row_q[k]);
            a[q] = std::array::from_fn(|k| s * row_p[k] + c * row_q[k]);
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}
