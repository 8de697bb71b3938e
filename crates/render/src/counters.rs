//! Traversal counters of a render (`Renderer::set_traversal_counters`): per pixel, what the rays
//! cast there cost the BVH traversal (shaders/inc/traverse.wgsl). The production integrator is
//! compiled without them; `integrator_counters` is the same source with them switched on, so a
//! render with counters casts the same rays and gives the same image.

use serde::Serialize;

/// Words per pixel after the renderer's four (shaders/kernels/integrator.wgsl `TC_WORDS`).
pub(crate) const TC_FIRST: usize = 4;
pub(crate) const TC_WORDS: usize = 7;

/// Per-pixel sums over every ray the pixel's paths cast (camera, bounce, shadow, walk, aux).
#[derive(Clone, Debug, Default)]
pub struct TraversalCounts {
    pub width: u32,
    pub height: u32,
    pub rays: Vec<u32>,
    /// Node tests (each tests one node's 8 child boxes).
    pub nodes: Vec<u32>,
    /// Triangle or fibre-segment intersection tests.
    pub prims: Vec<u32>,
    /// BLAS entries: instances whose bounds a ray reached in the TLAS.
    pub blas: Vec<u32>,
    /// Deepest traversal stack any of the pixel's rays reached (entries; BLAS stacks hold 24,
    /// TLAS stacks 8).
    pub max_depth: Vec<u32>,
    /// Pushes onto a full stack: each loses a subtree, so a hit may be missed.
    pub overflows: Vec<u32>,
    /// Rays with a NaN or infinite origin or direction: traced as misses, and a bug upstream
    /// (a NaN shading frame, say) wherever they appear.
    pub nonfinite: Vec<u32>,
}

/// Totals over the image, per ray.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct TraversalSummary {
    pub rays: u64,
    pub nodes_per_ray: f64,
    pub prims_per_ray: f64,
    pub blas_per_ray: f64,
    pub max_depth: u32,
    pub overflows: u64,
    pub nonfinite: u64,
}

impl TraversalCounts {
    pub(crate) fn from_words(words: &[u32], width: u32, height: u32) -> TraversalCounts {
        let pixels = width as usize * height as usize;
        let field = |k: usize| -> Vec<u32> {
            (0..pixels)
                .map(|p| words[TC_FIRST + TC_WORDS * p + k])
                .collect()
        };
        TraversalCounts {
            width,
            height,
            rays: field(0),
            nodes: field(1),
            prims: field(2),
            blas: field(3),
            max_depth: field(4),
            overflows: field(5),
            nonfinite: field(6),
        }
    }

    pub fn summary(&self) -> TraversalSummary {
        let sum = |v: &[u32]| v.iter().map(|&x| x as u64).sum::<u64>();
        let rays = sum(&self.rays);
        let per_ray = |v: &[u32]| sum(v) as f64 / rays.max(1) as f64;
        TraversalSummary {
            rays,
            nodes_per_ray: per_ray(&self.nodes),
            prims_per_ray: per_ray(&self.prims),
            blas_per_ray: per_ray(&self.blas),
            max_depth: self.max_depth.iter().copied().max().unwrap_or(0),
            overflows: sum(&self.overflows),
            nonfinite: sum(&self.nonfinite),
        }
    }

    /// Node tests per ray at each pixel.
    pub fn nodes_per_ray(&self) -> Vec<f32> {
        self.nodes
            .iter()
            .zip(&self.rays)
            .map(|(&n, &r)| if r > 0 { n as f32 / r as f32 } else { 0.0 })
            .collect()
    }

    /// A heat map of node tests per ray, RGB8 row-major: black (none) through blue, magenta and
    /// orange to white at `scale` node tests per ray (the image's maximum when `None`); pixels
    /// with a stack overflow are pure green.
    pub fn heat_map(&self, scale: Option<f32>) -> Vec<[u8; 3]> {
        let v = self.nodes_per_ray();
        let top = scale
            .unwrap_or_else(|| v.iter().copied().fold(0.0, f32::max))
            .max(1e-6);
        v.iter()
            .zip(&self.overflows)
            .map(|(&x, &o)| {
                if o > 0 {
                    return [0, 255, 0];
                }
                heat((x / top).clamp(0.0, 1.0))
            })
            .collect()
    }
}

/// Black → blue → magenta → orange → white.
fn heat(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.0],
        [0.1, 0.1, 0.8],
        [0.8, 0.1, 0.6],
        [1.0, 0.6, 0.1],
        [1.0, 1.0, 1.0],
    ];
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    let c = |k: usize| ((STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f) * 255.0).round() as u8;
    [c(0), c(1), c(2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_map_to_fields_and_the_summary_is_per_ray() {
        // Two pixels: 10 rays / 40 nodes / 20 prims / 10 blas / depth 3 / 0 overflows / 0
        // non-finite, and 30 rays / 200 nodes / 40 prims / 30 blas / depth 7 / 2 overflows / 5
        // non-finite.
        let mut words = vec![99u32; TC_FIRST];
        words.extend([10, 40, 20, 10, 3, 0, 0, 30, 200, 40, 30, 7, 2, 5]);
        let c = TraversalCounts::from_words(&words, 2, 1);
        assert_eq!(c.nodes, vec![40, 200]);
        assert_eq!(c.overflows, vec![0, 2]);
        assert_eq!(c.nonfinite, vec![0, 5]);
        let s = c.summary();
        assert_eq!(s.rays, 40);
        assert_eq!(s.nodes_per_ray, 6.0);
        assert_eq!(s.prims_per_ray, 1.5);
        assert_eq!(s.blas_per_ray, 1.0);
        assert_eq!(s.max_depth, 7);
        assert_eq!(s.overflows, 2);
        assert_eq!(s.nonfinite, 5);
        assert_eq!(c.nodes_per_ray(), vec![4.0, 200.0 / 30.0]);
        let heat = c.heat_map(Some(8.0));
        assert_eq!(heat[1], [0, 255, 0], "overflow marked");
        assert_eq!(heat[0], super::heat(0.5));
        assert_eq!(super::heat(0.0), [0, 0, 0]);
        assert_eq!(super::heat(1.0), [255, 255, 255]);
    }
}
