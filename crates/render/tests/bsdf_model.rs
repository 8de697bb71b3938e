//! The shader's BSDF evaluation (shaders/inc/bsdf.wgsl through the probe kernel) against an
//! independent CPU evaluation of the same model (tests/common/bsdf_ref.rs) at random direction
//! pairs, and its energy: a white-furnace integral of f·cos over the sphere that a GGX
//! mirror-metal must bring to the directional albedo tabulated by CPU quadrature (≤ 1), a
//! white Lambertian to 1 exactly, and a dielectric mixture to at most 1.

mod common;

use std::f64::consts::PI;

use common::bsdf_ref::{ggx_albedo, RefSurface};
use lightfarm_render::probe::{Probe, ProbeSurface};

fn probe() -> Probe {
    Probe::new(&common::ctx()).expect("probe kernels")
}

fn surface(base: [f32; 3], metallic: f32, roughness: f32, specular: f32) -> ProbeSurface {
    ProbeSurface {
        base,
        metallic,
        alpha: roughness * roughness,
        specular,
        spec_color: [1.0; 3],
        transmission: 0.0,
        ior: 1.5,
        ..Default::default()
    }
}

/// Deterministic uniform numbers in [0, 1) (SplitMix64), so a failure reproduces.
struct Uniform(u64);

impl Uniform {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A direction uniform on the sphere.
    fn direction(&mut self) -> [f32; 3] {
        let z = 2.0 * self.next() - 1.0;
        let phi = 2.0 * PI * self.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
    }
}

#[test]
fn device_bsdf_matches_the_cpu_model_at_random_directions() {
    let p = probe();
    let mut rng = Uniform(42);
    let cases = [
        ("lambert", surface([0.8, 0.5, 0.2], 0.0, 0.5, 0.0)),
        ("rough gold", surface([1.0, 0.78, 0.34], 1.0, 0.6, 1.0)),
        ("smooth metal", surface([0.9; 3], 1.0, 0.2, 1.0)),
        ("plastic", surface([0.3, 0.6, 0.9], 0.0, 0.35, 1.0)),
        ("half metal", surface([0.7, 0.2, 0.2], 0.5, 0.45, 0.6)),
        ("tinted specular", {
            let mut s = surface([0.4; 3], 0.0, 0.4, 0.8);
            s.spec_color = [1.0, 0.5, 0.25];
            s.ior = 1.4;
            s
        }),
    ];
    for (name, s) in cases {
        let reference = RefSurface::from(&s);
        for _ in 0..8 {
            // Above the surface, not quite grazing; unit length, as the shader assumes.
            let d = rng.direction();
            let z = d[2].abs().max(0.02);
            let s2 = ((1.0 - z * z) / (d[0] * d[0] + d[1] * d[1]).max(1e-12)).sqrt();
            let wo = [d[0] * s2, d[1] * s2, z];
            let wis: Vec<[f32; 3]> = (0..4096).map(|_| rng.direction()).collect();
            let got = p.bsdf_eval(&s, wo, &wis).expect("eval");
            let (mut nonzero, mut below) = (0, 0);
            for (wi, (f_cos, pdf)) in wis.iter().zip(got) {
                let (ref_f, ref_pdf) = reference.eval(wo, *wi);
                if wi[2] <= 0.0 {
                    below += 1;
                    assert!(
                        f_cos == [0.0; 3] && pdf == 0.0,
                        "{name}: nothing is reflected below the surface ({wi:?}: {f_cos:?}, {pdf})"
                    );
                    continue;
                }
                let close = |a: f32, b: f64| (f64::from(a) - b).abs() <= 1e-3 * b.abs() + 1e-6;
                assert!(
                    close(pdf, ref_pdf),
                    "{name}: pdf {pdf} vs the CPU model's {ref_pdf} at wo {wo:?} wi {wi:?}"
                );
                for k in 0..3 {
                    assert!(
                        close(f_cos[k], ref_f[k]),
                        "{name}: f·cos[{k}] {} vs the CPU model's {} at wo {wo:?} wi {wi:?}",
                        f_cos[k],
                        ref_f[k]
                    );
                }
                nonzero += usize::from(pdf > 0.0);
            }
            assert!(
                nonzero > 1000 && below > 1000,
                "{name}: {nonzero} lit, {below} below"
            );
        }
    }
}

/// ∫ f·cos dωi over the sphere for `wo`, from the device's eval on an n×n equal-area grid of
/// the upper hemisphere (cos θ, φ) — the white-furnace reflectance of the BSDF.
fn device_albedo(p: &Probe, s: &ProbeSurface, cos_o: f64, n: usize) -> [f64; 3] {
    let wo = [(1.0 - cos_o * cos_o).sqrt() as f32, 0.0, cos_o as f32];
    let mut wis = Vec::with_capacity(n * n);
    for i in 0..n {
        let z = (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        for j in 0..n {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
            wis.push([(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]);
        }
    }
    let mut sum = [0.0; 3];
    for (f, _) in p.bsdf_eval(s, wo, &wis).expect("eval") {
        for k in 0..3 {
            sum[k] += f64::from(f[k]);
        }
    }
    sum.map(|v| v * 2.0 * PI / (n * n) as f64)
}

#[test]
fn white_furnace_reflectance_of_the_device_bsdf() {
    let p = probe();
    let n = 512;
    // A white Lambertian reflects everything.
    let white = surface([1.0; 3], 0.0, 0.5, 0.0);
    for cos_o in [1.0, 0.5, 0.1] {
        let a = device_albedo(&p, &white, cos_o, n);
        assert!(a.iter().all(|v| (v - 1.0).abs() < 2e-3), "lambert: {a:?}");
    }
    // A mirror-coloured metal (F = 1) loses only what single-scattering GGX loses: its
    // directional albedo, tabulated here by an independent CPU quadrature of D·G2/(4 cos θo).
    for roughness in [0.3f32, 0.6, 0.9] {
        let metal = surface([1.0; 3], 1.0, roughness, 1.0);
        let alpha = f64::from(roughness * roughness);
        for cos_o in [0.95, 0.6, 0.25] {
            let table = ggx_albedo(cos_o, alpha, 1024);
            let a = device_albedo(&p, &metal, cos_o, n);
            println!(
                "GGX r={roughness} cosθo={cos_o}: device {:.4}, table {table:.4}",
                a[0]
            );
            assert!(table <= 1.0 + 1e-6, "the table exceeds 1: {table}");
            for v in a {
                assert!(
                    (v - table).abs() < 5e-3 + 0.01 * (1.0 - table),
                    "GGX r={roughness} cosθo={cos_o}: device albedo {v} vs table {table}"
                );
            }
        }
        // The rough lobe at grazing view loses visibly: the table is not trivially 1.
        if roughness >= 0.9 {
            assert!(ggx_albedo(0.25, alpha, 1024) < 0.9);
        }
    }
    // Diffuse under a dielectric coat reflects at most what comes in.
    let plastic = surface([1.0; 3], 0.0, 0.4, 1.0);
    for cos_o in [1.0, 0.5, 0.1] {
        let a = device_albedo(&p, &plastic, cos_o, n);
        assert!(
            a.iter().all(|v| *v <= 1.0 + 3e-3),
            "plastic gains energy: {a:?}"
        );
    }
}
