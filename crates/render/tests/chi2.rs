//! Chi-square tests of the shaders' sampling routines, run on the device through the probe
//! kernel (pbrt-v4 bsdfs_test.cpp / Mitsuba 3 chi2.py style): samples are histogrammed over the
//! sphere in (cos θ, φ) cells and compared with the integral of the device's own pdf() per cell.

mod common;

use std::f64::consts::PI;

use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::probe::{Probe, ProbeSurface};
use lightfarm_render::EnvLight;

use common::bsdf_ref::{fresnel_dielectric, RefSurface};
use common::sphere_chi2::{bsdf_chi2, SAMPLES};

fn probe() -> Probe {
    Probe::new(&common::ctx()).expect("probe kernels")
}

/// The chi-square test of the shader's sampler, which must also reject the same sampler made
/// 5% wrong (so a pass means something); then the sampled pdfs and weights against the
/// independent CPU evaluation of the model at the sampled directions.
fn check_bsdf(name: &str, s: ProbeSurface, theta_o_deg: f32, tests: u32) {
    let mut p = probe();
    let t = theta_o_deg.to_radians();
    let wo = [t.sin(), 0.0, t.cos()];
    bsdf_chi2(&p, name, &s, wo, tests).unwrap_or_else(|e| panic!("{e}"));

    // wo lies in the xz plane, so the lobes are symmetric in y: biasing the y < 0 half puts
    // exactly half the probability there and the biased sampler is off by ±5% everywhere.
    p.set_bias(Some(1));
    let biased = bsdf_chi2(&p, &format!("{name} (5% biased sampler)"), &s, wo, tests);
    assert!(
        biased.is_err(),
        "{name}: the chi-square test accepted a sampler whose density is 5% off (p = {biased:?})"
    );
    p.set_bias(None);

    let reference = RefSurface::from(&s);
    let samples = p.bsdf_samples(&s, wo, 4000, 13).expect("sample");
    let mut valid = 0;
    for smp in samples.iter().filter(|s| s.valid) {
        valid += 1;
        let (f_cos, pdf) = reference.eval(wo, smp.wi);
        assert!(
            pdf > 0.0,
            "{name}: sampled {:?}, where the model's pdf is 0",
            smp.wi
        );
        let rel = (f64::from(smp.pdf) - pdf).abs() / pdf;
        assert!(
            rel < 2e-3,
            "{name}: sampled pdf {} vs the CPU model's {pdf} at {:?}",
            smp.pdf,
            smp.wi
        );
        for (k, (sw, f)) in smp.weight.iter().zip(f_cos).enumerate() {
            let w = f / pdf;
            assert!(
                (f64::from(*sw) - w).abs() <= 2e-3 * w.max(1e-2),
                "{name}: weight[{k}] {} vs the CPU model's f·cos/pdf {w} at {:?}",
                sw,
                smp.wi
            );
        }
    }
    // Rough lobes send many samples below the horizon (invalid): still enough to check.
    assert!(
        valid > 1000,
        "{name}: only {valid} of 4000 samples are valid"
    );
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
        ..Default::default()
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

/// Counts of (reflected, refracted) samples of a smooth dielectric, checking each direction
/// (mirror; Snell's law) and its weight (1; radiance scaled by 1/η² on refraction, pbrt's
/// radiance transport) exactly.
fn dielectric_counts(p: &Probe, s: &ProbeSurface, theta_deg: f64, n: usize) -> [f64; 2] {
    let t = theta_deg.to_radians();
    let wo = [t.sin() as f32, 0.0, t.cos() as f32];
    let eta = f64::from(s.ior);
    let mut counts = [0.0; 2];
    for smp in &p.bsdf_samples(s, wo, n, 3).expect("sample") {
        assert!(smp.valid && smp.delta, "dielectric samples are delta");
        if smp.wi[2] > 0.0 {
            counts[0] += 1.0;
            assert!(
                (smp.wi[0] + wo[0]).abs() < 1e-5 && (smp.wi[2] - wo[2]).abs() < 1e-5,
                "mirror direction"
            );
            assert_eq!(
                smp.weight, [1.0; 3],
                "a mirror reflection keeps the radiance"
            );
        } else {
            counts[1] += 1.0;
            let sin_t = (t.sin() / eta) as f32;
            assert!(
                (smp.wi[0] + sin_t).abs() < 1e-4,
                "Snell: sin θt {} vs {}",
                -smp.wi[0],
                sin_t
            );
            let w = 1.0 / (eta * eta);
            for c in smp.weight {
                assert!(
                    (f64::from(c) - w).abs() < 1e-5 * w,
                    "refraction weight {:?} vs 1/η² = {w}",
                    smp.weight
                );
            }
        }
    }
    counts
}

/// A smooth dielectric is a two-point distribution: reflection with probability F, refraction
/// (Snell's law) otherwise. Chi-square on the two outcomes against an independent Fresnel,
/// which must reject the sampler when it is made to redraw 10% of its refractions.
#[test]
fn smooth_dielectric_reflects_with_fresnel_probability() {
    let mut p = probe();
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
        let f = fresnel_dielectric(theta_deg.to_radians().cos(), ior as f64);
        let name = format!("dielectric θ={theta_deg} η={ior}");
        p.set_bias(None);
        let counts = dielectric_counts(&p, &s, theta_deg, n);
        let expected = [f * n as f64, (1.0 - f) * n as f64];
        if f < 1.0 {
            common::chi2_test(&name, &counts, &expected, 5).unwrap_or_else(|e| panic!("{e}"));
            p.set_bias(Some(2));
            let biased = dielectric_counts(&p, &s, theta_deg, n);
            let r = common::chi2_test(&name, &biased, &expected, 5);
            assert!(r.is_err(), "{name}: accepted a biased sampler: {r:?}");
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
        let mut p = probe();
        let probs = texel_probabilities(&p, &light);
        let total: f64 = probs.iter().sum();
        assert!((total - 1.0).abs() < 1e-3, "env pdf integrates to {total}");
        let chi2 = |p: &Probe| {
            let mut observed = vec![0.0; (w * h) as usize];
            for (d, pdf) in &p.env_samples(&light, SAMPLES, 11).expect("env samples") {
                assert!(*pdf > 0.0, "sampled direction with pdf 0");
                observed[env_bin(&light, *d, w, h)] += 1.0;
            }
            let expected: Vec<f64> = probs.iter().map(|q| q * SAMPLES as f64).collect();
            common::chi2_test(&format!("env {transform:?}"), &observed, &expected, 2)
        };
        chi2(&p).unwrap_or_else(|e| panic!("{e}"));
        p.set_bias(Some(most_balanced_axis(&light, &probs)));
        let biased = chi2(&p);
        assert!(
            biased.is_err(),
            "env {transform:?}: accepted a biased sampler: {biased:?}"
        );
    }
}

/// World direction of texel `i`'s centre.
fn texel_dir(light: &EnvLight, i: usize) -> [f32; 3] {
    let (w, h) = (light.hdri.width as usize, light.hdri.height as usize);
    light.transform.env_to_world(lightfarm_light::uv_to_dir([
        ((i % w) as f32 + 0.5) / w as f32,
        ((i / w) as f32 + 0.5) / h as f32,
    ]))
}

/// The world axis whose negative half holds the probability closest to 1/2, so that the
/// biased sampler (which redraws there) departs from the pdf as much as it can.
fn most_balanced_axis(light: &EnvLight, probs: &[f64]) -> usize {
    let mut q = [0.0f64; 3];
    for (i, p) in probs.iter().enumerate() {
        let d = texel_dir(light, i);
        for k in 0..3 {
            if d[k] < 0.0 {
                q[k] += p;
            }
        }
    }
    (0..3)
        .min_by(|&a, &b| (q[a] - 0.5).abs().total_cmp(&(q[b] - 0.5).abs()))
        .unwrap_or(0)
}

/// The same check on a real 1024×512 sun-and-sky map (half a million texels, one tiny sun),
/// binned into 64×32 cells: large maps stress the precision of the texel choice.
#[test]
fn environment_sampler_matches_its_pdf_on_a_real_map() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/hdri/rooitou_park_1k.hdr");
    let hdri = Hdri::load(&path).expect("built-in HDRI");
    let transform = EnvTransform {
        rotation_deg: 30.0,
        flip: false,
    };
    let light = EnvLight {
        name: "rooitou".into(),
        hdri,
        transform,
    };
    let mut p = probe();
    let n = 2_000_000;
    let (bw, bh) = (64u32, 32u32);
    let probs = texel_probabilities(&p, &light);
    let mut expected = vec![0.0; (bw * bh) as usize];
    for (i, q) in probs.iter().enumerate() {
        expected[env_bin(&light, texel_dir(&light, i), bw, bh)] += q * n as f64;
    }
    let chi2 = |p: &Probe| {
        let mut observed = vec![0.0; (bw * bh) as usize];
        for (d, _) in p.env_samples(&light, n, 5).expect("env samples") {
            observed[env_bin(&light, d, bw, bh)] += 1.0;
        }
        common::chi2_test("env rooitou_park", &observed, &expected, 1)
    };
    chi2(&p).unwrap_or_else(|e| panic!("{e}"));
    p.set_bias(Some(most_balanced_axis(&light, &probs)));
    let biased = chi2(&p);
    assert!(
        biased.is_err(),
        "env rooitou_park: accepted a biased sampler: {biased:?}"
    );
}

/// Bin of direction `d` in a disc of axis `a` and 1 − cos(radius) `omc`: `rings` equal-area
/// rings (uniform in 1 − cos θ) × `sectors` in azimuth; None outside the disc.
fn disc_bin(a: [f64; 3], omc: f64, d: [f32; 3], rings: usize, sectors: usize) -> Option<usize> {
    let d = [d[0] as f64, d[1] as f64, d[2] as f64];
    let cos_t = a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
    // Directions a rounding error past the axis (cos θ > 1 in f32) are at the centre.
    let ring = ((1.0 - cos_t).max(0.0) / omc * rings as f64).floor();
    if !(0.0..rings as f64).contains(&ring) {
        return None;
    }
    // Any fixed frame about the axis will do: bins are equal in area whatever its azimuth origin.
    let t = {
        let up = if a[1].abs() < 0.9 {
            [0.0, 1.0, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let c = [
            up[1] * a[2] - up[2] * a[1],
            up[2] * a[0] - up[0] * a[2],
            up[0] * a[1] - up[1] * a[0],
        ];
        let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        [c[0] / l, c[1] / l, c[2] / l]
    };
    let b = [
        a[1] * t[2] - a[2] * t[1],
        a[2] * t[0] - a[0] * t[2],
        a[0] * t[1] - a[1] * t[0],
    ];
    let x = d[0] * t[0] + d[1] * t[1] + d[2] * t[2];
    let y = d[0] * b[0] + d[1] * b[1] + d[2] * b[2];
    let phi = y.atan2(x).rem_euclid(2.0 * PI);
    let sector = ((phi / (2.0 * PI) * sectors as f64) as usize).min(sectors - 1);
    Some(ring as usize * sectors + sector)
}

/// A disc light (one OLAT light of the virtual light stage): every sample lies in its cone with
/// pdf 1/Ω, samples are uniform over the cone (equal-area bins), the pdf and radiance are those
/// values inside and zero outside; a sampler biased away from one half of the disc is rejected.
#[test]
fn disc_light_sampler_matches_its_pdf() {
    use lightfarm_render::DiscLight;
    // The disc straddles the plane x = 0, so the biased sampler (redrawing x < 0) departs from it.
    let l = (0.6f64 * 0.6 + 0.8 * 0.8).sqrt();
    let axis = [0.0, 0.6 / l, 0.8 / l];
    let disc = DiscLight {
        name: "olat".into(),
        direction: [axis[0] as f32, axis[1] as f32, axis[2] as f32],
        radius_deg: 4.0,
        radiance: [3.0, 2.0, 1.0],
    };
    let omc = 1.0 - 4f64.to_radians().cos();
    let omega = disc.solid_angle();
    assert!((omega - 2.0 * PI * omc).abs() < 1e-9 * omega);
    let (rings, sectors) = (8usize, 16usize);
    let mut p = probe();
    let chi2 = |p: &Probe| {
        let samples = p.env_samples(&disc, SAMPLES, 3).expect("disc samples");
        let mut observed = vec![0.0; rings * sectors];
        for (d, pdf) in &samples {
            assert!(
                ((*pdf as f64) * omega - 1.0).abs() < 1e-4,
                "disc pdf {pdf} is not 1/Ω = {}",
                1.0 / omega
            );
            // Samples on the rim may round a hair outside; they count in the outer ring.
            let bin = disc_bin(axis, omc * (1.0 + 1e-4), *d, rings, sectors)
                .unwrap_or_else(|| panic!("sample {d:?} outside the disc"));
            observed[bin] += 1.0;
        }
        let expected = vec![SAMPLES as f64 / (rings * sectors) as f64; rings * sectors];
        common::chi2_test("disc light", &observed, &expected, 1)
    };
    chi2(&p).unwrap_or_else(|e| panic!("{e}"));
    // pdf and radiance: inside (the axis, half the radius) and outside (twice the radius).
    let rot = |deg: f64| {
        let t = deg.to_radians();
        // Tilt the axis towards +x, which is perpendicular to it.
        [
            t.sin() as f32,
            (axis[1] * t.cos()) as f32,
            (axis[2] * t.cos()) as f32,
        ]
    };
    let evals = p
        .env_eval(&disc, &[rot(0.0), rot(2.0), rot(8.0), [0.0, -0.6, -0.8]])
        .expect("disc eval");
    for (k, (pdf, radiance)) in evals.iter().enumerate() {
        if k < 2 {
            assert!(
                ((*pdf as f64) * omega - 1.0).abs() < 1e-4,
                "pdf inside: {pdf}"
            );
            assert_eq!(*radiance, disc.radiance, "radiance inside");
        } else {
            assert_eq!(*pdf, 0.0, "pdf outside the disc");
            assert_eq!(*radiance, [0.0; 3], "radiance outside the disc");
        }
    }
    p.set_bias(Some(0));
    let biased = chi2(&p);
    assert!(
        biased.is_err(),
        "disc light: accepted a biased sampler: {biased:?}"
    );
}
