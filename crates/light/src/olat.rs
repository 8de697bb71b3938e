//! The virtual light stage's one-light-at-a-time basis (Yeh et al. 2022, appendix "OLAT"): N
//! lights spread uniformly over the sphere, each a small disc of equal radiance and equal power
//! wherever it falls in the lat-long map, and the projection of any environment map onto them
//! (Debevec et al. 2000: each light stands for the part of the sphere nearest to it).
//!
//! One definition for everything that uses OLAT lighting: renders of the basis and the
//! synthetic-to-real OLAT consistency losses.

use std::f64::consts::PI;

use crate::hdri::Hdri;
use crate::load::LightError;
use crate::mapping::{uv_to_dir, EnvTransform};

/// The paper's light count.
pub const OLAT_LIGHTS: usize = 168;
/// Angular radius of each light's disc; well inside its share of the sphere at 168 lights
/// (neighbours are ≥ 13° apart).
pub const OLAT_DISC_DEG: f64 = 4.0;
/// Name of the sample layer that holds the image under OLAT light `i` (`olat000` …; the
/// channels are `.R`, `.G`, `.B`).
pub fn olat_layer(i: usize) -> String {
    format!("olat{i:03}")
}

/// Side of the sub-texel grid that measures how much of a texel a disc covers.
const SUBSAMPLES: u32 = 8;

/// The basis: light directions (env-local, unit), the disc radius and the lat-long size of
/// the maps.
#[derive(Clone, Debug, PartialEq)]
pub struct OlatBasis {
    pub directions: Vec<[f64; 3]>,
    pub disc_deg: f64,
    pub width: u32,
    pub height: u32,
}

/// Fibonacci-spiral directions: area-uniform in y (the polar axis of the lat-long
/// convention), successive lights a golden angle apart in azimuth.
pub fn olat_directions(n: usize) -> Vec<[f64; 3]> {
    let golden = PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - (2 * i + 1) as f64 / n as f64;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f64;
            [r * phi.sin(), y, -r * phi.cos()]
        })
        .collect()
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Solid angle of lat-long row `y` of a map `height` rows tall, per texel of a `width`-wide row.
fn texel_solid_angle(y: u32, width: u32, height: u32) -> f64 {
    let t0 = PI * y as f64 / height as f64;
    let t1 = PI * (y + 1) as f64 / height as f64;
    2.0 * PI / width as f64 * (t0.cos() - t1.cos())
}

fn texel_dir(x: f64, y: f64, width: u32, height: u32) -> [f64; 3] {
    let d = uv_to_dir([(x / width as f64) as f32, (y / height as f64) as f32]);
    [d[0] as f64, d[1] as f64, d[2] as f64]
}

impl OlatBasis {
    /// `n` lights as `width` × `height` maps. Refuses a basis whose discs would reach into a
    /// neighbour's share of the sphere (then projection could not recover a sum of lights).
    pub fn new(n: usize, disc_deg: f64, width: u32, height: u32) -> Result<OlatBasis, LightError> {
        let bad = |reason: String| Err(LightError::InvalidOlat { reason });
        if n < 2 {
            return bad(format!("{n} lights: a basis needs at least 2"));
        }
        if !(disc_deg > 0.0 && disc_deg < 90.0) {
            return bad(format!("disc radius {disc_deg}°: use a value in (0, 90)"));
        }
        if width != 2 * height || height == 0 {
            return bad(format!("{width}x{height} maps: lat-long maps are 2:1"));
        }
        let directions = olat_directions(n);
        let mut min_sep = PI;
        for (i, a) in directions.iter().enumerate() {
            for b in &directions[i + 1..] {
                min_sep = min_sep.min(dot(*a, *b).clamp(-1.0, 1.0).acos());
            }
        }
        let texel = (2.0 * PI / width as f64).hypot(PI / height as f64);
        let reach = disc_deg.to_radians() + texel;
        if reach >= min_sep / 2.0 {
            return bad(format!(
                "{n} lights are {:.2}° apart at the closest, so a {disc_deg}° disc at \
                 {width}x{height} ({:.2}° texels) reaches a neighbour's share: use fewer lights, \
                 a smaller disc or a larger map",
                min_sep.to_degrees(),
                texel.to_degrees()
            ));
        }
        Ok(OlatBasis {
            directions,
            disc_deg,
            width,
            height,
        })
    }

    /// The paper's basis: 168 lights, discs of `OLAT_DISC_DEG`, 512 × 256 maps.
    pub fn paper() -> OlatBasis {
        OlatBasis::new(OLAT_LIGHTS, OLAT_DISC_DEG, 512, 256).expect("the paper's basis is valid")
    }

    pub fn len(&self) -> usize {
        self.directions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.directions.is_empty()
    }

    /// What each light emits, ∫ L dω: the lights together emit what a uniform white
    /// environment of radiance 1 does (4π), so all of them on light a subject about as a
    /// white furnace does.
    pub fn power(&self) -> f64 {
        4.0 * PI / self.len() as f64
    }

    /// Radiance inside each disc.
    pub fn radiance(&self) -> f64 {
        self.power() / (2.0 * PI * (1.0 - self.disc_deg.to_radians().cos()))
    }

    /// Light `i` as a lat-long map: each texel holds the disc's radiance times the fraction of
    /// the texel the disc covers, so the light has the same radiance wherever it falls, and the
    /// map is then scaled so that it emits exactly `power()`, whatever the latitude.
    pub fn map(&self, i: usize) -> Hdri {
        let (w, h) = (self.width, self.height);
        let c = self.directions[i];
        let cos_disc = self.disc_deg.to_radians().cos();
        // Rows and columns the disc can touch (its angular radius plus a texel of margin).
        let reach = self.disc_deg.to_radians() + (2.0 * PI / w as f64).hypot(PI / h as f64);
        let theta = c[1].clamp(-1.0, 1.0).acos();
        let y0 = (((theta - reach) / PI * h as f64).floor().max(0.0)) as u32;
        let y1 = (((theta + reach) / PI * h as f64).ceil() as u32).min(h);
        let mut texels = vec![[0f32; 3]; (w * h) as usize];
        let mut emitted = 0.0;
        let l = self.radiance();
        let s = SUBSAMPLES as f64;
        for y in y0..y1 {
            let omega = texel_solid_angle(y, w, h);
            for x in 0..w {
                // Cheap reject: the texel's centre is far from the disc.
                if dot(texel_dir(x as f64 + 0.5, y as f64 + 0.5, w, h), c) < (reach + 0.05).cos() {
                    continue;
                }
                let mut inside = 0u32;
                for sy in 0..SUBSAMPLES {
                    for sx in 0..SUBSAMPLES {
                        let d = texel_dir(
                            x as f64 + (sx as f64 + 0.5) / s,
                            y as f64 + (sy as f64 + 0.5) / s,
                            w,
                            h,
                        );
                        inside += (dot(d, c) >= cos_disc) as u32;
                    }
                }
                if inside > 0 {
                    let v = l * inside as f64 / (s * s);
                    texels[(y * w + x) as usize] = [v as f32; 3];
                    emitted += v * omega;
                }
            }
        }
        let scale = (self.power() / emitted) as f32;
        for t in &mut texels {
            for ch in t.iter_mut() {
                *ch *= scale;
            }
        }
        Hdri {
            width: w,
            height: h,
            texels,
        }
    }

    /// The weight of each light that relights like `env` posed by `transform` (the render's
    /// rotation and flip): the power `env` sends from the part of the sphere nearest to that
    /// light, over the light's own power. Relit = Σ weightᵢ × (image under light i).
    pub fn weights(&self, env: &Hdri, transform: &EnvTransform) -> Vec<[f64; 3]> {
        let mut out = vec![[0f64; 3]; self.len()];
        let (w, h) = (env.width, env.height);
        for y in 0..h {
            let omega = texel_solid_angle(y, w, h);
            for x in 0..w {
                let t = env.texels[(y * w + x) as usize];
                if t == [0.0; 3] {
                    continue;
                }
                let e = texel_dir(x as f64 + 0.5, y as f64 + 0.5, w, h);
                let d = transform.env_to_world([e[0] as f32, e[1] as f32, e[2] as f32]);
                let d = [d[0] as f64, d[1] as f64, d[2] as f64];
                let nearest = self.nearest(d);
                for ch in 0..3 {
                    out[nearest][ch] += t[ch] as f64 * omega;
                }
            }
        }
        let p = self.power();
        for o in &mut out {
            for ch in o.iter_mut() {
                *ch /= p;
            }
        }
        out
    }

    /// The relit image: Σ weightᵢ × imageᵢ per channel, as a light stage forms any lighting
    /// from its one-light-at-a-time images (Debevec et al. 2000). `images[i]` is the render
    /// under light i; all are the same size.
    pub fn relight(
        &self,
        weights: &[[f64; 3]],
        images: &[&[[f32; 3]]],
    ) -> Result<Vec<[f32; 3]>, LightError> {
        let bad = |reason: String| Err(LightError::InvalidOlat { reason });
        if weights.len() != self.len() || images.len() != self.len() {
            return bad(format!(
                "{} weights and {} images for a basis of {} lights",
                weights.len(),
                images.len(),
                self.len()
            ));
        }
        let n = images.first().map_or(0, |i| i.len());
        if let Some(i) = images.iter().position(|i| i.len() != n) {
            return bad(format!(
                "OLAT image {i} has {} pixels, image 0 has {n}",
                images[i].len()
            ));
        }
        let mut out = vec![[0f64; 3]; n];
        for (w, img) in weights.iter().zip(images) {
            if *w == [0.0; 3] {
                continue;
            }
            for (o, p) in out.iter_mut().zip(img.iter()) {
                for ch in 0..3 {
                    o[ch] += w[ch] * p[ch] as f64;
                }
            }
        }
        Ok(out
            .into_iter()
            .map(|o| [o[0] as f32, o[1] as f32, o[2] as f32])
            .collect())
    }

    /// The light whose direction is closest to `d` (unit).
    pub fn nearest(&self, d: [f64; 3]) -> usize {
        let mut best = (f64::MIN, 0);
        for (i, c) in self.directions.iter().enumerate() {
            let cd = dot(*c, d);
            if cd > best.0 {
                best = (cd, i);
            }
        }
        best.1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn integral(m: &Hdri) -> f64 {
        let mut sum = 0.0;
        for y in 0..m.height {
            let omega = texel_solid_angle(y, m.width, m.height);
            for x in 0..m.width {
                sum += m.texels[(y * m.width + x) as usize][0] as f64 * omega;
            }
        }
        sum
    }

    #[test]
    fn directions_are_unit_and_spread_over_the_sphere() {
        let d = olat_directions(OLAT_LIGHTS);
        assert_eq!(d.len(), 168);
        let mut mean = [0.0; 3];
        for v in &d {
            assert!((dot(*v, *v) - 1.0).abs() < 1e-12);
            for k in 0..3 {
                mean[k] += v[k] / d.len() as f64;
            }
        }
        assert!(dot(mean, mean).sqrt() < 0.01, "mean direction {mean:?}");
        // Every cap of the sphere holds its share: the upper hemisphere about half.
        let up = d.iter().filter(|v| v[1] > 0.0).count();
        assert_eq!(up, 84);
        assert_eq!(OlatBasis::paper().len(), OLAT_LIGHTS);
    }

    #[test]
    fn every_light_emits_the_same_power_at_the_same_radiance() {
        let b = OlatBasis::paper();
        let analytic = b.radiance();
        // The lights nearest the pole, the equator and in between.
        let by_height = |y: f64| {
            (0..b.len())
                .min_by(|&i, &j| {
                    (b.directions[i][1] - y)
                        .abs()
                        .total_cmp(&(b.directions[j][1] - y).abs())
                })
                .expect("lights")
        };
        for i in [
            by_height(1.0),
            by_height(0.7),
            by_height(0.0),
            by_height(-0.95),
        ] {
            let m = b.map(i);
            assert!((integral(&m) / b.power() - 1.0).abs() < 1e-5, "light {i}");
            let peak = m.texels.iter().map(|t| t[0]).fold(0.0, f32::max) as f64;
            // The scaling that makes the power exact is a small correction of the rasterised
            // disc: the radiance at its centre is the disc's radiance within 3 %.
            assert!(
                (peak / analytic - 1.0).abs() < 0.03,
                "light {i}: peak {peak} vs {analytic}"
            );
            assert!(
                b.nearest(b.directions[i]) == i
                    && m.texels.iter().filter(|t| t[0] > 0.0).count() > 20,
                "light {i} covers too few texels"
            );
        }
    }

    #[test]
    fn projection_recovers_a_sum_of_lights_under_any_pose() {
        let b = OlatBasis::new(OLAT_LIGHTS, OLAT_DISC_DEG, 256, 128).expect("basis");
        let coeff = |i: usize| [(i % 7) as f64 * 0.3, (i % 3) as f64, 0.5];
        let chosen = [0usize, 5, 40, 83, 84, 120, 167];
        let mut texels = vec![[0f32; 3]; (b.width * b.height) as usize];
        for &i in &chosen {
            let m = b.map(i);
            for (t, v) in texels.iter_mut().zip(&m.texels) {
                for ch in 0..3 {
                    t[ch] += v[ch] * coeff(i)[ch] as f32;
                }
            }
        }
        let env = Hdri::from_texels(b.width, b.height, texels).expect("map");
        let w = b.weights(&env, &EnvTransform::default());
        for (i, wi) in w.iter().enumerate() {
            let want = if chosen.contains(&i) {
                coeff(i)
            } else {
                [0.0; 3]
            };
            for ch in 0..3 {
                assert!(
                    (wi[ch] - want[ch]).abs() < 1e-4,
                    "light {i}: {wi:?} vs {want:?}"
                );
            }
        }
        // A constant white environment weighs every light about equally (its share of the
        // sphere), and in all exactly 4π / power.
        let white = b.weights(
            &Hdri::constant(256, 128, [1.0; 3]),
            &EnvTransform::default(),
        );
        let total: f64 = white.iter().map(|x| x[0]).sum();
        assert!((total - b.len() as f64).abs() < 1e-3, "total {total}");
        assert!(
            white.iter().all(|x| (0.6..1.4).contains(&x[0])),
            "{white:?}"
        );
        // A rotation moves the light: the rotated sum projects onto other lights.
        let turned = b.weights(
            &env,
            &EnvTransform {
                rotation_deg: 90.0,
                flip: false,
            },
        );
        assert!((0..b.len()).any(|i| (turned[i][2] - w[i][2]).abs() > 0.1));
    }

    #[test]
    fn relighting_sums_the_weighted_images_and_refuses_a_mismatch() {
        let b = OlatBasis::new(4, 10.0, 256, 128).expect("basis");
        let imgs: Vec<Vec<[f32; 3]>> = (0..4)
            .map(|i| vec![[i as f32, 1.0, 2.0 * i as f32]; 3])
            .collect();
        let refs: Vec<&[[f32; 3]]> = imgs.iter().map(|v| v.as_slice()).collect();
        let w = [
            [1.0, 0.0, 0.5],
            [0.0, 2.0, 0.0],
            [0.25, 0.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let out = b.relight(&w, &refs).expect("relight");
        assert_eq!(out, vec![[0.5, 2.0, 6.0]; 3]);
        let e = b
            .relight(&w[..3], &refs)
            .expect_err("3 weights")
            .to_string();
        assert!(e.contains("3 weights"), "{e}");
        let short = [refs[0], refs[1], refs[2], &imgs[3][..2]];
        let e = b.relight(&w, &short).expect_err("sizes").to_string();
        assert!(e.contains("OLAT image 3 has 2 pixels"), "{e}");
    }

    #[test]
    fn bases_that_cannot_separate_their_lights_are_refused() {
        for (n, disc, w, h, needle) in [
            (1, 4.0, 512, 256, "at least 2"),
            (168, 0.0, 512, 256, "disc radius"),
            (168, 4.0, 500, 256, "2:1"),
            (168, 10.0, 512, 256, "reaches a neighbour"),
            (2000, 4.0, 512, 256, "reaches a neighbour"),
            (168, 4.0, 64, 32, "reaches a neighbour"),
        ] {
            let e = OlatBasis::new(n, disc, w, h)
                .expect_err("refused")
                .to_string();
            assert!(e.contains(needle), "{n} {disc} {w}x{h}: {e}");
        }
    }
}
