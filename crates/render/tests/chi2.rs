//! Chi-square tests of the shaders' sampling routines, run on the device through the probe
//! kernel (pbrt-v4 bsdfs_test.cpp / Mitsuba 3 chi2.py style): samples are histogrammed over the
//! sphere in (cos θ, φ) cells and compared with the integral of the device's own pdf() per cell.

mod common;

use std::f64::consts::PI;

use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::probe::{Probe, ProbeSurface};
use lightfarm_render::EnvLight;

const THETA_BINS: usize = 40;
const PHI_BINS: usize = 80;
const SUB: usize = 6;
const SAMPLES: usize = 1_000_000;

fn probe() -> Probe {
    Probe::new(&common::ctx()).expect("probe kernels")
}

fn cell_of(d: [f32; 3]) -> Option<usize> {
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if !len.is_finite() || len <= 0.0 {
        return None;
    }
    let z = (d[2] / len).clamp(-1.0, 1.0) as f64;
    let mut phi = (d[1] as f64).atan2(d[0] as f64);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let i = (((z + 1.0) * 0.5) * THETA_BINS as f64)
        .floor()
        .min(THETA_BINS as f64 - 1.0) as usize;
    let j = ((phi / (2.0 * PI)) * PHI_BINS as f64)
        .floor()
        .min(PHI_BINS as f64 - 1.0) as usize;
    Some(i * PHI_BINS + j)
}

/// Directions at the centres of SUB×SUB sub-cells of every (cos θ, φ) cell, and the solid angle
/// each represents (cells are equal-area in this parametrisation).
fn integration_grid() -> (Vec<[f32; 3]>, f64) {
    let mut dirs = Vec::with_capacity(THETA_BINS * PHI_BINS * SUB * SUB);
    for i in 0..THETA_BINS {
        for j in 0..PHI_BINS {
            for a in 0..SUB {
                for b in 0..SUB {
                    let z =
                        -1.0 + 2.0 * (i as f64 + (a as f64 + 0.5) / SUB as f64) / THETA_BINS as f64;
                    let phi =
                        2.0 * PI * (j as f64 + (b as f64 + 0.5) / SUB as f64) / PHI_BINS as f64;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    dirs.push([(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]);
                }
            }
        }
    }
    let d_omega = 4.0 * PI / (THETA_BINS * PHI_BINS * SUB * SUB) as f64;
    (dirs, d_omega)
}

fn expected_from_pdf(pdfs: &[f64], d_omega: f64, n: usize) -> Vec<f64> {
    pdfs.chunks_exact(SUB * SUB)
        .map(|c| c.iter().sum::<f64>() * d_omega * n as f64)
        .collect()
}

fn check_bsdf(name: &str, s: ProbeSurface, theta_o_deg: f32, tests: u32) {
    let p = probe();
    let t = theta_o_deg.to_radians();
    let wo = [t.sin(), 0.0, t.cos()];
    let samples = p.bsdf_samples(&s, wo, SAMPLES, 7).expect("sample");
    let mut observed = vec![0.0; THETA_BINS * PHI_BINS];
    let mut checked = Vec::new();
    for smp in samples.iter().filter(|s| s.valid) {
        if let Some(c) = cell_of(smp.wi) {
            observed[c] += 1.0;
        }
        if checked.len() < 2000 {
            checked.push(*smp);
        }
    }
    let (grid, d_omega) = integration_grid();
    let evals = p.bsdf_eval(&s, wo, &grid).expect("eval");
    let pdfs: Vec<f64> = evals.iter().map(|e| e.1 as f64).collect();
    let expected = expected_from_pdf(&pdfs, d_omega, SAMPLES);
    let total: f64 = expected.iter().sum::<f64>() / SAMPLES as f64;
    assert!(total <= 1.01, "{name}: pdf integrates to {total} > 1");
    common::chi2_test(name, &observed, &expected, tests).unwrap_or_else(|e| panic!("{e}"));

    // The sample's pdf and weight agree with eval() at the sampled direction.
    let wis: Vec<[f32; 3]> = checked.iter().map(|s| s.wi).collect();
    let ev = p.bsdf_eval(&s, wo, &wis).expect("eval at samples");
    for (smp, (f_cos, pdf)) in checked.iter().zip(ev) {
        let rel = (smp.pdf - pdf).abs() / pdf.max(1e-6);
        assert!(
            rel < 1e-3,
            "{name}: sampled pdf {} vs eval pdf {pdf}",
            smp.pdf
        );
        for (sw, f) in smp.weight.iter().zip(f_cos) {
            let w = f / pdf;
            assert!(
                (sw - w).abs() <= 1e-3 * w.max(1.0),
                "{name}: weight {:?} vs f·cos/pdf {w}",
                smp.weight
            );
        }
    }
}

fn surface(base: f32, metallic: f32, roughness: f32, specular: f32) -> ProbeSurface {
    ProbeSurface {
        base: [base; 3],
        metallic,
        alpha: roughness * roughness,
        specular,
        spec_color: [1.0; 3],
        transmission: 0.0,
        ior: 1.5,
    }
}

#[test]
fn lambert_matches_its_pdf() {
    for theta in [0.0, 60.0] {
        check_bsdf(
            &format!("lambert θo={theta}"),
            surface(0.8, 0.0, 0.5, 0.0),
            theta,
            2,
        );
    }
}

#[test]
fn ggx_vndf_reflection_matches_its_pdf() {
    for (rough, theta) in [(0.3, 30.0), (0.6, 70.0), (0.9, 10.0)] {
        check_bsdf(
            &format!("ggx r={rough} θo={theta}"),
            surface(0.9, 1.0, rough, 1.0),
            theta,
            3,
        );
    }
}

#[test]
fn diffuse_plus_specular_mixture_matches_its_pdf() {
    check_bsdf("diffuse+ggx", surface(0.5, 0.0, 0.4, 1.0), 45.0, 1);
}

fn fresnel(cos_i: f64, eta: f64) -> f64 {
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// A smooth dielectric is a two-point distribution: reflection with probability F, refraction
/// (Snell's law) otherwise. Chi-square on the two outcomes; both directions checked exactly.
#[test]
fn smooth_dielectric_reflects_with_fresnel_probability() {
    let p = probe();
    let mut s = surface(1.0, 0.0, 0.0, 1.0);
    s.transmission = 1.0;
    let n = 200_000;
    for (theta_deg, ior) in [
        (0.0f64, 1.5f32),
        (45.0, 1.5),
        (80.0, 1.5),
        (30.0, 1.0 / 1.5),
        (60.0, 1.0 / 1.5),
    ] {
        s.ior = ior;
        let t = theta_deg.to_radians();
        let wo = [t.sin() as f32, 0.0, t.cos() as f32];
        let f = fresnel(t.cos(), ior as f64);
        let samples = p.bsdf_samples(&s, wo, n, 3).expect("sample");
        let mut counts = [0.0; 2];
        for smp in &samples {
            assert!(smp.valid && smp.delta, "dielectric samples are delta");
            if smp.wi[2] > 0.0 {
                counts[0] += 1.0;
                assert!(
                    (smp.wi[0] + wo[0]).abs() < 1e-5 && (smp.wi[2] - wo[2]).abs() < 1e-5,
                    "mirror direction"
                );
            } else {
                counts[1] += 1.0;
                let sin_t = (t.sin() / ior as f64) as f32;
                assert!(
                    (smp.wi[0] + sin_t).abs() < 1e-4,
                    "Snell: sin θt {} vs {}",
                    -smp.wi[0],
                    sin_t
                );
            }
        }
        let expected = [f * n as f64, (1.0 - f) * n as f64];
        if f < 1.0 {
            common::chi2_test(
                &format!("dielectric θ={theta_deg} η={ior}"),
                &counts,
                &expected,
                5,
            )
            .unwrap_or_else(|e| panic!("{e}"));
        } else {
            assert_eq!(counts[1], 0.0, "total internal reflection never refracts");
        }
    }
}

/// Index of the `bw`×`bh` (u, v) bin that a world direction falls in, in the light's own frame.
fn env_bin(light: &EnvLight, d: [f32; 3], bw: u32, bh: u32) -> usize {
    let uv = lightfarm_light::dir_to_uv(light.transform.world_to_env(d));
    let x = ((uv[0] * bw as f32) as u32).min(bw - 1);
    let y = ((uv[1] * bh as f32) as u32).min(bh - 1);
    (y * bw + x) as usize
}

/// Probability of every texel of `light`'s map, from the device's own env_pdf() at the texel
/// centres: the pdf is constant in (u, v) over a texel, so this is exact.
fn texel_probabilities(p: &Probe, light: &EnvLight) -> Vec<f64> {
    let (w, h) = (light.hdri.width, light.hdri.height);
    let uv = |i: u32| {
        [
            ((i % w) as f32 + 0.5) / w as f32,
            ((i / w) as f32 + 0.5) / h as f32,
        ]
    };
    let centres: Vec<[f32; 3]> = (0..w * h)
        .map(|i| {
            light
                .transform
                .env_to_world(lightfarm_light::uv_to_dir(uv(i)))
        })
        .collect();
    let pdfs = p.env_eval(light, &centres).expect("env pdf");
    (0..w * h)
        .map(|i| {
            let p_uv = pdfs[i as usize].0 as f64 * 2.0 * PI * PI * (PI * uv(i)[1] as f64).sin();
            p_uv / (w * h) as f64
        })
        .collect()
}

/// The environment sampler on a map with a hot texel and a gradient: bins are the texels
/// themselves, where the pdf in (u, v) is exactly constant, so expected counts are exact.
#[test]
fn environment_sampler_matches_its_pdf() {
    let (w, h) = (32u32, 16u32);
    let mut texels = vec![[0.0f32; 3]; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let g = 0.2 + (x as f32 / w as f32) * (1.0 - y as f32 / h as f32);
            texels[(y * w + x) as usize] = [g, 0.5 * g, 0.25 * g];
        }
    }
    texels[(5 * w + 20) as usize] = [500.0, 400.0, 300.0];
    texels[(h * w - 1) as usize] = [0.0; 3]; // a zero-radiance texel must never be sampled
    let hdri = Hdri::from_texels(w, h, texels).expect("hdri");
    for transform in [
        EnvTransform::default(),
        EnvTransform {
            rotation_deg: 137.0,
            flip: true,
        },
    ] {
        let light = EnvLight {
            name: "synthetic".into(),
            hdri: hdri.clone(),
            transform,
        };
        let p = probe();
        let samples = p.env_samples(&light, SAMPLES, 11).expect("env samples");
        let mut observed = vec![0.0; (w * h) as usize];
        for (d, pdf) in &samples {
            assert!(*pdf > 0.0, "sampled direction with pdf 0");
            observed[env_bin(&light, *d, w, h)] += 1.0;
        }
        let expected: Vec<f64> = texel_probabilities(&p, &light)
            .iter()
            .map(|q| q * SAMPLES as f64)
            .collect();
        let total: f64 = expected.iter().sum::<f64>() / SAMPLES as f64;
        assert!((total - 1.0).abs() < 1e-3, "env pdf integrates to {total}");
        common::chi2_test(&format!("env {transform:?}"), &observed, &expected, 2)
            .unwrap_or_else(|e| panic!("{e}"));
    }
}

/// The same check on a real 1024×512 sun-and-sky map (half a million texels, one tiny sun),
/// binned into 64×32 cells: large maps stress the precision of the texel choice.
#[test]
fn environment_sampler_matches_its_pdf_on_a_real_map() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/hdri/rooitou_park_1k.hdr");
    let hdri = Hdri::load(&path).expect("built-in HDRI");
    let (w, h) = (hdri.width, hdri.height);
    let transform = EnvTransform {
        rotation_deg: 30.0,
        flip: false,
    };
    let light = EnvLight {
        name: "rooitou".into(),
        hdri,
        transform,
    };
    let p = probe();
    let n = 2_000_000;
    let (bw, bh) = (64u32, 32u32);
    let mut observed = vec![0.0; (bw * bh) as usize];
    for (d, _) in p.env_samples(&light, n, 5).expect("env samples") {
        observed[env_bin(&light, d, bw, bh)] += 1.0;
    }
    let mut expected = vec![0.0; (bw * bh) as usize];
    for (i, q) in texel_probabilities(&p, &light).into_iter().enumerate() {
        let texel_centre = lightfarm_light::uv_to_dir([
            ((i as u32 % w) as f32 + 0.5) / w as f32,
            ((i as u32 / w) as f32 + 0.5) / h as f32,
        ]);
        expected[env_bin(&light, light.transform.env_to_world(texel_centre), bw, bh)] +=
            q * n as f64;
    }
    common::chi2_test("env rooitou_park", &observed, &expected, 1)
        .unwrap_or_else(|e| panic!("{e}"));
}
