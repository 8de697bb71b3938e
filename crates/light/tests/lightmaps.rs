//! Light-map prefiltering: constant environments, a single hot texel, SH against brute force,
//! and the convolution window against the full sum.

// Channel and SH-band loops index several parallel arrays at once.
#![allow(clippy::needless_range_loop)]

use std::path::Path;

use lightfarm_light::{
    downsample, prefilter_phong, sh9_basis, uv_to_dir, Hdri, PrefilteredEnv, ShRadiance,
    PHONG_EXPONENTS,
};

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = dot(a, a).sqrt();
    a.map(|v| v / l)
}

/// Deterministic directions spread over the sphere (Fibonacci lattice).
fn directions(n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let phi = i as f32 * 2.399_963;
            [r * phi.cos(), y, r * phi.sin()]
        })
        .collect()
}

fn solid_angle(row: usize, w: usize, h: usize) -> f64 {
    let t0 = std::f64::consts::PI * row as f64 / h as f64;
    let t1 = std::f64::consts::PI * (row + 1) as f64 / h as f64;
    2.0 * std::f64::consts::PI / w as f64 * (t0.cos() - t1.cos())
}

/// Brute-force ∫ L(ω) max(0, n·ω)^e dω over every texel (no window); `normalise` divides by the
/// same sum of weights, otherwise by π (irradiance/π for e = 1).
fn brute_force(hdri: &Hdri, n: [f32; 3], e: i32, normalise: bool) -> [f64; 3] {
    let (w, h) = (hdri.width as usize, hdri.height as usize);
    let (mut acc, mut wsum) = ([0f64; 3], 0f64);
    for row in 0..h {
        let om = solid_angle(row, w, h);
        for col in 0..w {
            let d = uv_to_dir([(col as f32 + 0.5) / w as f32, (row as f32 + 0.5) / h as f32]);
            let c = f64::from(dot(n, d));
            if c <= 0.0 {
                continue;
            }
            let wgt = c.powi(e) * om;
            for ch in 0..3 {
                acc[ch] += wgt * f64::from(hdri.texels[row * w + col][ch]);
            }
            wsum += wgt;
        }
    }
    let div = if normalise {
        wsum
    } else {
        std::f64::consts::PI
    };
    acc.map(|a| a / div)
}

fn asset_hdri(name: &str) -> Hdri {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/hdri")
        .join(name);
    Hdri::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn constant_environment_gives_one_everywhere() {
    let env = PrefilteredEnv::compute(&Hdri::constant(128, 64, [1.0, 1.0, 1.0]));
    for n in directions(200) {
        let e = env.sh.irradiance(n);
        for v in e {
            assert!((v - 1.0).abs() < 1e-3, "SH irradiance {v} at {n:?}");
        }
        for map in &env.phong {
            for v in map.lookup(n) {
                assert!(
                    (v - 1.0).abs() < 1e-5,
                    "Phong {} gives {v} at {n:?}",
                    map.exponent
                );
            }
        }
    }
    assert_eq!(env.phong.len(), PHONG_EXPONENTS.len());
    let mean = env.sh.mean_radiance();
    assert!((mean[0] - 1.0).abs() < 1e-3, "mean radiance {mean:?}");
}

/// One hot texel: every lobe peaks in its direction and falls to half at the angle where
/// cos^n = 1/2 (within the blur of the map's resolution).
#[test]
fn hot_texel_lobes_peak_in_the_right_direction_with_the_right_width() {
    let (w, h) = (1024usize, 512usize);
    let (hot_col, hot_row) = (700usize, 190usize);
    let mut texels = vec![[0f32; 3]; w * h];
    texels[hot_row * w + hot_col] = [1000.0, 500.0, 250.0];
    let hdri = Hdri::from_texels(w as u32, h as u32, texels).unwrap();
    let hot = uv_to_dir([
        (hot_col as f32 + 0.5) / w as f32,
        (hot_row as f32 + 0.5) / h as f32,
    ]);
    // A direction perpendicular to `hot` to walk away from it along a great circle.
    let side = normalize([hot[2], 0.0, -hot[0]]);
    let at_angle = |g: f32| -> [f32; 3] {
        let (s, c) = g.sin_cos();
        normalize([
            c * hot[0] + s * side[0],
            c * hot[1] + s * side[1],
            c * hot[2] + s * side[2],
        ])
    };
    let env = PrefilteredEnv::compute(&hdri);
    for map in &env.phong {
        let n = map.exponent as f32;
        // Peak: the brightest texel's centre is within one texel (plus the source's) of `hot`.
        let (best, _) = map
            .texels
            .iter()
            .enumerate()
            .max_by(|a, b| a.1[0].total_cmp(&b.1[0]))
            .unwrap();
        let d = uv_to_dir([
            ((best % map.width) as f32 + 0.5) / map.width as f32,
            ((best / map.width) as f32 + 0.5) / map.height as f32,
        ]);
        let texel_angle = std::f32::consts::PI / map.height as f32;
        let off = dot(d, hot).clamp(-1.0, 1.0).acos();
        assert!(
            off <= 1.5 * texel_angle,
            "n={n}: peak {off} rad from the hot texel (texel {texel_angle})"
        );
        // Colour ratio is the texel's.
        let p = map.lookup(hot);
        assert!(
            (p[1] / p[0] - 0.5).abs() < 1e-3 && (p[2] / p[0] - 0.25).abs() < 1e-3,
            "n={n}: {p:?}"
        );
        // Width: half maximum where cos^n γ = 1/2.
        let half = 0.5f32.powf(1.0 / n).acos();
        let ratio = map.lookup(at_angle(half))[0] / p[0];
        let tolerance = if map.exponent >= 1024 { 0.15 } else { 0.06 };
        assert!(
            (ratio - 0.5).abs() < tolerance,
            "n={n}: at the half-max angle {half} the lobe is {ratio}"
        );
        let ratio2 = map.lookup(at_angle(2.0 * half))[0] / p[0];
        let expect2 = (2.0 * half).cos().max(0.0).powf(n);
        assert!(
            (ratio2 - expect2).abs() < tolerance,
            "n={n}: at twice the half-max angle {ratio2} vs {expect2}"
        );
    }
}

/// An environment that is exactly a band-limited SH function: projection returns its
/// coefficients and the irradiance matches the brute-force cosine integral.
#[test]
fn sh_matches_brute_force() {
    let (w, h) = (256usize, 128usize);
    let truth: [[f32; 3]; 9] = [
        [2.0, 1.5, 1.0],
        [0.6, 0.4, 0.2],
        [-0.3, 0.1, 0.2],
        [0.2, -0.2, 0.1],
        [0.1, 0.05, 0.0],
        [-0.1, 0.0, 0.1],
        [0.15, 0.1, -0.05],
        [0.0, 0.1, 0.05],
        [0.05, -0.05, 0.1],
    ];
    let mut texels = Vec::with_capacity(w * h);
    for row in 0..h {
        for col in 0..w {
            let d = uv_to_dir([(col as f32 + 0.5) / w as f32, (row as f32 + 0.5) / h as f32]);
            let y = sh9_basis(d);
            let mut l = [0f32; 3];
            for k in 0..9 {
                for c in 0..3 {
                    l[c] += truth[k][c] * y[k];
                }
            }
            texels.push(l.map(|v| v.max(0.0)));
        }
    }
    assert!(
        texels.iter().all(|t| t.iter().all(|&v| v > 0.0)),
        "test env must be positive"
    );
    let hdri = Hdri::from_texels(w as u32, h as u32, texels).unwrap();
    let sh = ShRadiance::project(&hdri);
    for k in 0..9 {
        for c in 0..3 {
            assert!(
                (sh.coeffs[k][c] - truth[k][c]).abs() < 2e-3,
                "L[{k}][{c}] {} vs {}",
                sh.coeffs[k][c],
                truth[k][c]
            );
        }
    }
    for n in directions(64) {
        let e = sh.irradiance(n);
        let b = brute_force(&hdri, n, 1, false);
        for c in 0..3 {
            assert!(
                (f64::from(e[c]) - b[c]).abs() < 2e-3 * b[c].abs().max(1.0),
                "{n:?}: SH {e:?} vs brute {b:?}"
            );
        }
    }
}

/// On a real sun-and-sky map order-2 SH is an approximation. Its worst case is a point light,
/// where the truncated clamped cosine is off by 9.4% of the peak (at 90° from the light); a
/// real map must do no worse than that, and better on average.
#[test]
fn sh_irradiance_of_a_real_map_is_close_to_brute_force() {
    let hdri = downsample(&asset_hdri("rooitou_park_1k.hdr"), 256);
    let sh = ShRadiance::project(&hdri);
    let dirs = directions(100);
    let brute: Vec<[f64; 3]> = dirs
        .iter()
        .map(|&n| brute_force(&hdri, n, 1, false))
        .collect();
    let peak = brute.iter().map(|b| b[1]).fold(0f64, f64::max);
    let (mut worst, mut sum) = (0f64, 0f64);
    for (n, b) in dirs.iter().zip(&brute) {
        let err = (f64::from(sh.irradiance(*n)[1]) - b[1]).abs() / peak;
        worst = worst.max(err);
        sum += err;
    }
    let mean = sum / dirs.len() as f64;
    assert!(
        worst < 0.094,
        "worst SH error {worst} of the peak irradiance"
    );
    assert!(mean < 0.04, "mean SH error {mean} of the peak irradiance");
}

/// The window only drops weights below 1e-6 of the peak: the prefiltered values equal the full
/// normalised sum over every texel, even in the dim directions of a studio map.
#[test]
fn windowed_convolution_equals_the_full_sum() {
    let hdri = downsample(&asset_hdri("studio_small_03_1k.hdr"), 128);
    let mean = ShRadiance::project(&hdri).mean_radiance();
    for n in [1u32, 16, 64, 1024] {
        let map = prefilter_phong(&hdri, n, 32, 128);
        for row in [0usize, 3, 8, 15] {
            for col in [0usize, 7, 20, 31] {
                let d = uv_to_dir([(col as f32 + 0.5) / 32.0, (row as f32 + 0.5) / 16.0]);
                let full = brute_force(&hdri, d, n as i32, true);
                let got = map.texels[row * 32 + col];
                for c in 0..3 {
                    let tol = 1e-3 * full[c].abs() + 1e-3 * f64::from(mean[c]);
                    assert!(
                        (f64::from(got[c]) - full[c]).abs() < tol,
                        "n={n} ({row},{col}): {got:?} vs {full:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn downsampling_keeps_the_mean_radiance() {
    let hdri = asset_hdri("venice_sunset_1k.hdr");
    let mean = |h: &Hdri| ShRadiance::project(h).mean_radiance();
    let (a, b) = (mean(&hdri), mean(&downsample(&hdri, 64)));
    for c in 0..3 {
        assert!((a[c] - b[c]).abs() < 1e-3 * a[c], "{a:?} vs {b:?}");
    }
}
