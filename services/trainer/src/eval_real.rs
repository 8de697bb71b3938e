//! `lightfarm eval --real FOLDER`: the real-photo metrics of section 5.2 / Table 4, where no
//! ground truth exists. Every photo of the folder is prepared as adaptation prepares it
//! (MODNet matte, square crop, dlib face alignment; photos without a face are skipped and
//! counted), relit by each model under catalog HDRIs at rotations drawn from (seed, photo), and
//! scored on:
//! - **lighting recovery** (section 5.2): second-order SH irradiance fitted to the relit image
//!   from the predicted albedo and normals on the face's skin, a diffuse sphere under it
//!   against one under the target HDRI (exposure matched, relative L1). The paper takes skin
//!   from a BiSeNet face parser, which is not available offline; here it is MediaPipe's face
//!   mesh fitted to the face dlib found: the face oval minus eyes, eyebrows and lips, within
//!   the matte;
//! - **identity**: cosine similarity (the paper's ↑ score) and dlib's Euclidean distance
//!   between the descriptors of the photo and of its relighting on the photo's aligned face
//!   chip (exposure-normalised, so a brighter lighting is not another person), and the share
//!   under dlib's same-person threshold 0.6;
//! - **realism**: FD-VGG and KID between the relit images and the photos, on VGG16 relu5_3
//!   features averaged over the image. There is no InceptionV3 offline, so these are not
//!   comparable to published FID/KID numbers, only between models;
//! - **OLAT consistency**: ‖(R̄_a + R̄_b) − R̄_{a+b}‖₁ / ‖R̄_{a+b}‖₁ over the subject for two
//!   OLAT lights of the 168-light stage, a linearity a physically plausible relighting has.

use std::path::PathBuf;
use std::sync::Arc;

use burn::prelude::*;
use lightfarm_face::{
    builtin_face_net, descriptor_distance, descriptor_similarity, descriptors, identity_display,
    skin, Alignment, FaceMesh, FaceNet, Image, LazyFaces, SAME_PERSON_DISTANCE,
};
use lightfarm_light::{OlatBasis, PrefilteredEnv, OLAT_DISC_DEG};
use lightfarm_nets::metrics::{fit_sh_irradiance, sphere_error, srgb_encode, Planar};
use lightfarm_nets::Vgg16;
use lightfarm_photo::LazyMatting;
use lightfarm_scene::{AssetKind, Catalog};
use nalgebra::DMatrix;
use serde::Serialize;

use crate::adapt::photos::{PhotoSet, Prepared};
use crate::data::mix;
use crate::eval::{model_column, planar};
use crate::infer::load_model;
use crate::lights::{identity_camera, Lighting};
use crate::TrainError;

#[derive(Clone, Debug, Serialize)]
pub struct RealEvalRow {
    pub model: String,
    pub photos: usize,
    /// Relit images per photo.
    pub lightings: usize,
    /// Section 5.2's SH lighting-recovery error on the face's skin (mean over relit images
    /// where the fit succeeds).
    pub lighting: Option<f64>,
    /// Mean cosine similarity of the dlib descriptors, photo vs relit.
    pub identity: f64,
    /// Mean dlib descriptor distance, photo vs relit.
    pub identity_distance: f64,
    /// Share of relit images dlib takes for the same person (distance < 0.6).
    pub identity_kept: f64,
    pub fd_vgg: f64,
    pub kid: f64,
    pub olat_consistency: f64,
}

/// What to evaluate on.
pub struct RealEvalOptions {
    pub photos: PathBuf,
    /// Where prepared photos are cached between runs.
    pub cache: PathBuf,
    /// Side of the square the photos are prepared at.
    pub size: usize,
    /// HDRI relightings per photo.
    pub lightings: usize,
    pub seed: u64,
    pub vgg: PathBuf,
    pub device: String,
}

/// ImageNet statistics of torchvision's VGG.
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// relu5_3 averaged over the image: [B, 512].
fn vgg_features(vgg: &Vgg16, display: Tensor<4>) -> Vec<Vec<f64>> {
    let device = display.device();
    let mean = Tensor::<1>::from_floats(IMAGENET_MEAN, &device).reshape([1, 3, 1, 1]);
    let std = Tensor::<1>::from_floats(IMAGENET_STD, &device).reshape([1, 3, 1, 1]);
    let x = (display.div_scalar(255.0) - mean) / std;
    let Some(last) = vgg.features(x).pop() else {
        return Vec::new();
    };
    let [b, c, _, _] = last.dims();
    let v: Vec<f32> = last
        .mean_dim(3)
        .mean_dim(2)
        .reshape([b * c])
        .into_data()
        .try_to_vec::<f32>()
        .unwrap_or_default();
    v.chunks_exact(c)
        .map(|r| r.iter().map(|&x| f64::from(x)).collect())
        .collect()
}

fn mean_cov(x: &[Vec<f64>]) -> (Vec<f64>, DMatrix<f64>) {
    let (n, d) = (x.len(), x.first().map_or(0, Vec::len));
    let mut mean = vec![0.0; d];
    for r in x {
        for (m, v) in mean.iter_mut().zip(r) {
            *m += v / n as f64;
        }
    }
    let centred = DMatrix::from_fn(n, d, |i, j| x[i][j] - mean[j]);
    let cov = centred.transpose() * &centred / (n.max(2) - 1) as f64;
    (mean, cov)
}

/// Square root of a symmetric positive semi-definite matrix (negative round-off clipped).
fn sqrt_psd(m: DMatrix<f64>) -> DMatrix<f64> {
    let e = m.symmetric_eigen();
    let d = DMatrix::from_diagonal(&e.eigenvalues.map(|v| v.max(0.0).sqrt()));
    &e.eigenvectors * d * e.eigenvectors.transpose()
}

/// Fréchet distance of two feature sets' Gaussians (the FID formula on other features).
pub fn frechet_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let (ma, ca) = mean_cov(a);
    let (mb, cb) = mean_cov(b);
    let diff: f64 = ma.iter().zip(&mb).map(|(x, y)| (x - y).powi(2)).sum();
    let sa = sqrt_psd(ca.clone());
    let inner = &sa * &cb * &sa;
    let cross: f64 = inner
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .map(|v| v.max(0.0).sqrt())
        .sum();
    diff + ca.trace() + cb.trace() - 2.0 * cross
}

/// Kernel inception distance's estimator on other features: the unbiased MMD² with the cubic
/// polynomial kernel (x·y/d + 1)³.
pub fn kernel_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let d = a.first().map_or(1, Vec::len) as f64;
    let k =
        |x: &[f64], y: &[f64]| (x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>() / d + 1.0).powi(3);
    let within = |s: &[Vec<f64>]| {
        let n = s.len();
        if n < 2 {
            return 0.0;
        }
        let mut t = 0.0;
        for i in 0..n {
            for j in 0..n {
                if i != j {
                    t += k(&s[i], &s[j]);
                }
            }
        }
        t / (n * (n - 1)) as f64
    };
    let mut across = 0.0;
    for x in a {
        for y in b {
            across += k(x, y);
        }
    }
    within(a) + within(b) - 2.0 * across / (a.len() * b.len()).max(1) as f64
}

/// Skin for the lighting fit: the face mesh's oval minus eyes, eyebrows and lips (see
/// `lightfarm_face::skin`), within the matte. The mesh is fitted on the prepared image from
/// dlib's face; None when the mesh network does not see a face there.
fn skin_mask(mesh_net: &FaceMesh, p: &Prepared, face: &Alignment, size: usize) -> Option<Planar> {
    let rgb: Vec<u8> = p
        .rgb
        .iter()
        .flat_map(|c| c.map(|v| (srgb_encode(v).clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
        .collect();
    let image = Image::new(&rgb, size, size).ok()?;
    let mesh = mesh_net.fit(&image, face);
    if mesh.presence < MIN_MESH_PRESENCE {
        return None;
    }
    let data = skin::skin_mask(&mesh, size, size)
        .into_iter()
        .zip(&p.mask)
        .map(|(s, &m)| if m > 0.5 { s } else { 0.0 })
        .collect();
    Some(Planar {
        width: size,
        height: size,
        channels: 1,
        data,
    })
}

/// Below this face-presence probability the mesh is not trusted for a skin mask.
const MIN_MESH_PRESENCE: f32 = 0.5;

fn to_tensor(rgb: &[[f32; 3]], size: usize, device: &Device) -> Tensor<4> {
    let mut v = vec![0f32; 3 * size * size];
    for (i, c) in rgb.iter().enumerate() {
        for ch in 0..3 {
            v[ch * size * size + i] = c[ch];
        }
    }
    Tensor::<4>::from_data(TensorData::new(v, [1, 3, size, size]), device)
}

/// Scores `models` on the real photos of `opts.photos`; also returns how many photos were
/// skipped (each is named in the log with the reason).
pub fn evaluate_real(
    models: &[PathBuf],
    opts: &RealEvalOptions,
    catalog: Catalog,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Vec<RealEvalRow>, usize), TrainError> {
    let device = lightfarm_nets::device::select(&opts.device)
        .map_err(|e| TrainError::Config(e.to_string()))?;
    let loaded = models
        .iter()
        .map(|m| load_model(m, &opts.device))
        .collect::<Result<Vec<_>, _>>()?;
    let face_net = FaceNet::load(&builtin_face_net(), &device)
        .map_err(|e| TrainError::Config(format!("identity metric: {e}")))?;
    let mesh_net = FaceMesh::builtin(&device)
        .map_err(|e| TrainError::Config(format!("skin mask of the lighting metric: {e}")))?;
    let vgg = Vgg16::load(&opts.vgg, &device)
        .map_err(|e| TrainError::Config(format!("FD-VGG and KID: {e}")))?;
    let photos = PhotoSet::open(
        &opts.photos,
        &opts.cache,
        opts.size,
        LazyMatting::builtin(),
        Some(Arc::new(LazyFaces::builtin(device.clone()))),
    )?;
    let hdris: Vec<String> = catalog
        .of_kind(AssetKind::Hdri)
        .into_iter()
        .map(|a| a.id.clone())
        .collect();
    if hdris.is_empty() {
        return Err(TrainError::Config(
            "the asset catalog has no HDRIs to relight with".into(),
        ));
    }
    let mut lightings: Vec<Option<Arc<Lighting>>> = vec![None; hdris.len()];
    let basis = OlatBasis::new(168, OLAT_DISC_DEG, 512, 256)
        .map_err(|e| TrainError::Config(format!("OLAT basis: {e}")))?;
    let size = opts.size;
    let mut real_features = Vec::new();
    let mut relit_features = vec![Vec::new(); loaded.len()];
    // Per model: identity distance, same-person count, OLAT error, cosine, lighting error.
    let mut sums = vec![[0f64; 5]; loaded.len()];
    let mut lighting_fits = vec![0usize; loaded.len()];
    let mut used = 0usize;
    for i in 0..photos.len() {
        progress(i, photos.len());
        let Some(p) = photos.get(i)? else { continue };
        let Some(face) = p.face.clone() else { continue };
        used += 1;
        let masked: Vec<[f32; 3]> = p
            .rgb
            .iter()
            .zip(&p.mask)
            .map(|(c, &m)| c.map(|v| v * m))
            .collect();
        let input = to_tensor(&masked, size, &device);
        let mask =
            Tensor::<4>::from_data(TensorData::new(p.mask.clone(), [1, 1, size, size]), &device);
        let real_display = identity_display(input.clone(), mask.clone());
        let skin = skin_mask(&mesh_net, &p, &face, size);
        if skin.is_none() {
            tracing::warn!(
                photo = i,
                "the face mesh sees no face in the prepared photo; it gets no lighting-recovery score"
            );
        }
        let faces = [face];
        let real_desc = descriptors(&face_net, real_display.clone(), &faces);
        real_features.extend(vgg_features(&vgg, real_display * mask.clone()));
        let r = |k: u64| mix(mix(opts.seed, i as u64), k);
        let front = identity_camera(0.0, false);
        // Two OLAT lights and their sum, each scaled like the adaptation's (mean radiance 1).
        let n = basis.len() as u64;
        let a = (r(100) % n) as usize;
        let b = (a + 1 + (r(101) % (n - 1)) as usize) % n as usize;
        let (ea, eb) = (
            PrefilteredEnv::compute(&basis.map(a)),
            PrefilteredEnv::compute(&basis.map(b)),
        );
        let eab = ea
            .sum(&eb)
            .ok_or_else(|| TrainError::Config("OLAT maps of different sizes".into()))?;
        let olat = [ea, eb, eab].map(|env| Lighting {
            env,
            scale: n as f32,
        });
        for (k, model) in loaded.iter().enumerate() {
            for j in 0..opts.lightings {
                let h = (r(j as u64) % hdris.len() as u64) as usize;
                if lightings[h].is_none() {
                    let asset = catalog.get(&hdris[h]).ok_or_else(|| {
                        TrainError::Config(format!("HDRI '{}' left the catalog", hdris[h]))
                    })?;
                    lightings[h] = Some(Arc::new(Lighting::load(&catalog.path_of(asset))?));
                }
                let Some(l) = lightings[h].clone() else {
                    continue;
                };
                let rot = identity_camera((r(50 + j as u64) % 360) as f32, false);
                let out = model.relight(&masked, &p.mask, size, size, &l, rot)?;
                let display = identity_display(to_tensor(&out.relit, size, &device), mask.clone());
                let desc = descriptors(&face_net, display.clone(), &faces);
                let d = descriptor_distance(real_desc.clone(), desc.clone()).into_scalar::<f32>();
                let cos = descriptor_similarity(real_desc.clone(), desc);
                sums[k][0] += f64::from(d);
                sums[k][1] += f64::from(u8::from(d < SAME_PERSON_DISTANCE));
                sums[k][3] += f64::from(cos.into_scalar::<f32>());
                let fit = skin.as_ref().and_then(|skin| {
                    fit_sh_irradiance(
                        &planar(&out.relit, size, size),
                        &planar(&out.albedo, size, size),
                        &planar(&out.normal, size, size),
                        skin,
                    )
                });
                if let Some(est) = fit {
                    let mul = |n: [f32; 3]| {
                        [0, 1, 2].map(|i| rot[i][0] * n[0] + rot[i][1] * n[1] + rot[i][2] * n[2])
                    };
                    sums[k][4] +=
                        sphere_error(&est, |n| l.env.sh.irradiance(mul(n)).map(|v| v * l.scale));
                    lighting_fits[k] += 1;
                }
                relit_features[k].extend(vgg_features(&vgg, display * mask.clone()));
            }
            let rel = olat
                .iter()
                .map(|l| {
                    model
                        .relight(&masked, &p.mask, size, size, l, front)
                        .map(|o| o.relit)
                })
                .collect::<Result<Vec<_>, _>>()?;
            let (mut err, mut norm) = (0f64, 0f64);
            for (px, &m) in p.mask.iter().enumerate() {
                let (a, b, both) = (rel[0][px], rel[1][px], rel[2][px]);
                for c in 0..3 {
                    err += f64::from(m * (a[c] + b[c] - both[c]).abs());
                    norm += f64::from(m * both[c].abs());
                }
            }
            sums[k][2] += err / norm.max(1e-12);
        }
    }
    progress(photos.len(), photos.len());
    if used == 0 {
        return Err(TrainError::Input(format!(
            "photos = {}: none of its {} photos shows a usable face (each is named in the log with the reason)",
            opts.photos.display(),
            photos.len()
        )));
    }
    let relit_n = (used * opts.lightings) as f64;
    let rows = loaded
        .iter()
        .enumerate()
        .map(|(k, _)| RealEvalRow {
            model: models[k].display().to_string(),
            photos: used,
            lightings: opts.lightings,
            lighting: (lighting_fits[k] > 0).then(|| sums[k][4] / lighting_fits[k] as f64),
            identity: sums[k][3] / relit_n,
            identity_distance: sums[k][0] / relit_n,
            identity_kept: sums[k][1] / relit_n,
            fd_vgg: frechet_distance(&real_features, &relit_features[k]),
            kid: kernel_distance(&real_features, &relit_features[k]),
            olat_consistency: sums[k][2] / used as f64,
        })
        .collect();
    Ok((rows, photos.skipped()))
}

/// The rows as an aligned text table.
pub fn real_table(rows: &[RealEvalRow]) -> String {
    let mut out = format!(
        "{:<40} {:>6} {:>6} {:>9} {:>9} {:>9} {:>8} {:>9} {:>8} {:>10}\n",
        "model",
        "photos",
        "relit",
        "lighting",
        "identity",
        "id dist",
        "same %",
        "FD-VGG",
        "KID",
        "OLAT cons"
    );
    for r in rows {
        let name = model_column(&r.model);
        out.push_str(&format!(
            "{:<40} {:>6} {:>6} {:>9} {:>9.4} {:>9.4} {:>8.1} {:>9.3} {:>8.4} {:>10.4}\n",
            name,
            r.photos,
            r.photos * r.lightings,
            r.lighting.map_or("-".to_owned(), |e| format!("{e:.4}")),
            r.identity,
            r.identity_distance,
            r.identity_kept * 100.0,
            r.fd_vgg,
            r.kid,
            r.olat_consistency
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(seed: u64, n: usize, d: usize, shift: f64) -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| {
                (0..d)
                    .map(|j| {
                        (mix(mix(seed, i as u64), j as u64) % 10_000) as f64 / 10_000.0 + shift
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn distances_of_feature_sets() {
        let a = set(1, 200, 4, 0.0);
        let b = set(2, 200, 4, 0.0);
        let far = set(3, 200, 4, 1.0);
        // Same distribution: near 0 (KID unbiased around 0); a shift of 1 in every one of 4
        // dimensions: FD about 4.
        assert!(frechet_distance(&a, &a).abs() < 1e-9);
        assert!(
            frechet_distance(&a, &b) < 0.05,
            "{}",
            frechet_distance(&a, &b)
        );
        let fd = frechet_distance(&a, &far);
        assert!((fd - 4.0).abs() < 0.2, "{fd}");
        assert!(kernel_distance(&a, &b).abs() < 0.05);
        assert!(kernel_distance(&a, &far) > 10.0 * kernel_distance(&a, &b).abs());
    }
}
