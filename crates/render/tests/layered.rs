//! The layered Standard Surface (shaders/inc/layered.wgsl) on the probe kernel: its albedo
//! tables against CPU quadrature of the lobe formulas, chi-square tests of the coat, the sheen
//! and the paper's skin mixture (each also rejecting a 5%-biased sampler), sampled weights
//! against the evaluated f·cos/pdf, and white-furnace energy of the layering.

// Per-channel loops over [f32; 3] read clearer indexed.
#![allow(clippy::needless_range_loop)]

mod common;

use std::f64::consts::PI;

use lightfarm_render::gpu_types::LUT_N;
use lightfarm_render::probe::{Probe, ProbeSurface};

use common::bsdf_ref::{ggx_albedo, ggx_d, ggx_lambda};
use common::sphere_chi2::{bsdf_chi2, integration_grid};

fn probe() -> Probe {
    Probe::new(&common::ctx()).expect("probe kernels")
}

const MODEL_SKIN: u32 = 1;

fn layered(base: [f32; 3]) -> ProbeSurface {
    ProbeSurface {
        base,
        model: MODEL_SKIN,
        specular: 0.0,
        sss: 0.0,
        sss_color: base,
        coat: 0.0,
        sheen: 0.0,
        ..Default::default()
    }
}

/// The paper's skin (appendix): specular 0.82 at roughness 0.4, coat 0.1 at 0.25, sheen 0.1 at
/// 0.3, subsurface 0.95 of a skin-coloured base.
fn paper_skin() -> ProbeSurface {
    ProbeSurface {
        base: [0.6, 0.4, 0.3],
        model: MODEL_SKIN,
        alpha: 0.16,
        specular: 1.0,
        spec_color: [0.82; 3],
        ior: 1.5,
        sss: 0.95,
        sss_color: [0.6, 0.4, 0.3],
        sss_mfp: [2.25e-3, 0.79e-3, 0.45e-3],
        coat: 0.1,
        coat_alpha: 0.0625,
        coat_ior: 1.5,
        sheen: 0.1,
        sheen_color: [1.0; 3],
        sheen_rough: 0.3,
        ..Default::default()
    }
}

fn wo(theta_deg: f64) -> [f32; 3] {
    let t = theta_deg.to_radians();
    [t.sin() as f32, 0.0, t.cos() as f32]
}

/// Midpoint quadrature over the hemisphere in (cos θi, φ) of g(wi·h, wi.z, h.z) for a
/// viewing cosine `mu`; returns ∫ g dω.
fn hemisphere(mu: f64, n: usize, g: impl Fn(f64, f64, f64) -> f64) -> f64 {
    let wo = [(1.0 - mu * mu).sqrt(), 0.0, mu];
    let mut sum = 0.0;
    for i in 0..n {
        let ci = (i as f64 + 0.5) / n as f64;
        let si = (1.0 - ci * ci).sqrt();
        for j in 0..n {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
            let wi = [si * phi.cos(), si * phi.sin(), ci];
            let h = [wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]];
            let len = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
            let h = [h[0] / len, h[1] / len, h[2] / len];
            let wo_h = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
            sum += g(wo_h, ci, h[2]);
        }
    }
    sum * 2.0 * PI / (n * n) as f64
}

#[test]
fn albedo_tables_match_cpu_quadrature_of_the_lobes() {
    let t = probe().tables().expect("tables");
    assert_eq!(t.len(), LUT_N * LUT_N);
    for &(i, j) in &[
        (0usize, 31usize),
        (3, 5),
        (8, 10),
        (16, 16),
        (24, 1),
        (31, 31),
        (12, 25),
        (2, 0),
        (20, 0),
    ] {
        let mu = (i as f64 + 0.5) / LUT_N as f64;
        let r = j as f64 / (LUT_N - 1) as f64;
        let alpha = (r * r).max(1e-4);
        let cell = t[j * LUT_N + i];
        // F = 1: the mirror-metal albedo; F = Schlick's (1 − cos)^5 term alone: B.
        let e1 = ggx_albedo(mu, alpha, 600);
        let b = hemisphere(mu, 600, |wo_h, ci, hz| {
            let g2 = 1.0 / (1.0 + ggx_lambda(mu, alpha) + ggx_lambda(ci, alpha));
            ggx_d(hz, alpha) * g2 / (4.0 * mu) * (1.0 - wo_h).powi(5)
        });
        let (a_gpu, b_gpu) = (f64::from(cell[0]), f64::from(cell[1]));
        // Nearly specular lobes have a sharply peaked integrand that the CPU grid resolves
        // worse than the GPU's visible-normal samples: compare where the grid is fine enough.
        if alpha > 0.05 {
            assert!(
                (a_gpu + b_gpu - e1).abs() < 4e-3,
                "cell ({i},{j}): A + B {} vs {e1}",
                a_gpu + b_gpu
            );
            assert!((b_gpu - b).abs() < 2e-3, "cell ({i},{j}): B {b_gpu} vs {b}");
        } else if alpha <= 1e-3 {
            assert!(
                (a_gpu + b_gpu - 1.0).abs() < 5e-3,
                "cell ({i},{j}): smooth A + B {}",
                a_gpu + b_gpu
            );
        }
        let rs = r.clamp(0.02, 1.0);
        let sheen = hemisphere(mu, 400, |_, ci, hz| {
            let d = (2.0 + 1.0 / rs) * (1.0 - hz * hz).max(0.0).powf(0.5 / rs) / (2.0 * PI);
            d / (4.0 * (ci + mu - ci * mu)) * ci
        });
        let s_gpu = f64::from(cell[2]);
        assert!(
            (s_gpu - sheen).abs() < 5e-3 * sheen.max(0.2),
            "cell ({i},{j}): sheen {s_gpu} vs {sheen}"
        );
    }
}

/// Chi-square of the shader's sampler against its own pdf, which must also reject the same
/// sampler made 5% wrong; then each sample's weight and pdf against the evaluation.
fn check_layered(name: &str, s: ProbeSurface, theta_deg: f64) {
    let mut p = probe();
    let w = wo(theta_deg);
    bsdf_chi2(&p, name, &s, w, 6).unwrap_or_else(|e| panic!("{e}"));
    p.set_bias(Some(1));
    let biased = bsdf_chi2(&p, &format!("{name} (biased)"), &s, w, 6);
    assert!(
        biased.is_err(),
        "{name}: the chi-square test accepted a 5%-biased sampler"
    );
    p.set_bias(None);

    // The skin's subsurface lobe takes most samples at normal incidence, hence the count.
    let samples = p.bsdf_samples(&s, w, 20_000, 21).expect("samples");
    let dirs: Vec<[f32; 3]> = samples
        .iter()
        .filter(|x| x.valid && !x.subsurface)
        .map(|x| x.wi)
        .collect();
    let evals = p.bsdf_eval(&s, w, &dirs).expect("eval");
    let mut k = 0;
    for smp in samples.iter().filter(|x| x.valid && !x.subsurface) {
        let (f_cos, pdf) = evals[k];
        k += 1;
        assert!(
            (smp.pdf - pdf).abs() <= 1e-4 * pdf,
            "{name}: sampled pdf {} vs eval {pdf}",
            smp.pdf
        );
        for c in 0..3 {
            let want = f_cos[c] / pdf;
            assert!(
                (smp.weight[c] - want).abs() <= 1e-4 * want.max(1e-2),
                "{name}: weight {} vs f·cos/pdf {want}",
                smp.weight[c]
            );
        }
    }
    assert!(k > 1000, "{name}: only {k} valid directions");
}

#[test]
fn coat_lobe_matches_its_pdf() {
    let mut s = layered([0.0; 3]);
    s.coat = 1.0;
    s.coat_alpha = 0.09;
    s.coat_ior = 1.5;
    for theta in [20.0, 65.0] {
        check_layered(&format!("coat at {theta}°"), s, theta);
    }
}

#[test]
fn sheen_lobe_matches_its_pdf() {
    let mut s = layered([0.0; 3]);
    s.sheen = 1.0;
    s.sheen_rough = 0.3;
    for theta in [10.0, 70.0] {
        check_layered(&format!("sheen at {theta}°"), s, theta);
    }
}

#[test]
fn paper_skin_mixture_matches_its_pdf() {
    for theta in [0.0, 45.0, 80.0] {
        check_layered(&format!("skin at {theta}°"), paper_skin(), theta);
    }
}

/// Directional albedo of the surface lobes (f·cos integrated over the hemisphere) plus what the
/// subsurface lobe sends into the medium (its sample weight times its probability).
fn directional_albedo(p: &Probe, s: &ProbeSurface, theta_deg: f64) -> [f64; 3] {
    let w = wo(theta_deg);
    let (grid, d_omega) = integration_grid();
    let upper: Vec<[f32; 3]> = grid.into_iter().filter(|d| d[2] > 0.0).collect();
    let evals = p.bsdf_eval(s, w, &upper).expect("eval");
    let mut e = [0.0; 3];
    for (f, _) in &evals {
        for c in 0..3 {
            e[c] += f64::from(f[c]) * d_omega;
        }
    }
    let n = 20_000;
    let samples = p.bsdf_samples(s, w, n, 5).expect("samples");
    for smp in samples.iter().filter(|x| x.valid && x.subsurface) {
        for c in 0..3 {
            // The walk returns the subsurface colour of what enters (the slab test in
            // subsurface.rs shows it), so the energy the layer stack passes on is this.
            e[c] += f64::from(smp.weight[c] * s.sss_color[c]) / n as f64;
        }
    }
    e
}

/// White furnace of the layering: with every colour 1 the stack's directional albedo is 1 at
/// every angle, which holds only if each table entry is exactly the albedo of its lobe; with
/// random parameters it never exceeds 1.
#[test]
fn layered_albedo_is_one_when_white_and_never_above() {
    let p = probe();
    let mut white = paper_skin();
    white.base = [1.0; 3];
    white.sss_color = [1.0; 3];
    white.spec_color = [1.0; 3];
    white.coat = 0.5;
    white.sheen = 0.5;
    for theta in [0.0, 30.0, 60.0, 80.0] {
        let e = directional_albedo(&p, &white, theta);
        for c in 0..3 {
            assert!(
                (e[c] - 1.0).abs() < 0.01,
                "white stack at {theta}°: albedo {e:?}"
            );
        }
        let mut no_sss = white;
        no_sss.sss = 0.0;
        let e = directional_albedo(&p, &no_sss, theta);
        assert!(
            (e[0] - 1.0).abs() < 0.01,
            "white stack without subsurface at {theta}°: {e:?}"
        );
    }
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    for k in 0..12 {
        let s = ProbeSurface {
            base: [next(), next(), next()],
            metallic: if k % 3 == 0 { next() } else { 0.0 },
            alpha: next().powi(2).max(1e-3),
            specular: next(),
            spec_color: [next(), next(), next()],
            ior: 1.0 + 2.0 * next(),
            sss: next(),
            sss_color: [next(), next(), next()],
            coat: next(),
            coat_color: [next(), next(), next()],
            coat_alpha: next().powi(2).max(1e-3),
            coat_ior: 1.0 + next(),
            sheen: next(),
            sheen_color: [next(), next(), next()],
            sheen_rough: next(),
            ..paper_skin()
        };
        for theta in [5.0, 75.0] {
            let e = directional_albedo(&p, &s, theta);
            assert!(
                e.iter().all(|x| *x <= 1.005),
                "set {k} at {theta}°: albedo {e:?} for {s:?}"
            );
        }
    }
}
