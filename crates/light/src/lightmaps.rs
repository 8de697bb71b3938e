//! Prefiltered environments for the relighting network's light maps (paper section 4.1).
//!
//! Per HDRI, once: second-order SH of the radiance (diffuse irradiance is exact to a few percent
//! at order 2, Ramamoorthi & Hanrahan 2001) and Phong-prefiltered lat-long maps
//! P_n(r) = ∫ L(ω) max(0, r·ω)^n dω / ∫ max(0, r·ω)^n dω for n = 1, 16, 32, 64, 1024.
//! Both are in env-local directions, so one set serves every rotation and flip of that HDRI:
//! the per-sample transform is applied to the lookup direction instead (see `nets::lightmap`).
//!
//! The Phong integral is a windowed direct sum over the texels of a box-downsampled copy of the
//! map, weighted by each texel's solid angle and normalised by the discrete weight sum, so a
//! constant environment gives exactly that constant and no energy is lost to the window.

use crate::hdri::Hdri;
use crate::mapping::{dir_to_uv, uv_to_dir};

/// The Phong exponents of the paper: 1/16/32/64 are looked up with the normal N, 1024 with the
/// lens normal N_l (glare on glasses).
pub const PHONG_EXPONENTS: [u32; 5] = [1, 16, 32, 64, 1024];

/// Weights below this fraction of the lobe peak are outside the convolution window. HDRIs span
/// 10^5 in radiance (a softbox next to a dark wall), so 1e-4 visibly darkened dim directions.
const WINDOW_CUTOFF: f64 = 1e-6;

/// Real SH basis, bands 0..=2, in the usual (l, m) order; `d` must be unit length.
pub fn sh9_basis(d: [f32; 3]) -> [f32; 9] {
    let [x, y, z] = d;
    [
        0.282_094_8,
        0.488_602_5 * y,
        0.488_602_5 * z,
        0.488_602_5 * x,
        1.092_548_4 * x * y,
        1.092_548_4 * y * z,
        0.315_391_57 * (3.0 * z * z - 1.0),
        1.092_548_4 * x * z,
        0.546_274_2 * (x * x - y * y),
    ]
}

/// Clamped-cosine convolution factors Â_l per band, divided by π so that a constant
/// environment of 1 has irradiance/π = 1 (the diffuse light map is radiance-scaled).
const COSINE_BAND: [f32; 3] = [1.0, 2.0 / 3.0, 0.25];

/// Band of each of the nine coefficients.
const BAND_OF: [usize; 9] = [0, 1, 1, 1, 2, 2, 2, 2, 2];

/// Second-order SH projection of an environment's radiance (env-local frame).
#[derive(Clone, Debug, PartialEq)]
pub struct ShRadiance {
    /// L_lm per RGB channel.
    pub coeffs: [[f32; 3]; 9],
}

impl ShRadiance {
    /// L_lm = Σ_texels L(ω) Y_lm(ω) ΔΩ with the exact solid angle of each lat-long texel.
    pub fn project(hdri: &Hdri) -> ShRadiance {
        let (w, h) = (hdri.width as usize, hdri.height as usize);
        let mut acc = [[0f64; 3]; 9];
        for row in 0..h {
            let d_omega = texel_solid_angle(row, w, h);
            for col in 0..w {
                let dir = uv_to_dir([(col as f32 + 0.5) / w as f32, (row as f32 + 0.5) / h as f32]);
                let y = sh9_basis(dir);
                let l = hdri.texels[row * w + col];
                for (k, yk) in y.iter().enumerate() {
                    for c in 0..3 {
                        acc[k][c] += f64::from(l[c]) * f64::from(*yk) * d_omega;
                    }
                }
            }
        }
        ShRadiance {
            coeffs: acc.map(|c| c.map(|v| v as f32)),
        }
    }

    /// The nine coefficients of E(n)/π, the diffuse light map's polynomial in the normal.
    pub fn irradiance_coeffs(&self) -> [[f32; 3]; 9] {
        let mut out = self.coeffs;
        for (k, c) in out.iter_mut().enumerate() {
            for v in c.iter_mut() {
                *v *= COSINE_BAND[BAND_OF[k]];
            }
        }
        out
    }

    /// Irradiance over π at env-local unit normal `n`: a white Lambertian surface's radiance.
    pub fn irradiance(&self, n: [f32; 3]) -> [f32; 3] {
        let y = sh9_basis(n);
        let mut out = [0f32; 3];
        for (k, c) in self.irradiance_coeffs().iter().enumerate() {
            for ch in 0..3 {
                out[ch] += c[ch] * y[k];
            }
        }
        out
    }

    /// Mean radiance over the sphere (L_00 · Y_00): the scale the trainer normalises HDRIs by.
    pub fn mean_radiance(&self) -> [f32; 3] {
        self.coeffs[0].map(|c| c * 0.282_094_8)
    }
}

/// One Phong-prefiltered lat-long map, row 0 at the top as in [`Hdri`].
#[derive(Clone, Debug, PartialEq)]
pub struct PrefilteredMap {
    pub exponent: u32,
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[f32; 3]>,
}

impl PrefilteredMap {
    /// Bilinear lookup at env-local direction `d`, wrapping in longitude; matches the device
    /// lookup in `nets` (texel centres at half-integers).
    pub fn lookup(&self, d: [f32; 3]) -> [f32; 3] {
        let [u, v] = dir_to_uv(d);
        let x = u * self.width as f32 - 0.5;
        let y = (v * self.height as f32 - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let col = |c: f32| (c as i64).rem_euclid(w) as usize;
        let row = |r: f32| (r as usize).min(self.height - 1);
        let at = |r: usize, c: usize| self.texels[r * self.width + c];
        let (c0, c1, r0, r1) = (col(x0), col(x0 + 1.0), row(y0), row(y0 + 1.0));
        let mut out = [0f32; 3];
        for (ch, o) in out.iter_mut().enumerate() {
            let top = at(r0, c0)[ch] * (1.0 - fx) + at(r0, c1)[ch] * fx;
            let bottom = at(r1, c0)[ch] * (1.0 - fx) + at(r1, c1)[ch] * fx;
            *o = top * (1.0 - fy) + bottom * fy;
        }
        out
    }
}

/// Everything the light maps of one HDRI need.
#[derive(Clone, Debug, PartialEq)]
pub struct PrefilteredEnv {
    pub sh: ShRadiance,
    /// One map per entry of [`PHONG_EXPONENTS`], in that order.
    pub phong: Vec<PrefilteredMap>,
}

impl PrefilteredEnv {
    /// SH projection plus the five Phong maps at their default resolutions.
    pub fn compute(hdri: &Hdri) -> PrefilteredEnv {
        let phong = PHONG_EXPONENTS
            .iter()
            .map(|&n| {
                let (out_w, in_w) = default_resolution(n);
                prefilter_phong(hdri, n, out_w, in_w)
            })
            .collect();
        PrefilteredEnv {
            sh: ShRadiance::project(hdri),
            phong,
        }
    }

    /// The prefiltered maps of the sum of two environments, from theirs: projection and
    /// prefiltering are linear. Lights switched on together (OLAT pairs) cost an addition, not
    /// a prefilter. None when the two were prefiltered at different resolutions.
    pub fn sum(&self, other: &PrefilteredEnv) -> Option<PrefilteredEnv> {
        if self.phong.len() != other.phong.len() {
            return None;
        }
        let mut sh = self.sh.coeffs;
        for (a, b) in sh.iter_mut().zip(&other.sh.coeffs) {
            for c in 0..3 {
                a[c] += b[c];
            }
        }
        let phong = self
            .phong
            .iter()
            .zip(&other.phong)
            .map(|(a, b)| {
                (a.exponent == b.exponent && a.width == b.width && a.height == b.height).then(
                    || PrefilteredMap {
                        exponent: a.exponent,
                        width: a.width,
                        height: a.height,
                        texels: a
                            .texels
                            .iter()
                            .zip(&b.texels)
                            .map(|(x, y)| [x[0] + y[0], x[1] + y[1], x[2] + y[2]])
                            .collect(),
                    },
                )
            })
            .collect::<Option<Vec<_>>>()?;
        Some(PrefilteredEnv {
            sh: ShRadiance { coeffs: sh },
            phong,
        })
    }
}

/// (output width, input width) per exponent: the lobe's half-maximum angle spans at least two
/// input texels and one output texel, so narrow lobes get finer maps.
pub fn default_resolution(exponent: u32) -> (usize, usize) {
    match exponent {
        0..=1 => (32, 64),
        2..=64 => (64, 128),
        65..=256 => (128, 256),
        _ => (256, 512),
    }
}

/// Phong-prefilters `hdri` with exponent `n` into a `out_w`×`out_w/2` map, convolving a copy
/// box-downsampled to `in_w` wide (or the original when it is smaller). Runs on every core.
pub fn prefilter_phong(hdri: &Hdri, n: u32, out_w: usize, in_w: usize) -> PrefilteredMap {
    let src = downsample(hdri, in_w.min(hdri.width as usize).max(2));
    let (sw, sh) = (src.width as usize, src.height as usize);
    let out_w = out_w.max(2);
    let out_h = (out_w / 2).max(1);

    // Per source texel: direction and solid angle, precomputed once.
    let dirs: Vec<[f64; 3]> = (0..sw * sh)
        .map(|i| {
            let d = uv_to_dir([
                ((i % sw) as f32 + 0.5) / sw as f32,
                ((i / sw) as f32 + 0.5) / sh as f32,
            ]);
            d.map(f64::from)
        })
        .collect();
    let row_omega: Vec<f64> = (0..sh).map(|r| texel_solid_angle(r, sw, sh)).collect();
    let row_theta: Vec<f64> = (0..sh)
        .map(|r| std::f64::consts::PI * (r as f64 + 0.5) / sh as f64)
        .collect();
    let cos_min = WINDOW_CUTOFF.powf(1.0 / f64::from(n.max(1)));
    let window = cos_min.clamp(-1.0, 1.0).acos();
    let half_row = std::f64::consts::PI / sh as f64 / 2.0;
    let half_col = std::f64::consts::PI / sw as f64;

    let convolve = |out_row: usize, texels: &mut [[f32; 3]]| {
        let theta_r = std::f64::consts::PI * (out_row as f64 + 0.5) / out_h as f64;
        for (out_col, texel) in texels.iter_mut().enumerate() {
            let r = uv_to_dir([
                (out_col as f32 + 0.5) / out_w as f32,
                (out_row as f32 + 0.5) / out_h as f32,
            ])
            .map(f64::from);
            let centre = ((out_col as f64 + 0.5) / out_w as f64 * sw as f64).floor() as i64;
            let (mut acc, mut wsum) = ([0f64; 3], 0f64);
            for row in 0..sh {
                let theta_i = row_theta[row];
                // Rows whose whole band is farther than the window cannot contribute.
                if (theta_i - theta_r).abs() > window + half_row {
                    continue;
                }
                let cols =
                    match longitude_half_span(theta_r, theta_i, window + half_row, half_col, sw) {
                        Some(span) => centre - span..centre + span + 1,
                        None => 0..sw as i64,
                    };
                for c in cols {
                    let col = c.rem_euclid(sw as i64) as usize;
                    let d = &dirs[row * sw + col];
                    let cos = r[0] * d[0] + r[1] * d[1] + r[2] * d[2];
                    if cos <= 0.0 {
                        continue;
                    }
                    let wgt = cos.powi(n as i32) * row_omega[row];
                    let l = src.texels[row * sw + col];
                    for ch in 0..3 {
                        acc[ch] += wgt * f64::from(l[ch]);
                    }
                    wsum += wgt;
                }
            }
            *texel = if wsum > 0.0 {
                acc.map(|a| (a / wsum) as f32)
            } else {
                [0.0; 3]
            };
        }
    };

    let mut texels = vec![[0f32; 3]; out_w * out_h];
    let threads = std::thread::available_parallelism()
        .map_or(1, |p| p.get())
        .min(out_h);
    let rows_per = out_h.div_ceil(threads);
    std::thread::scope(|s| {
        for (chunk_index, chunk) in texels.chunks_mut(rows_per * out_w).enumerate() {
            let convolve = &convolve;
            s.spawn(move || {
                for (i, row) in chunk.chunks_mut(out_w).enumerate() {
                    convolve(chunk_index * rows_per + i, row);
                }
            });
        }
    });
    PrefilteredMap {
        exponent: n,
        width: out_w,
        height: out_h,
        texels,
    }
}

/// How many source columns either side of the output direction's column can lie within
/// `window` of it, for a source row at polar angle `theta_i` (spherical law of cosines solved
/// for the longitude difference); `None` when the whole row can.
fn longitude_half_span(
    theta_r: f64,
    theta_i: f64,
    window: f64,
    half_col: f64,
    sw: usize,
) -> Option<i64> {
    let (sr, si) = (theta_r.sin(), theta_i.sin());
    if sr * si < 1e-9 {
        return None;
    }
    let cos_dphi = (window.cos() - theta_r.cos() * theta_i.cos()) / (sr * si);
    if cos_dphi <= -1.0 {
        return None;
    }
    let dphi = cos_dphi.min(1.0).acos() + half_col;
    let span = (dphi / (2.0 * std::f64::consts::PI) * sw as f64).ceil() as i64 + 1;
    (2 * span + 1 < sw as i64).then_some(span)
}

/// Exact solid angle of a texel in row `row` of a `w`×`h` lat-long map.
fn texel_solid_angle(row: usize, w: usize, h: usize) -> f64 {
    let t0 = std::f64::consts::PI * row as f64 / h as f64;
    let t1 = std::f64::consts::PI * (row + 1) as f64 / h as f64;
    2.0 * std::f64::consts::PI / w as f64 * (t0.cos() - t1.cos())
}

/// Area-weighted box downsample to `out_w`×`out_w/2` (solid-angle weights across rows, so the
/// mean radiance over the sphere is preserved); a no-op copy when the size already matches.
pub fn downsample(hdri: &Hdri, out_w: usize) -> Hdri {
    let (w, h) = (hdri.width as usize, hdri.height as usize);
    let out_h = (out_w / 2).max(1);
    if out_w == w && out_h == h {
        return hdri.clone();
    }
    let xs = overlaps(w, out_w);
    let ys = overlaps(h, out_h);
    let mut texels = vec![[0f32; 3]; out_w * out_h];
    for (oy, yr) in ys.iter().enumerate() {
        for (ox, xr) in xs.iter().enumerate() {
            let (mut acc, mut wsum) = ([0f64; 3], 0f64);
            for &(sy, wy) in yr {
                let wy = wy * texel_solid_angle(sy, w, h);
                for &(sx, wx) in xr {
                    let l = hdri.texels[sy * w + sx];
                    let wgt = wx * wy;
                    for ch in 0..3 {
                        acc[ch] += wgt * f64::from(l[ch]);
                    }
                    wsum += wgt;
                }
            }
            texels[oy * out_w + ox] = acc.map(|a| if wsum > 0.0 { (a / wsum) as f32 } else { 0.0 });
        }
    }
    Hdri {
        width: out_w as u32,
        height: out_h as u32,
        texels,
    }
}

/// For each of `n_out` equal cells over `n_in` source cells: (source index, overlap length).
fn overlaps(n_in: usize, n_out: usize) -> Vec<Vec<(usize, f64)>> {
    let scale = n_in as f64 / n_out as f64;
    (0..n_out)
        .map(|o| {
            let (a, b) = (o as f64 * scale, (o + 1) as f64 * scale);
            let mut v = Vec::new();
            let mut i = a.floor() as usize;
            while (i as f64) < b && i < n_in {
                let overlap = (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0);
                if overlap > 0.0 {
                    v.push((i, overlap));
                }
                i += 1;
            }
            v
        })
        .collect()
}
