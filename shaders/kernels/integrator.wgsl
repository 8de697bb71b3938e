//!include inc/bindings.wgsl
//!include inc/rng.wgsl
//!include inc/frame.wgsl
//!include inc/traverse.wgsl
//!include inc/env.wgsl
//!include inc/bsdf.wgsl
//!include inc/shading.wgsl

// The path tracer: one invocation per pixel, `pc.sample_count` camera samples per dispatch for the
// lighting `pc.light`. Unidirectional path tracing with next-event estimation of the environment,
// MIS (power heuristic) against BSDF sampling, Russian roulette after `params.rr_depth` bounces.
// Radiance of paths that leave the subject without touching a non-lens surface is the background
// and is not recorded (the sample contract: background = 0 where the mask is 0).
//
// Accumulators: accum_lit[light * pixels + p] += radiance; with pc.write_aux, accum_aux[4p..4p+4]
// += (albedo, coverage), (normal, 0), (normal_lens, lens coverage), (unused).

const SHADOW_LENS_LAYERS: u32 = 4u;

fn camera_ray(px: vec2<u32>, jitter: vec2<f32>) -> Ray {
    let ndc = (vec2<f32>(px) + jitter) / vec2<f32>(f32(params.width), f32(params.height));
    let sx = 2.0 * ndc.x - 1.0;
    let sy = 1.0 - 2.0 * ndc.y;
    let dir = normalize(params.cam_fwd.xyz + sx * params.cam_right.xyz + sy * params.cam_up.xyz);
    return Ray(params.cam_pos.xyz, dir, 0.0, 3.4e38);
}

// Camera-space vector: +X right, +Y up, +Z toward the camera.
fn to_camera(v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(v, normalize(params.cam_right.xyz)), dot(v, normalize(params.cam_up.xyz)), -dot(v, params.cam_fwd.xyz));
}

// Visibility of the environment along `dir`: lens surfaces are thin clear glass and let the
// light through attenuated by their Fresnel transmittance (refraction ignored, as for any
// shadow ray through a thin window); anything else blocks it.
fn shadow_transmittance(origin_in: vec3<f32>, dir: vec3<f32>, rays: ptr<function, u32>) -> f32 {
    // Without lenses any hit blocks, so the first one found ends the traversal. (One trace call
    // site per kernel path keeps the code lavapipe generates small.)
    let any_hit = (params.scene_flags & SCENE_HAS_LENS) == 0u;
    var origin = origin_in;
    var tr = 1.0;
    for (var i = 0u; i < SHADOW_LENS_LAYERS; i++) {
        *rays += 1u;
        let h = trace_impl(Ray(origin, dir, 0.0, 3.4e38), any_hit, 0u);
        if (h.t < 0.0) {
            return tr;
        }
        let mat = materials[triangle_material(h.tri)];
        if (any_hit || ((mat.tex.w & MAT_FLAG_LENS) == 0u && mat.extra.y >= 0.5)) {
            return 0.0;
        }
        let sp = shade_hit(Ray(origin, dir, 0.0, 3.4e38), h);
        if ((mat.tex.w & MAT_FLAG_LENS) != 0u) {
            tr *= 1.0 - fresnel_dielectric(abs(dot(dir, sp.ng)), max(mat.spec_color_ior.w, 1.0001));
        } else {
            tr *= 1.0 - mat.extra.y;
        }
        origin = offset_origin(sp.p, sp.ng, dir);
    }
    return 0.0;
}

fn trace_path(first: Ray, p: u32, light: u32, rng: ptr<function, Rng>, rays: ptr<function, u32>) -> vec3<f32> {
    var ray = first;
    var throughput = vec3<f32>(1.0);
    var radiance = vec3<f32>(0.0);
    var prev_pdf = 0.0;
    var prev_delta = true;
    var only_lens = true; // still on the camera ray (possibly through lenses): a miss is background
    // Next-event estimation sees the environment through lens surfaces (shadow_transmittance),
    // so a BSDF-sampled path that only refracts through lenses after its last non-delta vertex
    // reaches light that NEE at that vertex also counted: it is weighted by MIS against NEE
    // with that vertex's pdf (`nee_pdf`) instead of 1, or behind glasses light counts twice.
    // Reflections off a lens, or more lens layers than a shadow ray crosses, NEE never sees.
    var nee_pdf = 0.0;
    var through_lenses = false;
    var lens_layers = 0u;
    for (var depth = 0u; depth <= params.max_depth; depth++) {
        *rays += 1u;
        let hit = trace_closest(ray);
        if (depth == 0u && pc.write_aux != 0u) {
            // The camera ray's hit serves the passes too.
            aux_passes(ray, hit, p, rays);
        }
        if (hit.t < 0.0) {
            if (!only_lens) {
                let le = env_eval(light, ray.dir);
                var w = 1.0;
                if (!prev_delta) {
                    w = power_heuristic(prev_pdf, env_pdf(light, ray.dir));
                } else if (through_lenses) {
                    w = power_heuristic(nee_pdf, env_pdf(light, ray.dir));
                }
                radiance += throughput * le * w;
            }
            break;
        }
        let sp = shade_hit(ray, hit);
        // Partial coverage (glTF alpha): the surface is there with probability `opacity`; otherwise
        // the ray goes on along the same line (this counts as one of the path's events).
        if (sp.opacity < 1.0 && rng_next(rng) >= sp.opacity) {
            ray.tmin = hit.t * (1.0 + 1e-5) + 1e-6;
            continue;
        }
        let wo = to_local(sp.frame, -ray.dir);
        let delta = is_dielectric_delta(sp.surface);
        if ((sp.flags & MAT_FLAG_LENS) == 0u) {
            only_lens = false;
        }
        if (depth == params.max_depth) {
            break;
        }

        // Next-event estimation of the environment.
        if (!delta) {
            let ls = env_sample(light, rng_next_u32(rng), vec3<f32>(rng_next(rng), rng_next2(rng)));
            if (ls.pdf > 0.0 && dot(ls.dir, sp.ng) > 0.0) {
                let wi = to_local(sp.frame, ls.dir);
                let e = bsdf_eval(sp.surface, wo, wi);
                if (e.pdf > 0.0 || max3(e.f_cos) > 0.0) {
                    let vis = shadow_transmittance(offset_origin(sp.p, sp.ng, ls.dir), ls.dir, rays);
                    if (vis > 0.0) {
                        let w = power_heuristic(ls.pdf, e.pdf);
                        radiance += throughput * e.f_cos * ls.radiance * (vis * w / ls.pdf);
                    }
                }
            }
        } else {
            // Keep the random stream aligned whatever the material, for stable noise across lightings.
            _ = rng_next_u32(rng);
            _ = rng_next(rng);
            _ = rng_next2(rng);
        }

        let u_lobe = rng_next(rng);
        let bs = bsdf_sample(sp.surface, wo, u_lobe, rng_next2(rng));
        if (!bs.valid) {
            break;
        }
        let wi_world = to_world(sp.frame, bs.wi);
        // Reject directions that the shading normal allows but the geometry does not.
        let below = dot(wi_world, sp.ng) < 0.0;
        if (below && !delta) {
            break;
        }
        throughput *= bs.weight;
        prev_pdf = bs.pdf;
        prev_delta = bs.is_delta;
        if (!bs.is_delta) {
            nee_pdf = bs.pdf;
            through_lenses = true;
            lens_layers = 0u;
        } else {
            // Frames face the incoming ray (wo.z > 0): a refraction leaves through the back.
            lens_layers += 1u;
            let refracted = bs.wi.z < 0.0 && (sp.flags & MAT_FLAG_LENS) != 0u;
            through_lenses = through_lenses && refracted && lens_layers < SHADOW_LENS_LAYERS;
        }
        ray = Ray(offset_origin(sp.p, sp.ng, wi_world), wi_world, 0.0, 3.4e38);

        if (depth + 1u >= params.rr_depth) {
            let q = clamp(max3(throughput), 0.05, 1.0);
            if (rng_next(rng) >= q) {
                break;
            }
            throughput /= q;
        }
    }
    return radiance;
}

// Primary-hit passes: albedo, normal, coverage of the first non-lens surface; normal and coverage
// of the first lens surface in front of it (lens surfaces count only in normal_lens).
fn aux_passes(first: Ray, first_hit: Hit, p: u32, rays: ptr<function, u32>) {
    var ray = first;
    var lens_done = false;
    for (var layer = 0u; layer < 8u; layer++) {
        var hit = first_hit;
        if (layer > 0u) {
            *rays += 1u;
            hit = trace_closest(ray);
        }
        if (hit.t < 0.0) {
            return;
        }
        let sp = shade_hit(ray, hit);
        if (sp.opacity < 0.5) {
            // Mostly transparent (a cornea, a glTF BLEND veil): the passes look through it.
            ray.tmin = hit.t * (1.0 + 1e-5) + 1e-6;
            continue;
        }
        if ((sp.flags & MAT_FLAG_LENS) != 0u) {
            if (!lens_done) {
                accum_aux[4u * p + 2u] += vec4<f32>(to_camera(sp.frame.n), 1.0);
                lens_done = true;
            }
            // Continue along the same line (not from an offset origin) so the surface seen
            // through the lens is exactly the one seen without it.
            ray.tmin = hit.t * (1.0 + 1e-5) + 1e-6;
            continue;
        }
        accum_aux[4u * p] += vec4<f32>(sp.albedo, 1.0);
        accum_aux[4u * p + 1u] += vec4<f32>(to_camera(sp.frame.n), 0.0);
        return;
    }
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    stack_base = lid;
    if (gid.x >= params.width || gid.y >= params.height) {
        return;
    }
    let p = gid.y * params.width + gid.x;
    let pixels = params.width * params.height;
    var rays = 0u;
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < pc.sample_count; i++) {
        let s = pc.sample_start + i;
        var rng = rng_init(p, s, params.seed);
        let ray = camera_ray(gid.xy, rng_next2(&rng));
        let l = trace_path(ray, p, pc.light, &rng, &rays);
        // A non-finite sample would poison the pixel's sum for good: drop it.
        if (all(l == l) && max3(l) < 3.0e38) {
            sum += l;
        }
    }
    accum_lit[pc.light * pixels + p] += vec4<f32>(sum, 0.0);
    atomicAdd(&counters[0], rays);
}
