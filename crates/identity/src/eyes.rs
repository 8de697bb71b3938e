//! A person's eye texture: MakeHuman's eyeball texture with the iris recoloured from the
//! person's iris melanin (blue → green → hazel → brown, its own fibre pattern, a limbal ring)
//! and sclera vessels that grow denser with age.
//!
//! Iris colour is a palette keyed by stromal melanin rather than a spectral model: a blue
//! iris has almost no stromal melanin and is blue by scattering in the stroma, which a
//! Kubelka–Munk layer like the skin's does not reproduce. The palette stops are typical iris
//! colours (sRGB, converted to linear here); the brown source texture only lends its fibre
//! detail and pupil.

use lightfarm_render::scene::Texture;

use crate::makehuman::Image8;
use crate::skin::noise;

/// An iris of the source texture, in its pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Iris {
    pub centre: [f32; 2],
    pub radius: f32,
    /// Mean linear luminance of the iris annulus, which the fibre detail is taken relative to.
    pub mean_luminance: f32,
}

/// Pupil radius as a share of the iris radius (measured on MakeHuman's texture: 30 of 112 px).
const PUPIL: f32 = 0.28;

/// What makes one person's eyes theirs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeLook {
    /// 0 = blue (no stromal melanin) … 1 = dark brown.
    pub iris_melanin: f32,
    /// 0..1 visibility of sclera vessels.
    pub vessels: f32,
    pub seed: u64,
}

fn srgb_to_linear(s: f32) -> f32 {
    if s <= 0.04045 {
        s / 12.92
    } else {
        libm::powf((s + 0.055) / 1.055, 2.4)
    }
}

fn linear_to_srgb8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * libm::powf(x, 1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

fn luminance(rgb: [f32; 3]) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Iris colour stops (melanin, sRGB 0-255): blue, grey-green, green-hazel, light brown,
/// brown, dark brown.
const PALETTE: [(f32, [f32; 3]); 6] = [
    (0.0, [92.0, 124.0, 158.0]),
    (0.25, [108.0, 120.0, 104.0]),
    (0.45, [118.0, 108.0, 62.0]),
    (0.65, [118.0, 76.0, 38.0]),
    (0.85, [78.0, 46.0, 22.0]),
    (1.0, [44.0, 26.0, 13.0]),
];

/// Linear RGB of an iris with melanin `m`.
pub fn iris_colour(m: f32) -> [f32; 3] {
    let m = m.clamp(0.0, 1.0);
    let k = PALETTE
        .windows(2)
        .position(|w| m <= w[1].0)
        .unwrap_or(PALETTE.len() - 2);
    let ((m0, a), (m1, b)) = (PALETTE[k], PALETTE[k + 1]);
    let t = (m - m0) / (m1 - m0);
    [0, 1, 2].map(|c| srgb_to_linear((a[c] + (b[c] - a[c]) * t) / 255.0))
}

/// The two irises of an eyeball texture: the saturated opaque pixels, split in two by 2-means.
/// `None` if there are not two iris-sized blobs.
pub fn find_irises(tex: &Image8) -> Option<[Iris; 2]> {
    if tex.channels != 4 {
        return None;
    }
    let (w, h) = (tex.width as usize, tex.height as usize);
    let mut pts: Vec<([f32; 2], f32)> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let p = &tex.data[(y * w + x) * 4..(y * w + x) * 4 + 4];
            let rgb = [p[0], p[1], p[2]].map(|c| f32::from(c) / 255.0);
            let (mx, mn) = (
                rgb[0].max(rgb[1]).max(rgb[2]),
                rgb[0].min(rgb[1]).min(rgb[2]),
            );
            if p[3] >= 128 && mx > 0.05 && (mx - mn) / mx > 0.45 {
                let lin = rgb.map(srgb_to_linear);
                pts.push(([x as f32 + 0.5, y as f32 + 0.5], luminance(lin)));
            }
        }
    }
    let (first, last) = (pts.first()?.0, pts.last()?.0);
    let mut c = [first, last];
    let mut assign = vec![0usize; pts.len()];
    for _ in 0..20 {
        let mut sum = [[0.0f64; 2]; 2];
        let mut n = [0usize; 2];
        for (i, (p, _)) in pts.iter().enumerate() {
            let d = |q: [f32; 2]| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
            let k = usize::from(d(c[1]) < d(c[0]));
            assign[i] = k;
            sum[k][0] += f64::from(p[0]);
            sum[k][1] += f64::from(p[1]);
            n[k] += 1;
        }
        if n.contains(&0) {
            return None;
        }
        c = [0, 1].map(|k| {
            [
                (sum[k][0] / n[k] as f64) as f32,
                (sum[k][1] / n[k] as f64) as f32,
            ]
        });
    }
    let mut irises = [Iris {
        centre: [0.0; 2],
        radius: 0.0,
        mean_luminance: 0.0,
    }; 2];
    for k in 0..2 {
        let n = assign.iter().filter(|&&a| a == k).count();
        // A filled disc of the blob's area.
        let radius = (n as f32 / std::f32::consts::PI).sqrt();
        if !(0.02 * w as f32..0.25 * w as f32).contains(&radius) {
            return None;
        }
        let ring: Vec<f32> = pts
            .iter()
            .zip(&assign)
            .filter(|(_, &a)| a == k)
            .filter(|((p, _), _)| {
                let d = ((p[0] - c[k][0]).powi(2) + (p[1] - c[k][1]).powi(2)).sqrt() / radius;
                (0.4..0.9).contains(&d)
            })
            .map(|((_, l), _)| *l)
            .collect();
        let mean = ring.iter().sum::<f32>() / ring.len().max(1) as f32;
        irises[k] = Iris {
            centre: c[k],
            radius,
            mean_luminance: mean.max(1e-4),
        };
    }
    Some(irises)
}

/// Value noise periodic in x with `period` cells, so the iris pattern has no seam at angle 0.
fn periodic_noise(x: f32, y: f32, period: i32, seed: u64) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i32, fy as i32);
    let (tx, ty) = (x - fx, y - fy);
    let (tx, ty) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let at = |i: i32, j: i32| noise::lattice(i.rem_euclid(period), j, seed);
    let top = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * tx;
    let bottom = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * tx;
    top + (bottom - top) * ty
}

/// The person's eyeball texture at `size`², from the source `tex` and its `irises`.
pub fn eye_texture(tex: &Image8, irises: &[Iris; 2], look: &EyeLook, size: u32) -> Texture {
    let colour = iris_colour(look.iris_melanin);
    let s = look.seed;
    // Light irises often have a warmer ring around the pupil (central heterochromia).
    let warm_centre = (1.0 - look.iris_melanin) * 0.6 * noise::lattice(3, 5, s);
    let warm = iris_colour((look.iris_melanin + 0.45).min(1.0));
    let scale = tex.width as f32 / size as f32;
    let mut rgba8 = vec![0u8; (size * size * 4) as usize];
    for y in 0..size {
        for x in 0..size {
            let (u, v) = (
                (x as f32 + 0.5) / size as f32,
                1.0 - (y as f32 + 0.5) / size as f32,
            );
            let src = [0, 1, 2, 3].map(|c| tex.sample(u, v, c));
            let orig = [src[0], src[1], src[2]].map(srgb_to_linear);
            let p = [(x as f32 + 0.5) * scale, (y as f32 + 0.5) * scale];
            let (iris, d) = irises
                .iter()
                .map(|i| {
                    let r = ((p[0] - i.centre[0]).powi(2) + (p[1] - i.centre[1]).powi(2)).sqrt();
                    (i, r / i.radius)
                })
                .fold((&irises[0], f32::MAX), |a, b| if b.1 < a.1 { b } else { a });
            let mut out = orig;
            if d < 1.08 {
                let angle = libm::atan2f(p[1] - iris.centre[1], p[0] - iris.centre[0]);
                let turn = angle / std::f32::consts::TAU + 0.5;
                // Radial fibres: fine in angle, long in radius; crypts at a coarser scale.
                let fibre = periodic_noise(turn * 96.0, d * 5.0, 96, s ^ 0x1815) - 0.5;
                let crypt = periodic_noise(turn * 24.0, d * 3.0, 24, s ^ 0xC819) - 0.5;
                let detail = luminance(orig) / iris.mean_luminance;
                let limbal = 1.0 - 0.55 * smoothstep(0.82, 1.0, d);
                let centre_mix = warm_centre * (1.0 - smoothstep(0.35, 0.6, d));
                let base = [0, 1, 2].map(|c| colour[c] + (warm[c] - colour[c]) * centre_mix);
                let gain =
                    (0.6 + 0.4 * detail.min(2.5)) * (1.0 + 0.5 * fibre + 0.4 * crypt) * limbal;
                let recoloured = base.map(|c| (c * gain).max(0.0));
                // The pupil stays the source's black; the iris edge fades into the sclera.
                let w =
                    smoothstep(PUPIL - 0.02, PUPIL + 0.04, d) * (1.0 - smoothstep(0.98, 1.08, d));
                out = [0, 1, 2].map(|c| orig[c] + (recoloured[c] - orig[c]) * w);
            } else if d > 1.2 {
                // Vessels: ridges of a noise field, visible from the corners of the eye inward.
                let cell = 60.0 * iris.radius / 112.0;
                let q = [p[0] / cell, p[1] / cell];
                let n = noise::fbm(q[0], q[1], s ^ 0x7E55) + 0.5;
                let ridge = 1.0 - (2.0 * n - 1.0).abs();
                let line = smoothstep(0.95, 0.99, ridge);
                let vis = 0.6 * look.vessels * smoothstep(1.5, 2.4, d) * line;
                out = [
                    orig[0] * (1.0 - 0.25 * vis),
                    orig[1] * (1.0 - 0.7 * vis),
                    orig[2] * (1.0 - 0.7 * vis),
                ];
            }
            let i = ((y * size + x) * 4) as usize;
            for c in 0..3 {
                rgba8[i + c] = linear_to_srgb8(out[c]);
            }
            rgba8[i + 3] = 255;
        }
    }
    Texture {
        width: size,
        height: size,
        rgba8,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_runs_from_blue_to_dark_brown() {
        let blue = iris_colour(0.0);
        let brown = iris_colour(1.0);
        assert!(blue[2] > blue[0], "blue iris {blue:?}");
        assert!(brown[0] > brown[2], "brown iris {brown:?}");
        assert!(luminance(brown) < luminance(blue));
        // Continuous at the stops.
        let a = iris_colour(0.45 - 1e-4);
        let b = iris_colour(0.45 + 1e-4);
        assert!((0..3).all(|c| (a[c] - b[c]).abs() < 1e-3));
    }

    #[test]
    fn no_irises_in_a_grey_image() {
        let img = Image8 {
            width: 64,
            height: 64,
            channels: 4,
            data: vec![128; 64 * 64 * 4],
        };
        assert!(find_irises(&img).is_none());
    }
}
