//! What a render returns: the images of every lighting, the auxiliary passes resolved from the
//! integrator's accumulators, and what the render measured.

use crate::counters::TraversalCounts;
use crate::passes::{LitPasses, Pass};

/// What one render measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RenderStats {
    pub seconds: f64,
    /// Camera samples over all lightings: width × height × spp × lightings.
    pub samples: u64,
    pub samples_per_second: f64,
    /// Rays cast (camera, bounce, shadow and pass rays).
    pub rays: u64,
    pub rays_per_second: f64,
    pub device: String,
    pub device_kind: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub lightings: usize,
    /// Lightings traced on one set of camera paths (1 when traced separately).
    pub lightings_per_path: usize,
    pub triangles: usize,
    /// Fibre segments (hair, eyebrows) over all curve sets.
    pub curve_segments: usize,
    /// Geometry on the device: BVH nodes, triangle and segment data, bytes.
    pub geometry_bytes: u64,
    /// OLAT images rendered after the lightings (`RenderOutput::olat`), and their time (s).
    pub olat_lights: usize,
    pub olat_seconds: f64,
}

/// The passes of one render, row-major from the top-left pixel.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    pub width: u32,
    pub height: u32,
    /// One image per lighting.
    pub lit: Vec<Vec<[f32; 3]>>,
    pub albedo: Vec<[f32; 3]>,
    pub normal: Vec<[f32; 3]>,
    pub normal_lens: Vec<[f32; 3]>,
    pub mask: Vec<f32>,
    /// The passes asked for in the settings (sorted); the output writes exactly these.
    pub pass_set: Vec<Pass>,
    /// One per lighting when `pass_set` has a light-dependent pass, else empty.
    pub passes: Vec<LitPasses>,
    /// Per pixel: 0 background, else 1 + the object class of the first sample's surface
    /// (crate::passes::id_table); computed always, written when `pass_set` has `Id`.
    pub id: Vec<u32>,
    pub stats: RenderStats,
    /// The traversal counters, when the renderer counted (`Renderer::set_traversal_counters`).
    pub traversal: Option<TraversalCounts>,
    /// The subject under each light of the OLAT basis, when its caller rendered them too
    /// (`lightfarm_subject::render::render_sample`); written as half-float `olatNNN` layers.
    pub olat: Vec<Vec<[f32; 3]>>,
}

/// Progress of a render, reported after every dispatch.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub done: u64,
    pub total: u64,
}

/// The camera-ray passes of a render, resolved from the integrator's per-pixel sums
/// (`accum_aux`: (albedo, hits), (normal, 0), (normal_lens, lens hits), (id, ...)).
pub(crate) struct AuxImages {
    pub albedo: Vec<[f32; 3]>,
    pub normal: Vec<[f32; 3]>,
    pub normal_lens: Vec<[f32; 3]>,
    pub mask: Vec<f32>,
    pub id: Vec<u32>,
}

impl AuxImages {
    /// `sums` holds four vec4s per pixel accumulated over `spp` camera samples.
    pub fn resolve(sums: &[[f32; 4]], spp: f32) -> AuxImages {
        let normalize = |v: [f32; 4]| {
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if len > 0.0 {
                [v[0] / len, v[1] / len, v[2] / len]
            } else {
                [0.0; 3]
            }
        };
        let n = sums.len() / 4;
        let mut aux = AuxImages {
            albedo: Vec::with_capacity(n),
            normal: Vec::with_capacity(n),
            normal_lens: Vec::with_capacity(n),
            mask: Vec::with_capacity(n),
            id: Vec::with_capacity(n),
        };
        for px in sums.chunks_exact(4) {
            let a = px[0];
            let hits = a[3];
            aux.albedo.push(if hits > 0.0 {
                [a[0] / hits, a[1] / hits, a[2] / hits]
            } else {
                [0.0; 3]
            });
            aux.mask.push(hits / spp);
            aux.id.push(px[3][0] as u32);
            aux.normal.push(normalize(px[1]));
            aux.normal_lens.push(normalize(px[2]));
        }
        aux
    }
}

#[cfg(test)]
mod tests {
    use super::AuxImages;

    #[test]
    fn aux_sums_resolve_to_means_coverage_and_unit_normals() {
        // Pixel 0: 2 of 4 samples hit, albedo sum (1, 0.5, 0), normals summed unnormalised,
        // id 3. Pixel 1: background (no hit).
        let sums = [
            [1.0, 0.5, 0.0, 2.0],
            [0.0, 0.0, 3.0, 0.0],
            [0.0, 4.0, 0.0, 2.0],
            [3.0, 0.0, 0.0, 0.0],
            [0.0; 4],
            [0.0; 4],
            [0.0; 4],
            [0.0; 4],
        ];
        let aux = AuxImages::resolve(&sums, 4.0);
        assert_eq!(aux.albedo, vec![[0.5, 0.25, 0.0], [0.0; 3]]);
        assert_eq!(aux.mask, vec![0.5, 0.0]);
        assert_eq!(aux.normal, vec![[0.0, 0.0, 1.0], [0.0; 3]]);
        assert_eq!(aux.normal_lens, vec![[0.0, 1.0, 0.0], [0.0; 3]]);
        assert_eq!(aux.id, vec![3, 0]);
    }
}
