// The math of the random-walk subsurface scattering (Cycles' subsurface_random_walk.h, Arnold's
// randomwalk_v2, OpenPBR): the albedo inversion, the spectral-MIS free-flight sampler and the
// Henyey–Greenstein phase function. The walk itself, which casts rays, is walk.wgsl; this file
// has no scene access so the probe kernel can test the samplers alone.

// Single-scattering albedo α of a medium whose semi-infinite slab reflects `c` under diffuse
// light (van de Hulst's fit, index-matched boundary, anisotropy g).
fn sss_albedo(c_in: vec3<f32>, g: f32) -> vec3<f32> {
    let c = clamp(c_in, vec3<f32>(0.0), vec3<f32>(1.0));
    let s = max(vec3<f32>(4.09712) + 4.20863 * c - sqrt(vec3<f32>(9.59217) + 41.6808 * c + 17.7126 * c * c), vec3<f32>(0.0));
    let s2 = s * s;
    return (vec3<f32>(1.0) - s2) / (vec3<f32>(1.0) - g * s2);
}

// Slab reflectance of single-scattering albedo α (the forward fit), for the tests.
fn sss_reflectance(alpha: vec3<f32>, g: f32) -> vec3<f32> {
    let s = sqrt(max(vec3<f32>(1.0) - alpha, vec3<f32>(0.0)) / max(vec3<f32>(1.0) - alpha * g, vec3<f32>(1e-12)));
    return (vec3<f32>(1.0) - s) * (vec3<f32>(1.0) - 0.139 * s) / (vec3<f32>(1.0) + 1.17 * s);
}

// Spectral MIS: the channel of a free flight is drawn with probability ∝ throughput·α, so the
// channels that still carry light steer the walk; the weights below divide by the mixture.
fn sss_channel_probs(throughput: vec3<f32>, alpha: vec3<f32>) -> vec3<f32> {
    let w = throughput * alpha;
    let sum = w.x + w.y + w.z;
    if (sum <= 0.0) {
        return vec3<f32>(1.0 / 3.0);
    }
    return w / sum;
}

fn sss_pick_channel(p: vec3<f32>, u: f32) -> u32 {
    if (u < p.x) {
        return 0u;
    }
    if (u < p.x + p.y) {
        return 1u;
    }
    return 2u;
}

// Distance to the next collision in the medium of extinction `sigma_t`, for the channel `c`.
fn sss_flight(sigma_t: vec3<f32>, c: u32, u: f32) -> f32 {
    return -log(max(1.0 - u, 1e-30)) / sigma_t[c];
}

// Density of stopping at distance t (a collision there) under the channel mixture.
fn sss_collision_pdf(p: vec3<f32>, sigma_t: vec3<f32>, t: f32) -> f32 {
    return dot(p, sigma_t * exp(-sigma_t * t));
}

// Probability of flying past distance t (reaching a boundary there) under the channel mixture.
fn sss_pass_pdf(p: vec3<f32>, sigma_t: vec3<f32>, t: f32) -> f32 {
    return dot(p, exp(-sigma_t * t));
}

// New propagation direction after scattering off `dir`, Henyey–Greenstein with anisotropy g
// (g > 0 forward); the density in the propagation convention is
// (1 − g²) / (4π (1 + g² − 2g cos θ)^1.5), cos θ = dot(dir, new).
fn hg_sample(dir: vec3<f32>, g: f32, u: vec2<f32>) -> vec3<f32> {
    var cos_t: f32;
    if (abs(g) < 1e-3) {
        cos_t = 1.0 - 2.0 * u.x;
    } else {
        let q = (1.0 - g * g) / (1.0 + g - 2.0 * g * u.x);
        cos_t = (1.0 + g * g - q * q) / (2.0 * g);
    }
    cos_t = clamp(cos_t, -1.0, 1.0);
    let sin_t = sqrt(max(0.0, 1.0 - cos_t * cos_t));
    let phi = 2.0 * PI * u.y;
    let f = frame_from_normal(dir);
    return normalize(f.t * (sin_t * cos(phi)) + f.b * (sin_t * sin(phi)) + f.n * cos_t);
}

fn hg_pdf(cos_t: f32, g: f32) -> f32 {
    let d = 1.0 + g * g - 2.0 * g * cos_t;
    return (1.0 - g * g) / (4.0 * PI * d * sqrt(d));
}

// Direction into the medium through the rough specular interface: refraction of −wo through a
// visible GGX microfacet of the specular layer (IOR ior, outside → inside; ior = 1 goes
// straight on). Local frame, z = outward normal; the result points down (z < 0), or is zero
// where the facet would not let the light in.
fn sss_entry_dir(wo: vec3<f32>, alpha: f32, ior: f32, u: vec2<f32>) -> vec3<f32> {
    let m = ggx_sample_vndf(wo, max(alpha, 1e-4), u);
    let cos_i = dot(wo, m);
    if (cos_i <= 0.0) {
        return vec3<f32>(0.0);
    }
    let eta = max(ior, 1.0);
    let sin2_t = max(0.0, 1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = sqrt(max(0.0, 1.0 - sin2_t));
    let wi = -wo / eta + (cos_i / eta - cos_t) * m;
    if (wi.z >= 0.0) {
        return vec3<f32>(0.0);
    }
    return normalize(wi);
}
