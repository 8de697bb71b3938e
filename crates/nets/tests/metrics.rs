//! Known answers for the host metrics that `lightfarm eval` (services/trainer/src/eval.rs) and
//! the trainer's overfit test judge models by: MAE/MSE on hand-computed images, SSIM's
//! identities and closed form, the sRGB transfer at its defining points, and SH lighting
//! recovery from an image rendered with known coefficients.

use lightfarm_light::sh9_basis;
use lightfarm_nets::metrics::{
    fit_sh_irradiance, mae, mse, sphere_error, srgb_encode, ssim, Planar,
};

fn planar(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Planar {
    assert_eq!(data.len(), width * height * channels, "test image size");
    Planar {
        width,
        height,
        channels,
        data,
    }
}

/// A deterministic, textured value in [0, 1) (an LCG, so the test needs no RNG crate).
fn texture(width: usize, height: usize, channels: usize, seed: u64) -> Planar {
    let mut state = seed;
    let data = (0..width * height * channels)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect();
    planar(width, height, channels, data)
}

fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tolerance {tol})");
}

#[test]
fn planar_is_channel_major_rows_then_columns() {
    // 3 wide, 2 high, 2 channels: value = 100c + 10y + x, laid out as the doc comment says.
    let data = (0..2)
        .flat_map(|c| (0..2).flat_map(move |y| (0..3).map(move |x| (100 * c + 10 * y + x) as f32)))
        .collect();
    let p = planar(3, 2, 2, data);
    assert_eq!(p.pixels(), 6);
    for c in 0..2 {
        for y in 0..2 {
            for x in 0..3 {
                assert_eq!(
                    p.at(c, x, y),
                    (100 * c + 10 * y + x) as f32,
                    "({c}, {x}, {y})"
                );
            }
        }
    }
}

/// eval scores MAE/MSE over every value of the display image, background included: a
/// background that is black in both images adds nothing to the sum but counts in the mean, so
/// the mean is over all pixels, not over the subject's.
#[test]
fn mae_and_mse_are_means_over_the_whole_image() {
    // 2×2, one channel; the bottom row is background (mask 0), black in both.
    let a = planar(2, 2, 1, vec![0.2, 0.4, 0.0, 0.0]);
    let b = planar(2, 2, 1, vec![0.1, 0.7, 0.0, 0.0]);
    // |0.2 - 0.1| + |0.4 - 0.7| = 0.4 over 4 pixels (0.2 if only the subject counted).
    close(mae(&a, &b), 0.1, 1e-6, "MAE");
    // 0.1² + 0.3² = 0.1 over 4 pixels.
    close(mse(&a, &b), 0.025, 1e-6, "MSE");
    close(mae(&b, &a), 0.1, 1e-6, "MAE is symmetric");

    // 2×1, three channels, values exact in binary so the answers are exact: the pixel at
    // x = 1 is black background in both.
    //            R          G           B
    let a = planar(2, 1, 3, vec![0.5, 0.0, 0.25, 0.0, 1.0, 0.0]);
    let b = planar(2, 1, 3, vec![0.25, 0.0, 0.5, 0.0, 0.5, 0.0]);
    // Differences 0.25, 0.25, 0.5 over 6 values.
    assert_eq!(mae(&a, &b), 1.0 / 6.0);
    // 0.0625 + 0.0625 + 0.25 = 0.375 over 6 values.
    assert_eq!(mse(&a, &b), 0.0625);

    let same = texture(7, 5, 3, 1);
    assert_eq!(mae(&same, &same), 0.0);
    assert_eq!(mse(&same, &same), 0.0);
}

#[test]
fn ssim_of_an_image_with_itself_is_one() {
    let x = texture(32, 24, 3, 7);
    // Every window's numerator and denominator are the same products in the same order.
    close(ssim(&x, &x), 1.0, 1e-12, "SSIM(x, x)");
}

/// With both images constant every window's variances and covariance vanish, and SSIM is its
/// luminance term alone: (2ab + C1) / (a² + b² + C1) with C1 = 0.01².
#[test]
fn ssim_of_two_constant_images_is_the_luminance_term() {
    let (a, b) = (0.3f32, 0.5f32);
    let x = planar(16, 16, 1, vec![a; 256]);
    let y = planar(16, 16, 1, vec![b; 256]);
    let (a, b) = (f64::from(a), f64::from(b));
    let c1 = 1e-4;
    let expected = (2.0 * a * b + c1) / (a * a + b * b + c1);
    // 0.3001 / 0.3401, by hand.
    close(expected, 0.882_387_5, 1e-6, "closed form");
    // Σw of the Gaussian window is 1 only to rounding, so the window variances are ~1e-17,
    // against C2 = 9e-4.
    close(ssim(&x, &y), expected, 1e-9, "SSIM of constants");
    close(ssim(&x, &x), 1.0, 1e-12, "SSIM of a constant with itself");
}

#[test]
fn ssim_drops_for_a_noisy_copy_and_is_symmetric() {
    let x = texture(32, 32, 3, 11);
    let noise = texture(32, 32, 3, 12);
    let noisy = |amount: f32| Planar {
        data: x
            .data
            .iter()
            .zip(&noise.data)
            .map(|(v, n)| v + amount * (n - 0.5))
            .collect(),
        ..x.clone()
    };
    let (light, heavy) = (noisy(0.1), noisy(0.5));
    let (s_light, s_heavy) = (ssim(&x, &light), ssim(&x, &heavy));
    assert!(
        s_light < 0.999 && s_heavy < s_light - 0.05 && s_heavy > -1.0,
        "SSIM with light noise {s_light}, heavy noise {s_heavy}"
    );
    // Swapping the images only reorders products inside each window sum.
    close(ssim(&light, &x), s_light, 1e-12, "SSIM symmetry");
    close(ssim(&heavy, &x), s_heavy, 1e-12, "SSIM symmetry");
}

/// Images too small for one 11×11 window score 1 when equal and 0 otherwise.
#[test]
fn ssim_of_images_smaller_than_its_window_is_equality() {
    let x = texture(10, 10, 1, 3);
    let mut y = x.clone();
    assert_eq!(ssim(&x, &y), 1.0);
    y.data[17] += 0.01;
    assert_eq!(ssim(&x, &y), 0.0);
}

#[test]
fn srgb_encode_matches_the_standard_at_its_defining_points() {
    close(f64::from(srgb_encode(0.0)), 0.0, 0.0, "0");
    close(f64::from(srgb_encode(1.0)), 1.0, 1e-6, "1");
    // The linear segment up to and including 0.0031308: 12.92 × 0.0031308.
    close(
        f64::from(srgb_encode(0.003_130_8)),
        0.040_449_936,
        1e-7,
        "linear end",
    );
    close(
        f64::from(srgb_encode(0.001)),
        0.012_92,
        1e-7,
        "linear segment",
    );
    // The two segments meet there (the standard's constants make it continuous to ~1e-6).
    let above = f64::from(srgb_encode(0.003_131));
    close(
        above,
        0.040_45,
        2e-5,
        "power segment just above the boundary",
    );
    // 1.055 × 0.5^(1/2.4) − 0.055 and the same for mid grey 0.18.
    close(f64::from(srgb_encode(0.5)), 0.735_357, 1e-5, "0.5");
    close(f64::from(srgb_encode(0.18)), 0.461_356, 1e-5, "0.18");
    // Display values: out-of-range inputs clamp, NaN and −∞ show as black.
    assert_eq!(srgb_encode(-0.5), 0.0);
    assert_eq!(srgb_encode(f32::NEG_INFINITY), 0.0);
    assert_eq!(srgb_encode(f32::NAN), 0.0);
    close(f64::from(srgb_encode(7.0)), 1.0, 1e-6, "above 1");
    // Strictly increasing over [0, 1].
    let curve: Vec<f32> = (0..=1000).map(|i| srgb_encode(i as f32 / 1000.0)).collect();
    assert!(curve.windows(2).all(|w| w[1] > w[0]));

    let p = planar(2, 1, 1, vec![0.5, -1.0]).display();
    close(f64::from(p.data[0]), 0.735_357, 1e-5, "display()");
    assert_eq!(p.data[1], 0.0);
}

/// Coefficients of E(n)/π (what `fit_sh_irradiance` returns): a coloured directional light
/// from `dir` plus a uniform ambient radiance. For radiance L_lm the irradiance over π has
/// coefficients Â_l L_lm with Â = (1, 2/3, 1/4) per band; a directional light of intensity I
/// has L_lm = I·Y_lm(d), and a uniform radiance `a` contributes a·√(4π) to L_00, i.e. E/π = a.
fn lighting(dir: [f32; 3], colour: [f32; 3], ambient: [f32; 3]) -> [[f32; 3]; 9] {
    let len = dir.iter().map(|v| v * v).sum::<f32>().sqrt();
    let y = sh9_basis(dir.map(|v| v / len));
    let band = [
        1.0,
        2.0 / 3.0,
        2.0 / 3.0,
        2.0 / 3.0,
        0.25,
        0.25,
        0.25,
        0.25,
        0.25,
    ];
    let mut out = [[0f32; 3]; 9];
    for k in 0..9 {
        for c in 0..3 {
            out[k][c] = band[k] * y[k] * colour[c];
        }
    }
    for c in 0..3 {
        out[0][c] += ambient[c] / 0.282_094_8;
    }
    out
}

fn eval_sh(coeffs: &[[f32; 3]; 9], n: [f32; 3]) -> [f32; 3] {
    let y = sh9_basis(n);
    let mut e = [0f32; 3];
    for k in 0..9 {
        for c in 0..3 {
            e[c] += coeffs[k][c] * y[k];
        }
    }
    e
}

/// Image planes for the SH fit, rendered as relit = albedo ⊙ E(n)/π with a textured albedo.
struct Scene {
    relit: Planar,
    albedo: Planar,
    normal: Planar,
    mask: Planar,
}

const S: usize = 48;

/// A sphere seen orthographically from +Z: an S×S disc of the front hemisphere of normals,
/// and with `back` a second disc to its right holding the back hemisphere (z negated), as
/// though a second camera looked from −Z. Outside the discs the mask is 0 and the relit image
/// holds junk; inside, a few pixels have a near-black albedo and junk too. A fit must ignore
/// both.
fn sphere_scene(coeffs: &[[f32; 3]; 9], back: bool) -> Scene {
    let w = if back { 2 * S } else { S };
    let plane = w * S;
    let (mut relit, mut albedo, mut normal, mut mask) = (
        vec![0f32; 3 * plane],
        vec![0f32; 3 * plane],
        vec![0f32; 3 * plane],
        vec![0f32; plane],
    );
    for y in 0..S {
        for x in 0..w {
            let i = y * w + x;
            let px = ((x % S) as f32 + 0.5) / S as f32 * 2.0 - 1.0;
            let py = 1.0 - (y as f32 + 0.5) / S as f32 * 2.0;
            let r2 = px * px + py * py;
            if r2 >= 0.98 {
                for c in 0..3 {
                    relit[c * plane + i] = 5.0;
                    albedo[c * plane + i] = 0.5;
                    normal[c * plane + i] = [0.0, 0.0, 1.0][c];
                }
                continue;
            }
            mask[i] = 1.0;
            let z = (1.0 - r2).sqrt();
            let n = [px, py, if x < S { z } else { -z }];
            let e = eval_sh(coeffs, n);
            for c in 0..3 {
                normal[c * plane + i] = n[c];
                let a = 0.15 + 0.7 * (((x * 7 + y * 3 + c * 5) % 11) as f32 / 10.0);
                albedo[c * plane + i] = a;
                relit[c * plane + i] = a * e[c];
            }
            if (x + 2 * y) % 29 == 0 {
                albedo[i] = 0.01;
                relit[i] = 3.0;
            }
        }
    }
    Scene {
        relit: planar(w, S, 3, relit),
        albedo: planar(w, S, 3, albedo),
        normal: planar(w, S, 3, normal),
        mask: planar(w, S, 1, mask),
    }
}

fn fit(s: &Scene) -> [[f32; 3]; 9] {
    fit_sh_irradiance(&s.relit, &s.albedo, &s.normal, &s.mask)
        .expect("a fit from thousands of sphere pixels")
}

/// The lighting of these tests: a warm light from the upper right front and a cool ambient.
fn key_light() -> [[f32; 3]; 9] {
    lighting([0.5, 0.6, 0.62], [1.0, 0.8, 0.6], [0.2, 0.25, 0.3])
}

/// The same light from the opposite side (x mirrored): it lights the other half of the face.
fn mirrored_light() -> [[f32; 3]; 9] {
    lighting([-0.5, 0.6, 0.62], [1.0, 0.8, 0.6], [0.2, 0.25, 0.3])
}

/// With normals over the whole sphere every band is constrained, and the exact data leave
/// only the ridge's shrinkage: λ = 1e-3 of the mean diagonal of AᵀA pulls each eigen-direction
/// of the solution toward zero by λ/(σ + λ). The orthographic discs sample the sphere with
/// density ∝ |z|, which keeps σ within a small factor of the mean diagonal, so the shrinkage
/// is about 1e-3 of coefficients of at most ~1.2 (measured: 1.7e-3 at most).
#[test]
fn sh_irradiance_is_recovered_from_normals_over_the_whole_sphere() {
    let truth = key_light();
    let est = fit(&sphere_scene(&truth, true));
    for k in 0..9 {
        for c in 0..3 {
            close(
                f64::from(est[k][c]),
                f64::from(truth[k][c]),
                5e-3,
                &format!("coefficient {k} channel {c}"),
            );
        }
    }
    let err = sphere_error(&est, |n| eval_sh(&truth, n));
    assert!(err < 1e-3, "sphere error of the recovered lighting: {err}");
    let wrong = sphere_error(&est, |n| eval_sh(&mirrored_light(), n));
    assert!(
        wrong > 0.2,
        "sphere error against the mirrored light: {wrong} (recovered: {err})"
    );
    // The truth against itself is exactly zero: the mean matching scales by exactly 1.
    assert_eq!(sphere_error(&truth, |n| eval_sh(&truth, n)), 0.0);
}

/// A face shows the camera only the front hemisphere of normals. There, 1, z and 3z² − 1 are
/// nearly collinear, so that combination has a small σ and the ridge shrinks it by far more
/// than the others (measured: Y00 off by up to 0.14, compensated in Y10 and Y20). The bands the
/// front hemisphere does separate (x, y, xy, yz, xz, x² − y²) are still recovered to the ridge's
/// ~1e-3, and the irradiance over the visible normals, which the shrunk combination barely
/// changes, to about 1 %: that, not the coefficients, is what section 5.2's sphere error
/// (camera at +Z) scores.
#[test]
fn sh_irradiance_seen_from_the_front_matches_where_it_is_seen() {
    let truth = key_light();
    let est = fit(&sphere_scene(&truth, false));
    for k in [1, 3, 4, 5, 7, 8] {
        for c in 0..3 {
            close(
                f64::from(est[k][c]),
                f64::from(truth[k][c]),
                3e-3,
                &format!("coefficient {k} channel {c}"),
            );
        }
    }
    for n in [
        [0.0, 0.0, 1.0],
        [-0.56, 0.15, 0.814],
        [0.69, -0.27, 0.671],
        [0.0, 0.81, 0.586],
        [-0.9, 0.0, 0.436],
    ] {
        let (e, t) = (eval_sh(&est, n), eval_sh(&truth, n));
        for c in 0..3 {
            close(
                f64::from(e[c]),
                f64::from(t[c]),
                0.015 * f64::from(t[c]),
                &format!("E/π at {n:?} channel {c}"),
            );
        }
    }
    let err = sphere_error(&est, |n| eval_sh(&truth, n));
    assert!(err < 0.01, "sphere error of the recovered lighting: {err}");
    let wrong = sphere_error(&est, |n| eval_sh(&mirrored_light(), n));
    assert!(
        wrong > 0.2,
        "sphere error against the mirrored light: {wrong} (recovered: {err})"
    );
}

#[test]
fn sh_fit_needs_nine_usable_pixels() {
    let mut s = sphere_scene(&key_light(), false);
    s.mask.data.iter_mut().for_each(|m| *m = 0.0);
    assert_eq!(
        fit_sh_irradiance(&s.relit, &s.albedo, &s.normal, &s.mask),
        None
    );
    // Eight pixels near the centre of the disc are still too few.
    for m in s.mask.data.iter_mut().skip(24 * S + 20).take(8) {
        *m = 1.0;
    }
    assert_eq!(
        fit_sh_irradiance(&s.relit, &s.albedo, &s.normal, &s.mask),
        None
    );
}
