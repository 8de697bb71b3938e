//!include inc/bindings.wgsl
//!include inc/rng.wgsl
//!include inc/frame.wgsl
//!include inc/traverse.wgsl
//!include inc/env.wgsl
//!include inc/bsdf.wgsl
//!include inc/layered.wgsl
//!include inc/hair.wgsl
//!include inc/subsurface.wgsl

// Runs the renderer's own sampling routines on the device so the host can test them (chi-square,
// pdf consistency). probe_in[0..8] describe a Surface (see probe_surface), probe_in[8] is wo;
// the modes:
//   0 BSDF sample:  out[2i] = (wi, pdf), out[2i+1] = (weight, valid + 2*delta + 4*subsurface)
//   1 BSDF eval:    for wi = probe_in[9 + i]: out[i] = (f_cos, pdf)
//   2 env sample:   out[i] = (dir_world, pdf) for light 0
//   3 env pdf:      for d = probe_in[i]: out[i] = (env_pdf, radiance)
//   4 SSS flight:   probe_in[0] = (throughput, _), [1] = (colour, g), [2] = (mean free path, _):
//                   out[i] = (t, collision pdf(t), pass probability(t), channel)
//   5 HG phase:     probe_in[0] = (dir, g): out[i] = (new dir, pdf)
//   6 SSS albedo:   for probe_in[i] = (colour, g): out[2i] = (α, 0), out[2i+1] = (slab C(α), 0)
//   7 fibre sample: probe_in[0] = (σa, h), [1] = (βm, βn, α, ior), [2] = wo:
//                   out[2i] = (wi, pdf), out[2i+1] = (weight, valid)
//   8 fibre eval:   the same fibre, for wi = probe_in[3 + i]: out[i] = (f_cos, pdf)
//   9 fibre furnace: the same fibre but wo uniform on the sphere and h uniform in [-1, 1] per
//                   item; wi from the fibre sampler or uniform, 1/2 each: out[i] =
//                   (f_cos / (pdf / 2 + 1 / 8π), 0), whose mean is the albedo ∫ f_cos dωi as
//                   long as pdf is the sampler's true density
//
// pc.mutate = 1 + axis turns the samplers of modes 0 and 2 into deliberately wrong ones, so the
// tests can show their statistics reject a biased sampler: a sample whose direction has a
// negative `axis` component is redrawn with probability MUTATE_REDRAW. The sampled density is
// then (1 - MUTATE_REDRAW (1 - q)) p on that half and (1 + MUTATE_REDRAW q) p on the other,
// where q is the half's probability: off by ±5% of the claimed pdf p when q = 1/2.
const MUTATE_REDRAW: f32 = 0.1;

fn mutated_away(d: vec3<f32>, rng: ptr<function, Rng>) -> bool {
    if (pc.mutate == 0u) {
        return false;
    }
    let u = rng_next(rng);
    return d[min(pc.mutate - 1u, 2u)] < 0.0 && u < MUTATE_REDRAW;
}

fn probe_surface() -> Surface {
    let a = probe_in[0]; // base rgb, metallic
    let b = probe_in[1]; // alpha, specular, transmission, ior
    let c = probe_in[2]; // specular colour, model
    let d = probe_in[3]; // subsurface colour, subsurface weight
    let e = probe_in[4]; // mean free path, anisotropy
    let f = probe_in[5]; // coat colour, coat weight
    let g = probe_in[6]; // coat alpha, coat ior, sheen weight, sheen roughness
    let h = probe_in[7]; // sheen colour, thin-walled (> 0.5)
    return Surface(a.xyz, a.w, b.x, b.y, c.xyz, b.z, b.w, u32(c.w), d.w, d.xyz, e.xyz, e.w,
        f.w, f.xyz, g.x, g.y, g.z, h.xyz, g.w, h.w > 0.5, vec3<f32>(0.0), vec4<f32>(0.0));
}

fn probe_fibre(h: f32) -> Surface {
    let a = probe_in[0];
    let b = probe_in[1];
    return Surface(vec3<f32>(0.0), 0.0, 1.0, 0.0, vec3<f32>(0.0), 0.0, b.w, MODEL_HAIR, 0.0, vec3<f32>(0.0),
        vec3<f32>(1.0), 0.0, 0.0, vec3<f32>(0.0), 1.0, 1.5, 0.0, vec3<f32>(0.0), 1.0, false, a.xyz, vec4<f32>(b.xyz, h));
}

fn uniform_sphere(u: vec2<f32>) -> vec3<f32> {
    let z = 1.0 - 2.0 * u.x;
    let r = sqrt(max(0.0, 1.0 - z * z));
    let phi = TWO_PI * u.y;
    return vec3<f32>(r * cos(phi), r * sin(phi), z);
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    stack_base = lid;
    let i = gid.x;
    if (i >= pc.count) {
        return;
    }
    switch pc.mode {
        case 0u: {
            var rng = rng_init(i, pc.sample_start, params.seed);
            let s = probe_surface();
            let wo = probe_in[8].xyz;
            let u_lobe = rng_next(&rng);
            var bs = bsdf_sample(s, wo, u_lobe, rng_next2(&rng));
            if (bs.valid && mutated_away(bs.wi, &rng)) {
                let u_redraw = rng_next(&rng);
                bs = bsdf_sample(s, wo, u_redraw, rng_next2(&rng));
            }
            let flags = select(0.0, 1.0, bs.valid) + select(0.0, 2.0, bs.is_delta) + select(0.0, 4.0, bs.subsurface);
            probe_out[2u * i] = vec4<f32>(bs.wi, bs.pdf);
            probe_out[2u * i + 1u] = vec4<f32>(bs.weight, flags);
        }
        case 1u: {
            let s = probe_surface();
            let wo = probe_in[8].xyz;
            let e = bsdf_eval(s, wo, probe_in[9u + i].xyz);
            probe_out[i] = vec4<f32>(e.f_cos, e.pdf);
        }
        case 2u: {
            var rng = rng_init(i, pc.sample_start, params.seed);
            var es = env_sample(0u, rng_next_u32(&rng), vec3<f32>(rng_next(&rng), rng_next2(&rng)));
            if (mutated_away(es.dir, &rng)) {
                es = env_sample(0u, rng_next_u32(&rng), vec3<f32>(rng_next(&rng), rng_next2(&rng)));
            }
            probe_out[i] = vec4<f32>(es.dir, es.pdf);
        }
        case 3u: {
            let d = probe_in[i].xyz;
            probe_out[i] = vec4<f32>(env_pdf(0u, d), env_eval(0u, d));
        }
        case 4u: {
            var rng = rng_init(i, pc.sample_start, params.seed);
            let alpha = sss_albedo(probe_in[1].xyz, probe_in[1].w);
            let sigma_t = vec3<f32>(1.0) / probe_in[2].xyz;
            let probs = sss_channel_probs(probe_in[0].xyz, alpha);
            let c = sss_pick_channel(probs, rng_next(&rng));
            let t = sss_flight(sigma_t, c, rng_next(&rng));
            probe_out[i] = vec4<f32>(t, sss_collision_pdf(probs, sigma_t, t), sss_pass_pdf(probs, sigma_t, t), f32(c));
        }
        case 5u: {
            var rng = rng_init(i, pc.sample_start, params.seed);
            let dir = normalize(probe_in[0].xyz);
            let g = probe_in[0].w;
            var d = hg_sample(dir, g, rng_next2(&rng));
            if (mutated_away(d, &rng)) {
                d = hg_sample(dir, g, rng_next2(&rng));
            }
            probe_out[i] = vec4<f32>(d, hg_pdf(dot(dir, d), g));
        }
        case 6u: {
            let a = sss_albedo(probe_in[i].xyz, probe_in[i].w);
            probe_out[2u * i] = vec4<f32>(a, 0.0);
            probe_out[2u * i + 1u] = vec4<f32>(sss_reflectance(a, probe_in[i].w), 0.0);
        }
        case 7u: {
            var rng = rng_init(i, pc.sample_start, params.seed);
            let s = probe_fibre(probe_in[0].w);
            let wo = probe_in[2].xyz;
            let u_lobe = rng_next(&rng);
            var bs = hair_sample(s, wo, u_lobe, rng_next2(&rng));
            if (bs.valid && mutated_away(bs.wi, &rng)) {
                let u_redraw = rng_next(&rng);
                bs = hair_sample(s, wo, u_redraw, rng_next2(&rng));
            }
            probe_out[2u * i] = vec4<f32>(bs.wi, bs.pdf);
            probe_out[2u * i + 1u] = vec4<f32>(bs.weight, select(0.0, 1.0, bs.valid));
        }
        case 8u: {
            let e = hair_eval(probe_fibre(probe_in[0].w), probe_in[2].xyz, probe_in[3u + i].xyz);
            probe_out[i] = vec4<f32>(e.f_cos, e.pdf);
        }
        case 9u: {
            var rng = rng_init(i, pc.sample_start, params.seed);
            let wo = uniform_sphere(rng_next2(&rng));
            let s = probe_fibre(2.0 * rng_next(&rng) - 1.0);
            let u_pick = rng_next(&rng);
            let u_lobe = rng_next(&rng);
            let u = rng_next2(&rng);
            var wi = uniform_sphere(u);
            if (u_pick < 0.5) {
                let bs = hair_sample(s, wo, u_lobe, u);
                wi = select(vec3<f32>(0.0, 0.0, 1.0), bs.wi, bs.valid);
            }
            let e = hair_eval(s, wo, wi);
            probe_out[i] = vec4<f32>(e.f_cos / (0.5 * e.pdf + 0.5 / (4.0 * PI)), 0.0);
        }
        default: {}
    }
}
