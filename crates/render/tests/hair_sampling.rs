//! The fibre model (shaders/inc/hair.wgsl) on the device: the white furnace over random wo and
//! h, chi-square of its sampler against its own pdf over (sin θ, φ) cells of the fibre frame,
//! and the sampled pdf and weight against the evaluated ones.

mod common;

use std::f64::consts::PI;

use lightfarm_render::probe::{Probe, ProbeFibre};

const BETAS: [f32; 4] = [0.1, 0.3, 0.6, 0.9];
const TILTS_DEG: [f32; 2] = [0.0, 2.0];

fn probe() -> Probe {
    Probe::new(&common::ctx()).expect("probe kernels")
}

fn fibre(beta_m: f32, beta_n: f32, tilt_deg: f32, sigma_a: [f32; 3], h: f32) -> ProbeFibre {
    ProbeFibre {
        sigma_a,
        beta_m,
        beta_n,
        alpha: tilt_deg.to_radians(),
        ior: 1.55,
        h,
    }
}

/// σa per unit radius of melanin m (no redness), as lightfarm_render::hair maps it.
fn melanin(m: f32) -> [f32; 3] {
    lightfarm_render::hair::sigma_a_from_melanin(m, 0.0)
}

#[test]
fn white_furnace_fibre_returns_one_for_every_roughness_and_tilt() {
    let p = probe();
    let n = 1 << 20;
    let mut worst = (0.0f64, String::new());
    for (k, (&bm, (&bn, &tilt))) in BETAS
        .iter()
        .flat_map(|bm| {
            BETAS
                .iter()
                .flat_map(move |bn| TILTS_DEG.iter().map(move |t| (bm, (bn, t))))
        })
        .enumerate()
    {
        let f = fibre(bm, bn, tilt, [0.0; 3], 0.0);
        let est = p.fibre_furnace(&f, n, 100 + k as u32).expect("furnace");
        let mut sum = [0.0f64; 3];
        let mut sq = 0.0f64;
        for e in &est {
            for c in 0..3 {
                sum[c] += f64::from(e[c]);
            }
            sq += f64::from(e[0]) * f64::from(e[0]);
        }
        let mean = sum.map(|s| s / n as f64);
        let se = ((sq / n as f64 - mean[0] * mean[0]) / n as f64).sqrt();
        let name = format!("βm {bm}, βn {bn}, α {tilt}°");
        for c in 0..3 {
            assert!(
                (mean[c] - 1.0).abs() < 0.01,
                "{name}: furnace {:?} (standard error {se:.1e}), not 1 ± 0.01",
                mean
            );
        }
        // Colourless: the three channels see the same fibre.
        assert!((mean[0] - mean[2]).abs() < 1e-6, "{name}: {mean:?}");
        if (mean[0] - 1.0).abs() > worst.0 {
            worst = (
                (mean[0] - 1.0).abs(),
                format!("{name}: {:.4} ± {se:.1e}", mean[0]),
            );
        }
    }
    eprintln!("furnace: largest deviation {}", worst.1);
}

#[test]
fn fibre_furnace_sees_absorption() {
    // The estimator is not 1 by construction: with melanin the fibre absorbs, blue most.
    let p = probe();
    let est = p
        .fibre_furnace(&fibre(0.3, 0.3, 2.0, melanin(0.5), 0.0), 1 << 18, 3)
        .expect("furnace");
    let mean: Vec<f64> = (0..3)
        .map(|c| est.iter().map(|e| f64::from(e[c])).sum::<f64>() / est.len() as f64)
        .collect();
    assert!(
        mean[0] < 0.9 && mean[2] < mean[1] && mean[1] < mean[0],
        "{mean:?}"
    );
    // R alone (about 5% at these angles) is a floor no absorption removes.
    assert!(mean[2] > 0.03, "{mean:?}");
}

const THETA_BINS: usize = 40;
const PHI_BINS: usize = 80;
const SUB_T: usize = 8;
const SUB_P: usize = 16;
const SAMPLES: usize = 1_000_000;

/// Cell of a fibre-frame direction: sin θ = x in THETA_BINS equal steps, φ = atan2(z, y).
fn cell_of(d: [f32; 3]) -> Option<usize> {
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if !len.is_finite() || len <= 0.0 {
        return None;
    }
    let x = f64::from(d[0] / len).clamp(-1.0, 1.0);
    let mut phi = f64::from(d[2]).atan2(f64::from(d[1]));
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let i = ((x + 1.0) * 0.5 * THETA_BINS as f64)
        .floor()
        .min(THETA_BINS as f64 - 1.0) as usize;
    let j = (phi / (2.0 * PI) * PHI_BINS as f64)
        .floor()
        .min(PHI_BINS as f64 - 1.0) as usize;
    Some(i * PHI_BINS + j)
}

/// Sub-cell centres of every cell (finer in φ, where smooth fibres are narrowest) and the solid
/// angle of each: cells are equal-area in (sin θ, φ).
fn grid() -> (Vec<[f32; 3]>, f64) {
    let mut dirs = Vec::with_capacity(THETA_BINS * PHI_BINS * SUB_T * SUB_P);
    for i in 0..THETA_BINS {
        for j in 0..PHI_BINS {
            for a in 0..SUB_T {
                for b in 0..SUB_P {
                    let x = -1.0
                        + 2.0 * (i as f64 + (a as f64 + 0.5) / SUB_T as f64) / THETA_BINS as f64;
                    let phi =
                        2.0 * PI * (j as f64 + (b as f64 + 0.5) / SUB_P as f64) / PHI_BINS as f64;
                    let r = (1.0 - x * x).max(0.0).sqrt();
                    dirs.push([x as f32, (r * phi.cos()) as f32, (r * phi.sin()) as f32]);
                }
            }
        }
    }
    (
        dirs,
        4.0 * PI / (THETA_BINS * PHI_BINS * SUB_T * SUB_P) as f64,
    )
}

fn fibre_chi2(
    p: &Probe,
    name: &str,
    f: &ProbeFibre,
    wo: [f32; 3],
    tests: u32,
    seed: u32,
) -> Result<f64, String> {
    let samples = p.fibre_samples(f, wo, SAMPLES, seed).expect("sample");
    let mut observed = vec![0.0; THETA_BINS * PHI_BINS];
    for s in samples.iter().filter(|s| s.valid) {
        if let Some(c) = cell_of(s.wi) {
            observed[c] += 1.0;
        }
    }
    let (dirs, d_omega) = grid();
    let evals = p.fibre_eval(f, wo, &dirs).expect("eval");
    let expected: Vec<f64> = evals
        .chunks_exact(SUB_T * SUB_P)
        .map(|c| c.iter().map(|e| f64::from(e.1)).sum::<f64>() * d_omega * SAMPLES as f64)
        .collect();
    let total = expected.iter().sum::<f64>() / SAMPLES as f64;
    if (total - 1.0).abs() > 0.01 {
        return Err(format!("{name}: the pdf integrates to {total}, not 1"));
    }
    common::chi2_test(name, &observed, &expected, tests)
}

fn wo_at(theta_deg: f32, phi_deg: f32) -> [f32; 3] {
    let (t, ph) = (theta_deg.to_radians(), phi_deg.to_radians());
    [t.sin(), t.cos() * ph.cos(), t.cos() * ph.sin()]
}

#[test]
fn fibre_sampler_matches_its_pdf_over_the_grid() {
    let p = probe();
    // Each roughness and tilt with one of three melanin values in turn (every value meets
    // every roughness), so the suite stays within its time budget.
    let melanins = [0.0f32, 0.5, 0.95];
    let tests = (BETAS.len() * BETAS.len() * TILTS_DEG.len()) as u32;
    let mut k = 0;
    let mut failures = Vec::new();
    for &bm in &BETAS {
        for &bn in &BETAS {
            for &tilt in &TILTS_DEG {
                {
                    k += 1;
                    let m = melanins[k as usize % melanins.len()];
                    // Vary wo and h over the grid rather than fixing one.
                    let wo = wo_at(
                        -50.0 + 97.0 * (k as f32 * 0.618).fract(),
                        360.0 * (k as f32 * 0.414).fract(),
                    );
                    let h = -0.95 + 1.9 * (k as f32 * 0.7548).fract();
                    let f = fibre(bm, bn, tilt, melanin(m), h);
                    let name =
                        format!("βm {bm}, βn {bn}, α {tilt}°, melanin {m}, h {h:.2}, wo {wo:?}");
                    if let Err(e) = fibre_chi2(&p, &name, &f, wo, tests, k) {
                        failures.push(e);
                    }
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {tests} failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn fibre_chi2_rejects_a_five_percent_biased_sampler() {
    let mut p = probe();
    p.set_bias(Some(2));
    // wo in the fibre's xy plane and h = 0: the fibre is mirror-symmetric in z, so redrawing
    // z < 0 samples moves the density 5% everywhere.
    for &(bm, bn) in &[(0.1f32, 0.1f32), (0.3, 0.3), (0.9, 0.6)] {
        let f = fibre(bm, bn, 2.0, melanin(0.3), 0.0);
        let r = fibre_chi2(&p, "biased", &f, wo_at(20.0, 0.0), 3, 5);
        assert!(
            r.is_err(),
            "βm {bm}, βn {bn}: a 5% biased sampler passed (p = {r:?})"
        );
    }
}

#[test]
fn sampled_pdf_and_weight_equal_the_evaluated_ones() {
    let p = probe();
    let mut k = 0u32;
    for &bm in &BETAS {
        for &bn in &BETAS {
            for &m in &[0.0f32, 0.4, 0.9] {
                k += 1;
                let f = fibre(bm, bn, 2.0, melanin(m), -0.9 + 0.3 * (k % 7) as f32);
                let wo = wo_at(-70.0 + 10.0 * (k % 15) as f32, 23.0 * k as f32);
                let samples = p.fibre_samples(&f, wo, 2000, 40 + k).expect("sample");
                let wis: Vec<[f32; 3]> = samples.iter().map(|s| s.wi).collect();
                let evals = p.fibre_eval(&f, wo, &wis).expect("eval");
                let mut valid = 0;
                for (s, (f_cos, pdf)) in samples.iter().zip(&evals) {
                    if !s.valid {
                        continue;
                    }
                    valid += 1;
                    assert!(
                        *pdf > 0.0,
                        "βm {bm} βn {bn}: sampled {:?} where the pdf is 0",
                        s.wi
                    );
                    let rel = (s.pdf - pdf).abs() / pdf;
                    assert!(
                        rel < 1e-4,
                        "βm {bm} βn {bn}: sampled pdf {} vs evaluated {pdf}",
                        s.pdf
                    );
                    for (sw, f) in s.weight.iter().zip(f_cos) {
                        let w = f / pdf;
                        assert!(
                            (sw - w).abs() <= 1e-4 * w.max(1e-3),
                            "βm {bm} βn {bn}: weight {:?} vs f·cos/pdf {w}",
                            s.weight
                        );
                    }
                    // No absorption: the weight is exactly 1 (the sampler is the model's pdf).
                    if m == 0.0 {
                        assert!((s.weight[0] - 1.0).abs() < 1e-4, "{:?}", s.weight);
                    }
                }
                assert!(
                    valid > 1990,
                    "βm {bm} βn {bn}: {valid} of 2000 samples valid"
                );
            }
        }
    }
}

#[test]
fn smooth_black_fibre_reflects_like_a_mirror_cylinder() {
    // Black (no light comes back out of the fibre), nearly smooth, untilted: every sample is R,
    // the mirror image of wo about the cylinder normal at h, n = cos γ ŵ - sin γ (t × ŵ) with
    // γ = asin h and ŵ the unit projection of wo across the fibre (x = t).
    let p = probe();
    for &h in &[-0.8f32, -0.3, 0.0, 0.5, 0.9] {
        let f = fibre(0.02, 0.02, 0.0, [40.0; 3], h);
        let wo = wo_at(25.0, 40.0);
        let w_hat = {
            let (y, z) = (wo[1], wo[2]);
            let l = (y * y + z * z).sqrt();
            [0.0, y / l, z / l]
        };
        // t × ŵ with t = x: (0, -ŵz, ŵy).
        let t_x_w = [0.0, -w_hat[2], w_hat[1]];
        let g = h.asin();
        let n: Vec<f32> = (0..3)
            .map(|i| g.cos() * w_hat[i] - g.sin() * t_x_w[i])
            .collect();
        let d = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2];
        let mirror: Vec<f32> = (0..3).map(|i| 2.0 * d * n[i] - wo[i]).collect();
        let samples = p.fibre_samples(&f, wo, 4000, 9).expect("sample");
        let mut cos: Vec<f32> = samples
            .iter()
            .filter(|s| s.valid)
            .map(|s| s.wi[0] * mirror[0] + s.wi[1] * mirror[1] + s.wi[2] * mirror[2])
            .collect();
        cos.sort_by(f32::total_cmp);
        let median = cos[cos.len() / 2];
        assert!(
            median > 0.995,
            "h {h}: samples cluster {:.2}° from the mirror direction {mirror:?}",
            median.clamp(-1.0, 1.0).acos().to_degrees()
        );
    }
}

#[test]
fn tilted_scales_shift_the_primary_highlight_toward_the_root() {
    // x runs from root to tip. A smooth black fibre reflects only R, whose peak sits at
    // θi = -θo - 2α: toward the root (-x) for a positive tilt, as on real hair (Marschner 2003)
    // and in Cycles.
    let p = probe();
    let (theta_o, tilt) = (20.0f32, 5.0f32);
    for (t, want) in [
        (tilt, -theta_o - 2.0 * tilt),
        (-tilt, -theta_o + 2.0 * tilt),
        (0.0, -theta_o),
    ] {
        let f = fibre(0.02, 0.3, t, [40.0; 3], 0.3);
        let samples = p
            .fibre_samples(&f, wo_at(theta_o, 30.0), 4000, 17)
            .expect("sample");
        let mut theta: Vec<f32> = samples
            .iter()
            .filter(|s| s.valid)
            .map(|s| s.wi[0].clamp(-1.0, 1.0).asin().to_degrees())
            .collect();
        theta.sort_by(f32::total_cmp);
        let median = theta[theta.len() / 2];
        assert!(
            (median - want).abs() < 1.0,
            "tilt {t}°: R peaks at θi {median}°, not {want}°"
        );
    }
}
