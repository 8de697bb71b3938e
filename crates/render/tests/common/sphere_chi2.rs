//! The chi-square harness of the BSDF samplers: samples histogrammed over the sphere in
//! (cos θ, φ) cells, compared with the integral of the device's own pdf() per cell.
#![allow(dead_code)]

use std::f64::consts::PI;

use lightfarm_render::probe::{Probe, ProbeSurface};

pub const THETA_BINS: usize = 40;
pub const PHI_BINS: usize = 80;
pub const SUB: usize = 6;
pub const SAMPLES: usize = 1_000_000;

pub fn cell_of(d: [f32; 3]) -> Option<usize> {
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
pub fn integration_grid() -> (Vec<[f32; 3]>, f64) {
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

pub fn expected_from_pdf(pdfs: &[f64], d_omega: f64, n: usize) -> Vec<f64> {
    pdfs.chunks_exact(SUB * SUB)
        .map(|c| c.iter().sum::<f64>() * d_omega * n as f64)
        .collect()
}

/// Pearson's chi-square of `p`'s BSDF samples for `wo` against the integral of the device's own
/// pdf over each cell; also checks the pdf integrates to at most 1.
pub fn bsdf_chi2(
    p: &Probe,
    name: &str,
    s: &ProbeSurface,
    wo: [f32; 3],
    tests: u32,
) -> Result<f64, String> {
    let samples = p.bsdf_samples(s, wo, SAMPLES, 7).expect("sample");
    let mut observed = vec![0.0; THETA_BINS * PHI_BINS];
    for smp in samples.iter().filter(|s| s.valid) {
        if let Some(c) = cell_of(smp.wi) {
            observed[c] += 1.0;
        }
    }
    let (grid, d_omega) = integration_grid();
    let evals = p.bsdf_eval(s, wo, &grid).expect("eval");
    let pdfs: Vec<f64> = evals.iter().map(|e| e.1 as f64).collect();
    let expected = expected_from_pdf(&pdfs, d_omega, SAMPLES);
    let total: f64 = expected.iter().sum::<f64>() / SAMPLES as f64;
    assert!(total <= 1.01, "{name}: pdf integrates to {total} > 1");
    super::chi2_test(name, &observed, &expected, tests)
}
