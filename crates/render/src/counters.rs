//! Traversal counters of a render (`Renderer::set_traversal_counters`): per pixel, what the rays
//! cast there cost the BVH traversal (shaders/inc/traverse.wgsl). The production integrator is
//! compiled without them; `integrator_counters` is the same source with them switched on, so a
//! render with counters casts the same rays and gives the same image.

use serde::Serialize;

/// The renderer's own words come first (shaders/inc/bindings.wgsl `counters`), then TC_WORDS per
/// pixel (shaders/kernels/integrator.wgsl `TC_FIRST`, `TC_WORDS`).
pub(crate) const TC_FIRST: usize = 8;
pub(crate) const TC_WORDS: usize = 10;

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
    /// Turns of the BLAS traversal loop (each does a node test, a pop, or both, after the
    /// primitive tests it starts with).
    pub turns: Vec<u32>,
    /// Turns of the BLAS loop and of its primitive tests counted once per SIMD group, at the
    /// pixel of the group's first active invocation: only their sums over the image mean
    /// something.
    pub simd_turns: Vec<u32>,
    pub simd_prims: Vec<u32>,
    /// Invocations the device runs in lockstep (8 on lavapipe with 256-bit vectors, 32 on
    /// NVIDIA).
    pub simd_width: u32,
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
    pub simd_width: u32,
    /// Share of the SIMD group's lanes that took part in a turn of the BLAS loop, over every
    /// turn: the rest had left the loop already (their ray was done while another lane's was
    /// not) and waited. `None` without a turn.
    pub loop_lanes_busy: Option<f64>,
    /// The same for the primitive tests: lanes without a primitive to test wait while the
    /// others test theirs.
    pub prim_lanes_busy: Option<f64>,
}

impl TraversalCounts {
    pub(crate) fn from_words(
        words: &[u32],
        width: u32,
        height: u32,
        simd_width: u32,
    ) -> TraversalCounts {
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
            turns: field(7),
            simd_turns: field(8),
            simd_prims: field(9),
            simd_width,
        }
    }

    pub fn summary(&self) -> TraversalSummary {
        let sum = |v: &[u32]| v.iter().map(|&x| x as u64).sum::<u64>();
        let rays = sum(&self.rays);
        let per_ray = |v: &[u32]| sum(v) as f64 / rays.max(1) as f64;
        let busy = |lanes: &[u32], groups: &[u32]| {
            let turns = sum(groups) * self.simd_width as u64;
            (turns > 0).then(|| sum(lanes) as f64 / turns as f64)
        };
        TraversalSummary {
            rays,
            nodes_per_ray: per_ray(&self.nodes),
            prims_per_ray: per_ray(&self.prims),
            blas_per_ray: per_ray(&self.blas),
            max_depth: self.max_depth.iter().copied().max().unwrap_or(0),
            overflows: sum(&self.overflows),
            nonfinite: sum(&self.nonfinite),
            simd_width: self.simd_width,
            loop_lanes_busy: busy(&self.turns, &self.simd_turns),
            prim_lanes_busy: busy(&self.prims, &self.simd_prims),
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
        // non-finite / 60 turns / 10 SIMD turns / 5 SIMD primitive turns, and 30 rays / 200
        // nodes / 40 prims / 30 blas / depth 7 / 2 overflows / 5 non-finite / 260 turns / 30
        // SIMD turns / 10 SIMD primitive turns, in SIMD groups of 8.
        let mut words = vec![99u32; TC_FIRST];
        words.extend([10, 40, 20, 10, 3, 0, 0, 60, 10, 5]);
        words.extend([30, 200, 40, 30, 7, 2, 5, 260, 30, 10]);
        let c = TraversalCounts::from_words(&words, 2, 1, 8);
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
        assert_eq!(s.simd_width, 8);
        assert_eq!(s.loop_lanes_busy, Some(320.0 / (40.0 * 8.0)));
        assert_eq!(s.prim_lanes_busy, Some(60.0 / (15.0 * 8.0)));
        assert_eq!(c.nodes_per_ray(), vec![4.0, 200.0 / 30.0]);
        let heat = c.heat_map(Some(8.0));
        assert_eq!(heat[1], [0, 255, 0], "overflow marked");
        assert_eq!(heat[0], super::heat(0.5));
        assert_eq!(super::heat(0.0), [0, 0, 0]);
        assert_eq!(super::heat(1.0), [255, 255, 255]);
        let none = TraversalCounts::from_words(&[0; TC_FIRST + TC_WORDS], 1, 1, 8).summary();
        assert_eq!((none.loop_lanes_busy, none.prim_lanes_busy), (None, None));
    }
}
