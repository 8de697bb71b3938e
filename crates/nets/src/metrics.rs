//! Evaluation metrics on host images (planar CHW, f32): MAE, MSE, SSIM, and the SH
//! lighting-recovery error of section 5.2.
//!
//! MAE/MSE/SSIM are computed on display values (sRGB-encoded, clamped to [0, 1]) over the whole
//! image, background included, as the paper's tables compare images a viewer sees.

// Channel and SH-band loops index several parallel arrays at once; iterators would hide that.
#![allow(clippy::needless_range_loop)]

/// A planar image: `data[c * width * height + y * width + x]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Planar {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Planar {
    pub fn at(&self, c: usize, x: usize, y: usize) -> f32 {
        self.data[(c * self.height + y) * self.width + x]
    }

    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// sRGB-encoded copy clamped to [0, 1] (the display values the metrics compare).
    pub fn display(&self) -> Planar {
        Planar {
            data: self.data.iter().map(|&v| srgb_encode(v)).collect(),
            ..self.clone()
        }
    }
}

/// Linear → sRGB transfer, clamped to [0, 1].
pub fn srgb_encode(v: f32) -> f32 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

pub fn mae(a: &Planar, b: &Planar) -> f64 {
    debug_assert_eq!(a.data.len(), b.data.len());
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| f64::from((x - y).abs()))
        .sum::<f64>()
        / a.data.len().max(1) as f64
}

pub fn mse(a: &Planar, b: &Planar) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| f64::from((x - y) * (x - y)))
        .sum::<f64>()
        / a.data.len().max(1) as f64
}

/// Mean SSIM over channels (Wang et al. 2004: 11×11 Gaussian window, σ = 1.5, K1 = 0.01,
/// K2 = 0.03, dynamic range 1), valid windows only.
pub fn ssim(a: &Planar, b: &Planar) -> f64 {
    const R: usize = 5;
    let g: Vec<f64> = (0..=2 * R)
        .map(|i| {
            let d = i as f64 - R as f64;
            (-d * d / (2.0 * 1.5 * 1.5)).exp()
        })
        .collect();
    let gsum: f64 = g.iter().sum();
    let g: Vec<f64> = g.iter().map(|v| v / gsum).collect();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    if a.width <= 2 * R || a.height <= 2 * R {
        return if mse(a, b) == 0.0 { 1.0 } else { 0.0 };
    }
    let (mut total, mut count) = (0f64, 0usize);
    for c in 0..a.channels {
        for y in R..a.height - R {
            for x in R..a.width - R {
                let (mut ma, mut mb, mut saa, mut sbb, mut sab) = (0f64, 0f64, 0f64, 0f64, 0f64);
                for (j, gy) in g.iter().enumerate() {
                    for (i, gx) in g.iter().enumerate() {
                        let w = gx * gy;
                        let va = f64::from(a.at(c, x + i - R, y + j - R));
                        let vb = f64::from(b.at(c, x + i - R, y + j - R));
                        ma += w * va;
                        mb += w * vb;
                        saa += w * va * va;
                        sbb += w * vb * vb;
                        sab += w * va * vb;
                    }
                }
                let (va, vb, cov) = (saa - ma * ma, sbb - mb * mb, sab - ma * mb);
                total += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                    / ((ma * ma + mb * mb + c1) * (va + vb + c2));
                count += 1;
            }
        }
    }
    total / count.max(1) as f64
}

/// Least-squares second-order SH irradiance (coefficients of E/π in camera space) explaining
/// `relit = albedo ⊙ E(normal)/π` on the pixels where `mask` > 0.5 and the albedo is not black.
/// Returns None when fewer than 9 usable pixels exist.
pub fn fit_sh_irradiance(
    relit: &Planar,
    albedo: &Planar,
    normal: &Planar,
    mask: &Planar,
) -> Option<[[f32; 3]; 9]> {
    let mut out = [[0f32; 3]; 9];
    for c in 0..3 {
        let mut ata = [[0f64; 9]; 9];
        let mut atb = [0f64; 9];
        let mut rows = 0usize;
        for y in 0..relit.height {
            for x in 0..relit.width {
                let a = albedo.at(c, x, y);
                if mask.at(0, x, y) <= 0.5 || a < 0.02 {
                    continue;
                }
                let n = [normal.at(0, x, y), normal.at(1, x, y), normal.at(2, x, y)];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                if len.is_nan() || len <= 0.5 {
                    continue;
                }
                let basis = lightfarm_light::sh9_basis(n.map(|v| v / len)).map(f64::from);
                let t = f64::from(relit.at(c, x, y) / a);
                for i in 0..9 {
                    atb[i] += basis[i] * t;
                    for j in 0..9 {
                        ata[i][j] += basis[i] * basis[j];
                    }
                }
                rows += 1;
            }
        }
        if rows < 9 {
            return None;
        }
        // A little ridge keeps bands the visible normals do not constrain (the back of the
        // head) at zero instead of exploding.
        let ridge = 1e-3 * (0..9).map(|i| ata[i][i]).sum::<f64>() / 9.0;
        for (i, row) in ata.iter_mut().enumerate() {
            row[i] += ridge;
        }
        let x = solve9(ata, atb)?;
        for k in 0..9 {
            out[k][c] = x[k] as f32;
        }
    }
    Some(out)
}

/// Section 5.2's lighting-recovery error: render a diffuse sphere (orthographic, camera at +Z)
/// with the estimated and the target irradiance, match the estimate's mean intensity to the
/// target's, and return the mean L1 difference over the disc relative to the target's mean.
pub fn sphere_error(estimated: &[[f32; 3]; 9], target: impl Fn([f32; 3]) -> [f32; 3]) -> f64 {
    const SIZE: usize = 64;
    let (mut est, mut tgt) = (Vec::new(), Vec::new());
    for y in 0..SIZE {
        for x in 0..SIZE {
            let px = (x as f32 + 0.5) / SIZE as f32 * 2.0 - 1.0;
            let py = 1.0 - (y as f32 + 0.5) / SIZE as f32 * 2.0;
            let r2 = px * px + py * py;
            if r2 >= 1.0 {
                continue;
            }
            let n = [px, py, (1.0 - r2).sqrt()];
            let basis = lightfarm_light::sh9_basis(n);
            let mut e = [0f32; 3];
            for k in 0..9 {
                for c in 0..3 {
                    e[c] += estimated[k][c] * basis[k];
                }
            }
            est.extend(e.map(|v| f64::from(v.max(0.0))));
            tgt.extend(target(n).map(|v| f64::from(v.max(0.0))));
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let (me, mt) = (mean(&est), mean(&tgt));
    if mt <= 0.0 {
        return 0.0;
    }
    let scale = if me > 0.0 { mt / me } else { 0.0 };
    let l1 = est
        .iter()
        .zip(&tgt)
        .map(|(e, t)| (e * scale - t).abs())
        .sum::<f64>()
        / est.len() as f64;
    l1 / mt
}

/// Gaussian elimination with partial pivoting; None when singular.
fn solve9(mut a: [[f64; 9]; 9], mut b: [f64; 9]) -> Option<[f64; 9]> {
    for col in 0..9 {
        let pivot = (col..9).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..9 {
            let f = a[row][col] / a[col][col];
            for k in col..9 {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0f64; 9];
    for row in (0..9).rev() {
        let s: f64 = (row + 1..9).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}
