//!include inc/bindings.wgsl
//!include inc/rng.wgsl
//!include inc/frame.wgsl
//!include inc/traverse.wgsl
//!include inc/env.wgsl
//!include inc/bsdf.wgsl

// Runs the renderer's own sampling routines on the device so the host can test them (chi-square,
// pdf consistency). probe_in[0..3] describe a Surface, probe_in[3] is wo; the modes:
//   0 BSDF sample:  out[2i] = (wi, pdf), out[2i+1] = (weight, valid + 2*delta), with seeded u
//   1 BSDF eval:    for wi = probe_in[4 + i]: out[i] = (f_cos, pdf)
//   2 env sample:   out[i] = (dir_world, pdf) for light 0
//   3 env pdf:      for d = probe_in[i]: out[i] = (env_pdf, radiance)
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
    let a = probe_in[0];
    let b = probe_in[1];
    let c = probe_in[2];
    // a = base rgb + metallic, b = alpha, specular, transmission, ior, c = specular colour
    return Surface(a.xyz, a.w, b.x, b.y, c.xyz, b.z, b.w);
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
            let wo = probe_in[3].xyz;
            let u_lobe = rng_next(&rng);
            var bs = bsdf_sample(s, wo, u_lobe, rng_next2(&rng));
            if (bs.valid && mutated_away(bs.wi, &rng)) {
                let u_redraw = rng_next(&rng);
                bs = bsdf_sample(s, wo, u_redraw, rng_next2(&rng));
            }
            let flags = select(0.0, 1.0, bs.valid) + select(0.0, 2.0, bs.is_delta);
            probe_out[2u * i] = vec4<f32>(bs.wi, bs.pdf);
            probe_out[2u * i + 1u] = vec4<f32>(bs.weight, flags);
        }
        case 1u: {
            let s = probe_surface();
            let wo = probe_in[3].xyz;
            let e = bsdf_eval(s, wo, probe_in[4u + i].xyz);
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
        default: {}
    }
}
