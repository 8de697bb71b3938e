//!include inc/bindings.wgsl
//!include inc/rng.wgsl
//!include inc/frame.wgsl
//!include inc/bsdf.wgsl
//!include inc/layered.wgsl
//!include inc/hair.wgsl

// Directional albedo tables of the layered model's lobes, computed once per device from the
// lobes' own code (so the albedo scaling removes exactly the energy those lobes reflect):
// cell (μ, r) of LUT_N × LUT_N, μ = cos θo at cell centres, r = roughness on grid points,
// probe_out[r_index · LUT_N + μ_index] = (A, B, E_sheen, 0) where a GGX lobe with Schlick F0
// reflects F0·A + B (α = r²) and the Charlie sheen of roughness r reflects E_sheen.
// Deterministic: 64 × 64 midpoint strata per cell, of the visible-normal sampler for GGX and of
// (cos θi, φ) for the sheen.

const TABLE_STRATA: u32 = 64u;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= LUT_N * LUT_N) {
        return;
    }
    let mu = (f32(i % LUT_N) + 0.5) / f32(LUT_N);
    let rough = f32(i / LUT_N) / f32(LUT_N - 1u);
    let wo = vec3<f32>(sqrt(max(0.0, 1.0 - mu * mu)), 0.0, mu);
    let alpha = max(rough * rough, 1e-4);
    var a = 0.0;
    var b = 0.0;
    var sheen = 0.0;
    let n = TABLE_STRATA * TABLE_STRATA;
    for (var j = 0u; j < n; j++) {
        let u = (vec2<f32>(f32(j % TABLE_STRATA), f32(j / TABLE_STRATA)) + vec2<f32>(0.5)) / f32(TABLE_STRATA);
        // GGX through its visible normals: f·cos/pdf = F · G2 / G1(wo).
        let m = ggx_sample_vndf(wo, alpha, u);
        let wi = reflect(-wo, m);
        if (wi.z > 0.0) {
            let w = ggx_g2(wo, wi, alpha) / ggx_g1(wo, alpha);
            let c = clamp(1.0 - dot(wo, m), 0.0, 1.0);
            let s5 = c * c * c * c * c;
            a += w * (1.0 - s5);
            b += w * s5;
        }
        // Sheen by the midpoint rule in (cos θi, φ): at grazing views its visibility term
        // peaks where a cosine-sampled estimate has the fewest samples.
        let ci = u.x;
        let si = sqrt(max(0.0, 1.0 - ci * ci));
        let phi = 2.0 * PI * u.y;
        sheen += sheen_eval(wo, vec3<f32>(si * cos(phi), si * sin(phi), ci), rough) * (2.0 * PI);
    }
    let inv = 1.0 / f32(n);
    probe_out[i] = vec4<f32>(a * inv, b * inv, sheen * inv, 0.0);
}
