//! VGG16 / LPIPS from user-supplied weights: loading (and refusing broken files), LPIPS against
//! a direct CPU computation of its definition, and the perceptual loss's gradients.
//! The weights are random (He-scaled), written here in torchvision's layout: the code under
//! test cannot tell them from ImageNet's, and no pretrained file is needed.

use std::collections::HashMap;
use std::path::Path;

use burn::prelude::*;
use lightfarm_nets::vgg::{TAP_CHANNELS, VGG16_CONVS};
use lightfarm_nets::{perceptual_loss, Lpips, Vgg16};
use safetensors::{Dtype, View};

struct Rng(u64);
impl Rng {
    /// Uniform in [0, 1).
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn symmetric(&mut self, scale: f32) -> f32 {
        (self.next() * 2.0 - 1.0) * scale
    }
}

struct Raw {
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

impl View for &Raw {
    fn dtype(&self) -> Dtype {
        Dtype::F32
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> std::borrow::Cow<'_, [u8]> {
        std::borrow::Cow::Borrowed(&self.bytes)
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

/// Random VGG16 features plus LPIPS heads: lin0 gets `lin0`, the other heads zero unless `all`.
fn weights(seed: u64, lin0: &[f32], all_heads: bool) -> HashMap<String, (Vec<usize>, Vec<f32>)> {
    let mut r = Rng(seed);
    let mut m = HashMap::new();
    for (i, cin, cout) in VGG16_CONVS {
        // He-uniform keeps activations of the same order through 13 layers.
        let bound = (6.0 / (9.0 * cin as f32)).sqrt();
        let w = (0..cout * cin * 9).map(|_| r.symmetric(bound)).collect();
        let b = (0..cout).map(|_| r.symmetric(0.05)).collect();
        m.insert(format!("features.{i}.weight"), (vec![cout, cin, 3, 3], w));
        m.insert(format!("features.{i}.bias"), (vec![cout], b));
    }
    for (k, c) in TAP_CHANNELS.into_iter().enumerate() {
        let w = if k == 0 {
            lin0.to_vec()
        } else if all_heads {
            (0..c).map(|_| r.next()).collect()
        } else {
            vec![0.0; c]
        };
        m.insert(format!("lin{k}.model.1.weight"), (vec![1, c, 1, 1], w));
    }
    m
}

fn write(path: &Path, tensors: &HashMap<String, (Vec<usize>, Vec<f32>)>) {
    let raw: Vec<(String, Raw)> = tensors
        .iter()
        .map(|(k, (shape, v))| {
            (
                k.clone(),
                Raw {
                    shape: shape.clone(),
                    bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                },
            )
        })
        .collect();
    let views: Vec<(&str, &Raw)> = raw.iter().map(|(k, r)| (k.as_str(), r)).collect();
    safetensors::serialize_to_file(views, None, path).unwrap();
}

fn image(seed: u64, size: usize) -> Vec<f32> {
    let mut r = Rng(seed);
    (0..3 * size * size).map(|_| r.next()).collect()
}

fn tensor(data: &[f32], size: usize, device: &Device) -> Tensor<4> {
    Tensor::from_data(TensorData::new(data.to_vec(), [1, 3, size, size]), device)
}

fn cpu() -> Device {
    lightfarm_nets::device::select("cpu").unwrap()
}

/// relu(conv3×3(x) + b) with zero padding, CHW.
fn conv_relu(x: &[f32], cin: usize, size: usize, w: &[f32], b: &[f32]) -> Vec<f32> {
    let cout = b.len();
    let mut out = vec![0f32; cout * size * size];
    for o in 0..cout {
        for y in 0..size {
            for xx in 0..size {
                let mut acc = b[o];
                for i in 0..cin {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let (sy, sx) =
                                (y as isize + ky as isize - 1, xx as isize + kx as isize - 1);
                            if sy < 0 || sx < 0 || sy >= size as isize || sx >= size as isize {
                                continue;
                            }
                            acc += w[((o * cin + i) * 3 + ky) * 3 + kx]
                                * x[(i * size + sy as usize) * size + sx as usize];
                        }
                    }
                }
                out[(o * size + y) * size + xx] = acc.max(0.0);
            }
        }
    }
    out
}

/// LPIPS restricted to its first tap (the other heads are zero), straight from the definition:
/// scale to [−1, 1], LPIPS's shift/scale, relu1_2, unit-normalise over channels, squared
/// difference weighted by lin0, mean over pixels.
fn lpips_first_tap(
    tensors: &HashMap<String, (Vec<usize>, Vec<f32>)>,
    a: &[f32],
    b: &[f32],
    size: usize,
) -> f64 {
    let shift = [-0.030f32, -0.088, -0.188];
    let scale = [0.458f32, 0.448, 0.450];
    let feats = |img: &[f32]| {
        let x: Vec<f32> = img
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let c = i / (size * size);
                (v * 2.0 - 1.0 - shift[c]) / scale[c]
            })
            .collect();
        let (w0, b0) = (
            &tensors["features.0.weight"].1,
            &tensors["features.0.bias"].1,
        );
        let (w2, b2) = (
            &tensors["features.2.weight"].1,
            &tensors["features.2.bias"].1,
        );
        let h = conv_relu(&x, 3, size, w0, b0);
        conv_relu(&h, 64, size, w2, b2)
    };
    let (fa, fb) = (feats(a), feats(b));
    let lin = &tensors["lin0.model.1.weight"].1;
    let px = size * size;
    let mut total = 0f64;
    for p in 0..px {
        let norm = |f: &[f32]| (0..64).map(|c| f[c * px + p].powi(2)).sum::<f32>().sqrt() + 1e-10;
        let (na, nb) = (norm(&fa), norm(&fb));
        for c in 0..64 {
            let d = fa[c * px + p] / na - fb[c * px + p] / nb;
            total += f64::from(lin[c] * d * d);
        }
    }
    total / px as f64
}

#[test]
fn lpips_matches_its_definition_on_the_first_tap() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lpips.safetensors");
    let mut r = Rng(5);
    let lin0: Vec<f32> = (0..64).map(|_| r.next()).collect();
    let w = weights(1, &lin0, false);
    write(&path, &w);
    let device = cpu();
    let lpips = Lpips::load(&path, &device).unwrap();
    let size = 16;
    let (a, b) = (image(2, size), image(3, size));
    let got = f64::from(
        lpips
            .distance(tensor(&a, size, &device), tensor(&b, size, &device))
            .into_scalar::<f32>(),
    );
    let want = lpips_first_tap(&w, &a, &b, size);
    assert!(want > 0.01, "the reference distance is degenerate: {want}");
    assert!(
        (got - want).abs() < 1e-4 * want.max(1.0),
        "LPIPS {got} vs the definition {want}"
    );
}

#[test]
fn lpips_is_a_distance_on_all_taps() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lpips.safetensors");
    write(&path, &weights(7, &[1.0; 64], true));
    let device = cpu();
    let lpips = Lpips::load(&path, &device).unwrap();
    let size = 32;
    let (a, b) = (image(8, size), image(9, size));
    let d = |x: &[f32], y: &[f32]| {
        lpips
            .distance(tensor(x, size, &device), tensor(y, size, &device))
            .into_scalar::<f32>()
    };
    assert!(d(&a, &a).abs() < 1e-6, "d(a, a) = {}", d(&a, &a));
    let ab = d(&a, &b);
    assert!(ab > 0.0, "d(a, b) = {ab}");
    assert!((ab - d(&b, &a)).abs() < 1e-5 * ab, "not symmetric");
    // A slightly perturbed image is nearer than an unrelated one.
    let near: Vec<f32> = a.iter().map(|v| (v + 0.02).min(1.0)).collect();
    assert!(d(&a, &near) < ab, "{} vs {ab}", d(&a, &near));
}

#[test]
fn perceptual_loss_is_zero_on_the_target_and_has_gradients() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg16.safetensors");
    write(&path, &weights(11, &[0.0; 64], false));
    let device = cpu().autodiff();
    let vgg = Vgg16::load(&path, &device).unwrap();
    let size = 32;
    let mask = Tensor::<4>::ones([1, 1, size, size], &device);
    let target = tensor(&image(12, size), size, &device).mul_scalar(3.0);
    let same = perceptual_loss(&vgg, target.clone(), target.clone(), mask.clone());
    assert!(same.into_scalar::<f32>().abs() < 1e-7);
    let pred = tensor(&image(13, size), size, &device)
        .mul_scalar(3.0)
        .require_grad();
    let loss = perceptual_loss(&vgg, pred.clone(), target, mask);
    assert!(loss.clone().into_scalar::<f32>() > 0.0);
    let grads = loss.backward();
    let g = pred.grad(&grads).expect("the prediction gets a gradient");
    let norm = g.abs().sum().into_scalar::<f32>();
    assert!(norm > 0.0 && norm.is_finite(), "gradient norm {norm}");
}

#[test]
fn broken_weight_files_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let device = cpu();
    let msg = |p: &Path| Lpips::load(p, &device).unwrap_err().to_string();

    let missing = dir.path().join("missing.safetensors");
    assert!(msg(&missing).contains("cannot read"), "{}", msg(&missing));

    let mut w = weights(1, &[1.0; 64], true);
    w.remove("features.10.weight");
    let p = dir.path().join("no-conv.safetensors");
    write(&p, &w);
    assert!(msg(&p).contains("features.10.weight"), "{}", msg(&p));

    let mut w = weights(1, &[1.0; 64], true);
    w.insert(
        "lin2.model.1.weight".into(),
        (vec![1, 128, 1, 1], vec![1.0; 128]),
    );
    let p = dir.path().join("bad-shape.safetensors");
    write(&p, &w);
    let m = msg(&p);
    assert!(
        m.contains("lin2.model.1.weight") && m.contains("shape"),
        "{m}"
    );

    // A VGG-only file serves the perceptual loss but not LPIPS.
    let mut w = weights(1, &[1.0; 64], true);
    w.retain(|k, _| k.starts_with("features."));
    let p = dir.path().join("vgg-only.safetensors");
    write(&p, &w);
    assert!(Vgg16::load(&p, &device).is_ok());
    assert!(msg(&p).contains("lin0.model.1.weight"), "{}", msg(&p));

    let bytes = std::fs::read(&p).unwrap();
    let p = dir.path().join("truncated.safetensors");
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    assert!(msg(&p).contains("not a safetensors file"), "{}", msg(&p));

    let p = dir.path().join("junk.safetensors");
    std::fs::write(&p, b"\xff\xff\xff\xff\xff\xff\xff\x7fjunk").unwrap();
    assert!(msg(&p).contains("not a safetensors file"), "{}", msg(&p));
}
