//! Packs the lights at infinity — environment maps (HDRI + rotation/flip + sampling tables) and
//! the discs of the virtual light stage — into the flat arrays of `shaders/inc/env.wgsl`.

use lightfarm_light::{EnvSampler, EnvTransform, Hdri, OlatBasis};

use crate::gpu_types::{EnvDesc, ENV_DISC, ENV_MAP};

/// One lighting of a render: an HDRI and how it is oriented.
#[derive(Clone, Debug)]
pub struct EnvLight {
    /// What the user called it (file name), recorded in the output's metadata.
    pub name: String,
    pub hdri: Hdri,
    pub transform: EnvTransform,
}

/// A disc of constant radiance at infinity: one OLAT light of the virtual light stage. Rendered
/// analytically (exact radiance, sampled uniformly inside its cone), so 168 of them cost no
/// texel memory.
#[derive(Clone, Debug, PartialEq)]
pub struct DiscLight {
    pub name: String,
    /// World direction towards the disc's centre (unit).
    pub direction: [f32; 3],
    /// Angular radius, degrees.
    pub radius_deg: f64,
    pub radiance: [f32; 3],
}

impl DiscLight {
    /// Every light of `basis` in the world frame (the basis's directions are world directions:
    /// the stage does not turn with a sample's HDRI).
    pub fn olat(basis: &OlatBasis) -> Vec<DiscLight> {
        let l = basis.radiance() as f32;
        basis
            .directions
            .iter()
            .enumerate()
            .map(|(i, d)| DiscLight {
                name: format!("olat{i:03}"),
                direction: [d[0] as f32, d[1] as f32, d[2] as f32],
                radius_deg: basis.disc_deg,
                radiance: [l; 3],
            })
            .collect()
    }

    /// 1 − cos(radius), computed without cancellation.
    fn one_minus_cos(&self) -> f64 {
        let half = self.radius_deg.to_radians() * 0.5;
        2.0 * half.sin() * half.sin()
    }

    /// The disc's solid angle, sr.
    pub fn solid_angle(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.one_minus_cos()
    }
}

/// One lighting of a render, borrowed.
#[derive(Clone, Copy, Debug)]
pub enum Lighting<'a> {
    Map(&'a EnvLight),
    Disc(&'a DiscLight),
}

impl<'a> From<&'a EnvLight> for Lighting<'a> {
    fn from(l: &'a EnvLight) -> Self {
        Lighting::Map(l)
    }
}

impl<'a> From<&'a DiscLight> for Lighting<'a> {
    fn from(l: &'a DiscLight) -> Self {
        Lighting::Disc(l)
    }
}

#[derive(Default)]
pub struct PackedEnv {
    pub texels: Vec<[f32; 4]>,
    pub dist: Vec<f32>,
    pub desc: Vec<EnvDesc>,
}

pub fn pack_envs(lights: &[EnvLight]) -> PackedEnv {
    let lightings: Vec<Lighting> = lights.iter().map(Lighting::Map).collect();
    pack_lightings(&lightings)
}

pub fn pack_lightings(lights: &[Lighting]) -> PackedEnv {
    let mut out = PackedEnv::default();
    for light in lights {
        let light = match light {
            Lighting::Map(m) => m,
            Lighting::Disc(d) => {
                out.desc.push(disc_desc(d));
                continue;
            }
        };
        let hdri = &light.hdri;
        let sampler = EnvSampler::new(hdri);
        let dist = &sampler.dist;
        let texel_offset = out.texels.len() as u32;
        out.texels
            .extend(hdri.texels.iter().map(|t| [t[0], t[1], t[2], 0.0]));
        let cond_func_offset = out.dist.len() as u32;
        for row in &dist.conditional {
            out.dist.extend_from_slice(&row.func);
        }
        // Texel probabilities of the 2D distribution (marginal row × conditional column), for
        // O(1) sampling on the device; the pdf stays the piecewise-constant one above.
        let (w, h) = (hdri.width as usize, hdri.height as usize);
        let mut probs = Vec::with_capacity(w * h);
        for (y, row) in dist.conditional.iter().enumerate() {
            let p_row = if dist.marginal.integral > 0.0 {
                dist.marginal.func[y] as f64 / (dist.marginal.integral as f64 * h as f64)
            } else {
                1.0 / h as f64
            };
            for x in 0..w {
                let p_col = if row.integral > 0.0 {
                    row.func[x] as f64 / (row.integral as f64 * w as f64)
                } else {
                    1.0 / w as f64
                };
                probs.push(p_row * p_col);
            }
        }
        let alias_offset = out.dist.len() as u32;
        for (p, a) in alias_table(&probs) {
            out.dist.push(p);
            out.dist.push(f32::from_bits(a));
        }
        let theta = light.transform.rotation_deg.to_radians();
        out.desc.push(EnvDesc {
            width: hdri.width,
            height: hdri.height,
            texel_offset,
            cond_func_offset,
            alias_offset,
            kind: ENV_MAP,
            _pad1: 0,
            flip: light.transform.flip as u32,
            cos_rot: theta.cos(),
            sin_rot: theta.sin(),
            marg_integral: dist.marginal.integral,
            ..Default::default()
        });
    }
    out
}

fn disc_desc(d: &DiscLight) -> EnvDesc {
    let [x, y, z] = d.direction;
    let len = (x * x + y * y + z * z).sqrt();
    let axis = if len > 0.0 {
        [x / len, y / len, z / len]
    } else {
        [0.0, 1.0, 0.0]
    };
    EnvDesc {
        kind: ENV_DISC,
        disc: [axis[0], axis[1], axis[2], d.one_minus_cos() as f32],
        disc_radiance: [
            d.radiance[0],
            d.radiance[1],
            d.radiance[2],
            (1.0 / d.solid_angle()) as f32,
        ],
        ..Default::default()
    }
}

/// Walker's alias method (Vose's construction): for each cell, the probability of keeping it and
/// the cell to take otherwise. `probs` sums to 1.
fn alias_table(probs: &[f64]) -> Vec<(f32, u32)> {
    let n = probs.len();
    let mut scaled: Vec<f64> = probs.iter().map(|p| p * n as f64).collect();
    let mut table = vec![(1.0f32, 0u32); n];
    let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| scaled[i] < 1.0);
    while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
        table[s] = (scaled[s] as f32, l as u32);
        scaled[l] -= 1.0 - scaled[s];
        if scaled[l] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    // Leftovers are 1 up to rounding: keep them — except cells of probability 0, which rounding
    // can strand here when most of the map has none (compensated maps): send those elsewhere.
    let fallback = probs
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i as u32);
    for i in small.into_iter().chain(large) {
        table[i] = if probs[i] > 0.0 {
            (1.0, i as u32)
        } else {
            (0.0, fallback)
        };
    }
    table
}

#[cfg(test)]
mod tests {
    use super::alias_table;

    #[test]
    fn alias_table_reproduces_the_probabilities() {
        let probs = [0.5, 0.0, 0.125, 0.25, 0.125];
        let table = alias_table(&probs);
        let n = probs.len() as f64;
        let mut got = vec![0.0f64; probs.len()];
        for (i, (p, a)) in table.iter().enumerate() {
            got[i] += *p as f64 / n;
            got[*a as usize] += (1.0 - *p as f64) / n;
        }
        for (g, p) in got.iter().zip(probs) {
            assert!((g - p).abs() < 1e-6, "{got:?} vs {probs:?}");
        }
        assert_eq!(table[1].0, 0.0, "a zero-probability cell is never kept");
    }

    #[test]
    fn zero_cells_are_never_kept_even_when_rounding_strands_them() {
        // Mostly zeros and a few uneven cells: rounding leaves some cells on the worklists.
        let mut probs = vec![0.0f64; 1000];
        for (k, i) in [3usize, 77, 500, 999].iter().enumerate() {
            probs[*i] = [0.1, 0.2, 0.3, 0.4][k];
        }
        for (i, (keep, alias)) in alias_table(&probs).iter().enumerate() {
            if probs[i] == 0.0 {
                assert_eq!(*keep, 0.0, "cell {i} of probability 0 is kept");
            }
            assert!(
                probs[*alias as usize] > 0.0 || *keep == 1.0,
                "cell {i} aliases a zero cell"
            );
        }
    }
}
