//!include inc/bindings.wgsl
//!include inc/rng.wgsl
//!include inc/frame.wgsl
//!include inc/traverse.wgsl
//!include inc/env.wgsl
//!include inc/bsdf.wgsl
//!include inc/layered.wgsl
//!include inc/hair.wgsl
//!include inc/subsurface.wgsl
//!include inc/shading.wgsl
//!include inc/walk.wgsl
//!include inc/walk_queue.wgsl

// The path tracer: one invocation per pixel, `pc.sample_count` camera samples per dispatch for the
// `pc.count` lightings from `pc.light` on (0 counts as 1). Unidirectional path tracing with
// next-event estimation of the environment, MIS (power heuristic) against BSDF sampling, Russian
// roulette after `params.rr_depth` bounces. Radiance of paths that leave the subject without
// touching a non-lens surface is the background and is not recorded (the sample contract:
// background = 0 where the mask is 0).
//
// One path serves every lighting of the dispatch: where it goes does not depend on the light (BSDF
// sampling, roulette on the throughput), only what it gathers does. Each vertex casts one NEE
// shadow ray per lighting from that lighting's own distribution, and an escaped ray adds each
// lighting's radiance with that lighting's MIS weight, so every lighting gets the estimator it would
// get rendered alone (tests/shared_paths.rs compares the two). With pc.nee = NEE_MIXTURE a vertex
// casts one shadow ray for all lightings instead, from the mixture of their distributions, and
// every MIS weight uses the mixture's density: unbiased per lighting, fewer rays, more noise.
//
// Accumulators: accum_lit[k * pixels + p] += radiance of lighting pc.light + k (the renderer
// binds one group of lightings at a time); with pc.write_aux, accum_aux[4p..4p+4]
// += (albedo, coverage), (normal, 0), (normal_lens = lens normal or normal, lens coverage), (unused).
// An invocation that owns its pixel adds each finite contribution to them where it arises (a
// non-finite one would poison the pixel's sum for good, so it is dropped); a queued walk
// (STAGE_WALKS, always one lighting) returns its path's for the gather stage.

const SHADOW_LENS_LAYERS: u32 = 4u;

// The mixture schedule's shadow-ray stream is forked with this salt, which no lighting index
// (at most MAX_LIGHTS) takes.
const MIXTURE_STREAM: u32 = 0xfffffff0u;

// The traversal counters' per-pixel words in `counters` (integrator_counters only; the renderer
// sizes the buffer): rays, node tests, primitive tests, BLAS entries, deepest stack, overflows,
// non-finite rays, BLAS loop turns, and the SIMD-group turns of the BLAS loop and of its
// primitive tests (each counted at the group leader's pixel: only their sums mean something).
const TC_FIRST: u32 = 8u;
const TC_WORDS: u32 = 10u;

// The appendix passes (pc.passes != 0; the renderer binds their accumulator at probe_out):
// PASS_VEC4S per pixel and lighting of the dispatch (slot k = lighting pc.light + k at
// PASS_VEC4S * (k * pixels + p)): diffuse, specular, sss, coat, sheen (rgb),
// (direct light with visibility, without it, 0, 0) as luminance for the shadow pass. Every
// contribution of a path goes to the lobe family sampled at its first non-delta vertex, NEE
// there by each family's own f; a lobe's share of a sampled continuation is its f over the
// total f, so each pass is an unbiased estimate and the five sum to lit.
const PASS_VEC4S: u32 = 6u;

struct Passes {
    diffuse: vec3<f32>,
    specular: vec3<f32>,
    sss: vec3<f32>,
    coat: vec3<f32>,
    sheen: vec3<f32>,
    direct: f32,      // direct light at the first vertex, with visibility
    unshadowed: f32,  // the same without visibility
};

fn passes_zero() -> Passes {
    return Passes(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0);
}

fn passes_add(acc: ptr<function, Passes>, p: Passes) {
    (*acc).diffuse += p.diffuse;
    (*acc).specular += p.specular;
    (*acc).sss += p.sss;
    (*acc).coat += p.coat;
    (*acc).sheen += p.sheen;
    (*acc).direct += p.direct;
    (*acc).unshadowed += p.unshadowed;
}

// Fractions of later contributions per family (set at the first non-delta vertex).
struct Split {
    diffuse: vec3<f32>,
    specular: vec3<f32>,
    sss: vec3<f32>,
    coat: vec3<f32>,
    sheen: vec3<f32>,
};

fn safe_ratio(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return select(vec3<f32>(0.0), a / b, b > vec3<f32>(0.0));
}

fn split_of(l: Lobes) -> Split {
    let f = lobes_sum(l);
    return Split(safe_ratio(l.diffuse, f), safe_ratio(l.specular, f), vec3<f32>(0.0), safe_ratio(l.coat, f), safe_ratio(l.sheen, f));
}

fn finite3(c: vec3<f32>) -> bool {
    return all(c == c) && max3(abs(c)) < 3.0e38;
}

fn shared_lightings() -> u32 {
    return max(pc.count, 1u);
}

// NEE_MIXTURE with more than one lighting: each vertex casts one shadow ray for all of them.
fn nee_mixture() -> bool {
    return pc.nee == NEE_MIXTURE && shared_lightings() > 1u;
}

// The density of the mixture's light samples, the same for every lighting of the dispatch:
// (1/K) Σ_j p_j (it picks a lighting uniformly, then samples it), so MIS against BSDF sampling
// stays exact for each lighting. Without the mixture a lighting's own env_pdf is the density.
fn mixture_pdf(d: vec3<f32>) -> f32 {
    let n = shared_lightings();
    var sum = 0.0;
    for (var j = 0u; j < n; j++) {
        sum += env_pdf(pc.light + j, d);
    }
    return sum / f32(n);
}

// Radiance `c` of lighting slot `slot` at pixel `p` (see the accumulators above).
fn deposit_lit(p: u32, slot: u32, c: vec3<f32>, radiance: ptr<function, vec3<f32>>) {
    if (pc.mode == STAGE_WALKS) {
        *radiance += c;
    } else if (finite3(c)) {
        accum_lit[slot * params.width * params.height + p] += vec4<f32>(c, 0.0);
    }
}

// Pass contributions `q` of lighting slot `slot` at pixel `p`.
fn deposit_passes(p: u32, slot: u32, q: Passes, ps: ptr<function, Passes>) {
    if (pc.mode == STAGE_WALKS) {
        passes_add(ps, q);
        return;
    }
    let ok = finite3(q.diffuse) && finite3(q.specular) && finite3(q.sss) && finite3(q.coat)
        && finite3(q.sheen) && finite3(vec3<f32>(q.direct, q.unshadowed, 0.0));
    if (ok) {
        passes_add_at(PASS_VEC4S * (slot * params.width * params.height + p), q);
    }
}

// Adds `q` to the pass accumulator's PASS_VEC4S vec4s from `b` on.
fn passes_add_at(b: u32, q: Passes) {
    probe_out[b] += vec4<f32>(q.diffuse, 0.0);
    probe_out[b + 1u] += vec4<f32>(q.specular, 0.0);
    probe_out[b + 2u] += vec4<f32>(q.sss, 0.0);
    probe_out[b + 3u] += vec4<f32>(q.coat, 0.0);
    probe_out[b + 4u] += vec4<f32>(q.sheen, 0.0);
    probe_out[b + 5u] += vec4<f32>(q.direct, q.unshadowed, 0.0, 0.0);
}

fn split_passes(s: Split, c: vec3<f32>) -> Passes {
    return Passes(c * s.diffuse, c * s.specular, c * s.sss, c * s.coat, c * s.sheen, 0.0, 0.0);
}

// Where trace_path starts: a camera ray, or (STAGE_WALKS) the exit point of a parked walk.
struct PathStart {
    ray: Ray,
    throughput: vec3<f32>,
    depth: u32,
    exit: bool,            // exit_sp is the first vertex (no ray to find it)
    exit_sp: ShadingPoint,
    split: Split,
    split_set: bool,
};

// Russian roulette after a bounce at `depth`: false ends the path.
fn roulette(throughput: ptr<function, vec3<f32>>, depth: u32, rng: ptr<function, Rng>) -> bool {
    if (depth + 1u >= params.rr_depth) {
        let q = clamp(max3(*throughput), 0.05, 1.0);
        if (rng_next(rng) >= q) {
            return false;
        }
        *throughput /= q;
    }
    return true;
}

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
// shadow ray through a thin window), thin-walled sheets (a cornea) by theirs, which is exact;
// partly covering surfaces (opacity < 0.5) by their coverage; anything else blocks it.
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
        let mat = materials[hit_material(h)];
        if (any_hit || ((mat.tex.w & MAT_FLAG_CLEAR) == 0u && mat.extra.y >= 0.5)) {
            return 0.0;
        }
        let sp = shade_hit(Ray(origin, dir, 0.0, 3.4e38), h);
        if ((mat.tex.w & MAT_FLAG_LENS) != 0u) {
            tr *= 1.0 - fresnel_dielectric(abs(dot(dir, sp.ng)), max(mat.spec_color_ior.w, 1.0001));
        } else if ((mat.tex.w & MAT_FLAG_THIN) != 0u) {
            tr *= 1.0 - thin_sheet_reflectance(dot(dir, sp.ng), sp.surface.ior);
        } else {
            tr *= 1.0 - mat.extra.y;
        }
        origin = spawn_origin(sp, dir);
    }
    return 0.0;
}

// `defer_slot`: NO_SLOT walks where the path picks a subsurface lobe; anything else parks the
// path there in that job slot (STAGE_PATHS) and ends it. Contributions go through deposit_*; the
// returned radiance and *ps are a queued walk's (STAGE_WALKS), zero otherwise.
fn trace_path(start: PathStart, p: u32, sample: u32, defer_slot: u32, rng: ptr<function, Rng>, rays: ptr<function, u32>, ps: ptr<function, Passes>) -> vec3<f32> {
    let want_passes = pc.passes != 0u;
    let lightings = shared_lightings();
    var split = start.split;
    var split_set = start.split_set;
    var ray = start.ray;
    var throughput = start.throughput;
    var radiance = vec3<f32>(0.0);
    var prev_pdf = 0.0;
    var prev_delta = true;
    // Still on the camera ray (possibly through lenses): a miss is background.
    var only_lens = start.depth == 0u;
    // Next-event estimation sees the environment through lens surfaces (shadow_transmittance),
    // so a BSDF-sampled path that only refracts through lenses after its last non-delta vertex
    // reaches light that NEE at that vertex also counted: it is weighted by MIS against NEE
    // with that vertex's pdf (`nee_pdf`) instead of 1, or behind glasses light counts twice.
    // Reflections off a lens, or more lens layers than a shadow ray crosses, NEE never sees.
    var nee_pdf = 0.0;
    var through_lenses = false;
    var lens_layers = 0u;
    // A subsurface walk ends at an exit point, which is the next vertex without a ray to find it.
    var exit_pending = start.exit;
    var exit_sp = start.exit_sp;
    for (var depth = start.depth; depth <= params.max_depth; depth++) {
        var sp: ShadingPoint;
        var hit_instance = 0u;
        var hit: Hit;
        if (exit_pending) {
            exit_pending = false;
            sp = exit_sp;
        } else {
            *rays += 1u;
            hit = trace_closest(ray);
            if (depth == 0u && pc.write_aux != 0u) {
                // The camera ray's hit serves the passes too.
                aux_passes(ray, hit, p, sample, rays);
            }
            if (hit.t < 0.0) {
                if (!only_lens) {
                    // The mixture's density is the same for every lighting: sum it once.
                    var mix_pdf = 0.0;
                    if (nee_mixture() && (!prev_delta || through_lenses)) {
                        mix_pdf = mixture_pdf(ray.dir);
                    }
                    for (var k = 0u; k < lightings; k++) {
                        let light = pc.light + k;
                        let le = env_eval(light, ray.dir);
                        var w = 1.0;
                        if (!prev_delta || through_lenses) {
                            var lp = mix_pdf;
                            if (!nee_mixture()) {
                                lp = env_pdf(light, ray.dir);
                            }
                            w = power_heuristic(select(nee_pdf, prev_pdf, !prev_delta), lp);
                        }
                        let c = throughput * le * w;
                        deposit_lit(p, k, c, &radiance);
                        if (want_passes) {
                            deposit_passes(p, k, split_passes(split, c), ps);
                        }
                    }
                }
                break;
            }
            sp = shade_hit(ray, hit);
            hit_instance = hit.instance;
            // Partial coverage (glTF alpha): the surface is there with probability `opacity`;
            // otherwise the ray goes on along the same line (one of the path's events).
            if (sp.opacity < 1.0 && rng_next(rng) >= sp.opacity) {
                ray.tmin = hit.t * (1.0 + 1e-5) + 1e-6;
                continue;
            }
        }
        let wo = to_local(sp.frame, -ray.dir);
        let delta = is_dielectric_delta(sp.surface);
        if ((sp.flags & MAT_FLAG_LENS) == 0u) {
            only_lens = false;
        }
        if (depth == params.max_depth) {
            break;
        }

        // Next-event estimation of each lighting, one shadow ray each. Each lighting draws from
        // a stream of its own, forked from the path's by the lighting's index: the path's stream
        // advances one draw per vertex whatever the material and however many lightings share
        // it, so a path takes the same turns under any K and a lighting gets the same shadow
        // rays in a group as alone. (Drawing all of them from the path's stream made K = 168
        // run ~700 draws per vertex through the one 2^32 LCG cycle every stream is an offset
        // of, where the streams of different samples overlap and correlate: 2.4x the noise.)
        //
        // The mixture schedule casts one shadow ray per vertex instead, from a stream of its own
        // (salted apart from the lightings'), toward a lighting picked uniformly, and weighs it
        // for every lighting by the mixture density: one loop and one shadow_transmittance call
        // site serve both (lavapipe inlines each call site's traversal).
        let fork = rng_next_u32(rng);
        let mixture = nee_mixture();
        let shadow_rays = select(lightings, 1u, mixture);
        for (var r = 0u; r < shadow_rays; r++) {
            if (delta) {
                break;
            }
            var lrng = Rng(pcg_hash(fork ^ pcg_hash(select(pc.light + r, MIXTURE_STREAM, mixture))));
            var aim = r;
            if (mixture) {
                aim = uniform_index(rng_next_u32(&lrng), lightings);
            }
            let ls = env_sample(pc.light + aim, rng_next_u32(&lrng), vec3<f32>(rng_next(&lrng), rng_next2(&lrng)));
            if (ls.pdf <= 0.0 || (!sp.fibre && dot(ls.dir, sp.ng) <= 0.0)) {
                continue;
            }
            let wi = to_local(sp.frame, ls.dir);
            let e = bsdf_eval(sp.surface, wo, wi);
            if (e.pdf <= 0.0 && max3(e.f_cos) <= 0.0) {
                continue;
            }
            let vis = shadow_transmittance(spawn_origin(sp, ls.dir), ls.dir, rays);
            var pdf = ls.pdf;
            if (mixture) {
                pdf = mixture_pdf(ls.dir);
            }
            let w = power_heuristic(pdf, e.pdf);
            // Under the mixture the ray serves every lighting, each with its own radiance there.
            let first = select(r, 0u, mixture);
            let last = select(r + 1u, lightings, mixture);
            for (var k = first; k < last; k++) {
                var le = ls.radiance;
                if (mixture) {
                    le = env_eval(pc.light + k, ls.dir);
                }
                if (max3(le) <= 0.0) {
                    continue;
                }
                if (vis > 0.0) {
                    deposit_lit(p, k, throughput * e.f_cos * le * (vis * w / pdf), &radiance);
                }
                if (want_passes) {
                    let c = throughput * le * (w / pdf);
                    if (!split_set) {
                        let lobes = bsdf_lobes(sp.surface, wo, wi);
                        deposit_passes(p, k, Passes(lobes.diffuse * c * vis, lobes.specular * c * vis, vec3<f32>(0.0),
                            lobes.coat * c * vis, lobes.sheen * c * vis, luminance(e.f_cos * c) * vis,
                            luminance(e.f_cos * c)), ps);
                    } else {
                        deposit_passes(p, k, split_passes(split, e.f_cos * c * vis), ps);
                    }
                }
            }
        }

        let u_lobe = rng_next(rng);
        let bs = bsdf_sample(sp.surface, wo, u_lobe, rng_next2(rng));
        if (!bs.valid) {
            break;
        }
        if (bs.subsurface) {
            if (defer_slot != NO_SLOT) {
                job_park(defer_slot, ray, hit, throughput, bs.weight, depth, split, split_set, *rng);
                break;
            }
            let walk = random_walk(sp, hit_instance, wo, rng, rays);
            if (!walk.ok) {
                break;
            }
            throughput *= bs.weight * walk.weight;
            if (!split_set) {
                split = Split(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(1.0), vec3<f32>(0.0), vec3<f32>(0.0));
                split_set = true;
            }
            exit_sp = walk.sp;
            exit_pending = true;
            // The exit vertex's wo: straight out, which a Lambertian exit does not depend on.
            ray = Ray(exit_sp.p, -exit_sp.frame.n, 0.0, 3.4e38);
        } else {
            let wi_world = to_world(sp.frame, bs.wi);
            // Reject directions that the shading normal allows but the geometry does not.
            let below = dot(wi_world, sp.ng) < 0.0;
            if (below && !delta && !sp.fibre) {
                break;
            }
            throughput *= bs.weight;
            if (want_passes && !split_set && !bs.is_delta) {
                split = split_of(bsdf_lobes(sp.surface, wo, bs.wi));
                split_set = true;
            }
            prev_pdf = bs.pdf;
            prev_delta = bs.is_delta;
            if (!bs.is_delta) {
                nee_pdf = bs.pdf;
                through_lenses = true;
                lens_layers = 0u;
            } else {
                // Frames face the incoming ray (wo.z > 0): a refraction leaves through the back
                // (and so does the straight pass through a thin sheet, which NEE sees exactly).
                lens_layers += 1u;
                let refracted = bs.wi.z < 0.0 && (sp.flags & MAT_FLAG_CLEAR) != 0u;
                through_lenses = through_lenses && refracted && lens_layers < SHADOW_LENS_LAYERS;
            }
            ray = Ray(spawn_origin(sp, wi_world), wi_world, 0.0, 3.4e38);
        }

        if (!roulette(&throughput, depth, rng)) {
            break;
        }
    }
    return radiance;
}

// Primary-hit passes: albedo, normal, coverage of the first non-lens surface; normal_lens is the
// normal of the first lens surface in front of it, or that surface's normal where no lens is
// (with the lens coverage in its w).
fn aux_passes(first: Ray, first_hit: Hit, p: u32, sample: u32, rays: ptr<function, u32>) {
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
        if (sp.opacity < 0.5 || (sp.flags & MAT_FLAG_THIN) != 0u) {
            // Mostly transparent (a glTF BLEND veil) or a clear sheet (a cornea): the passes
            // look through it.
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
        if (sample == 0u) {
            // The id pass: the object class of the first sample's surface, 0 for background.
            accum_aux[4u * p + 3u] = vec4<f32>(f32(materials[sp.material].tex2.z + 1u), 0.0, 0.0, 0.0);
        }
        let n = to_camera(sp.frame.n);
        accum_aux[4u * p + 1u] += vec4<f32>(n, 0.0);
        if (!lens_done) {
            // No lens in front: the normal with lenses is the normal (the paper's N_l = N
            // without eyeglasses), accumulated identically so the passes agree bit for bit.
            accum_aux[4u * p + 2u] += vec4<f32>(n, 0.0);
        }
        return;
    }
}

// Mesa 22's llvmpipe (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS) allows each SIMD group of
// invocations 65,535 loop turns in all, summed over every loop of the shader, and then ends each
// loop at its next turn: the samples and traversals still to come are lost without a trace, and
// the pixel is divided by samples it never took (a glass shell rendered at 64 spp kept ~52).
// Mesa 25 and 26 set no such limit. A loop that must turn params.loop_check (8) times turns
// fewer once the budget is spent (measured: 2 of 1,000; its bound is read from memory, so no
// compiler can unroll it away); counters[2] then counts the invocations that saw it, and the
// renderer refuses the render. On a driver that its STAGE_LOOP_PROBE dispatch found cutting
// loops, the renderer gives each invocation one sample per dispatch, which stays far below the
// budget; this check still catches a sample that alone exceeds it.
fn report_cut_loops() {
    var turns = 0u;
    loop {
        turns += 1u;
        if (turns >= params.loop_check) {
            break;
        }
    }
    if (turns < params.loop_check) {
        atomicAdd(&counters[2], 1u);
    }
}

fn accumulate(p: u32, sum: vec3<f32>, passes: Passes) {
    accum_lit[p] += vec4<f32>(sum, 0.0);
    if (pc.passes != 0u) {
        passes_add_at(PASS_VEC4S * p, passes);
    }
}

// Where the pixel queue's next entry is counted (params.pixel_queue; reset by the host after
// every dispatch): entry j is pixel j mod 64 of 8x8 tile j / 64, tiles in image order.
const PIXEL_QUEUE_WORD: u32 = 4u;

// pc.mode is the stage (inc/walk_queue.wgsl): the megakernel, or one of the walk-dispatch
// schedule's three. One call of trace_path serves all of them (lavapipe inlines every call).
//
// Which pixels an invocation renders: on a GPU, the one its workgroup and index name. With
// params.pixel_queue (CPU devices), every invocation of the megakernel and of STAGE_PATHS takes
// pixels off a queue until it is empty. llvmpipe hands each thread one contiguous block of
// workgroups and does not rebalance, so a thread whose block costs less would sit idle until
// the other's ends (1.80 of 2 cores busy on a head render, Mesa 25); off the queue a thread
// renders until the image is done. A pixel's samples do not depend on who renders it, so the images are the same.
@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    stack_base = lid;
    if (TRAVERSAL_COUNTERS) {
        // Before any invocation returns, so that the whole SIMD group is active.
        let width = simd_width();
        if (lid == 0u) {
            atomicMax(&counters[3], width);
        }
    }
    if (pc.mode == STAGE_LOOP_PROBE) {
        // The renderer asks once, with params.loop_check far above 65,535, whether this driver
        // cuts loops (report_cut_loops).
        report_cut_loops();
        return;
    }
    let walks = pc.mode == STAGE_WALKS;
    let queued = params.pixel_queue != 0u && (pc.mode == STAGE_MEGAKERNEL || pc.mode == STAGE_PATHS);
    let tiles_x = (params.width + 7u) / 8u;
    let queue_len = 64u * tiles_x * ((params.height + 7u) / 8u);
    let pixels = params.width * params.height;
    var all_rays = 0u;
    var first = true;
    loop {
        var p = 0u;
        var iterations = pc.sample_count;
        var job = NO_SLOT;
        var pix = gid.xy;
        var mine = true;
        if (walks) {
            if (!first) {
                break;
            }
            let k = lid + 64u * (wid.x + wid.y * nwg.x);
            mine = k < atomicLoad(&counters[1]);
            if (mine) {
                job = bitcast<u32>(probe_in[queue_entry(k)].x);
            }
            iterations = 1u;
        } else {
            var tile = wid.xy;
            var q = lid;
            if (queued) {
                let j = atomicAdd(&counters[PIXEL_QUEUE_WORD], 1u);
                if (j >= queue_len) {
                    break;
                }
                let t = j >> 6u;
                tile = vec2<u32>(t % tiles_x, t / tiles_x);
                q = j & 63u;
            } else if (!first) {
                break;
            }
            pix = tile * 8u + vec2<u32>(q & 7u, q >> 3u);
            mine = pix.x < params.width && pix.y < params.height;
            p = pix.y * params.width + pix.x;
            if (pc.mode == STAGE_GATHER) {
                if (mine) {
                    job_gather(p);
                }
                mine = false;
            }
        }
        first = false;
        if (!mine) {
            continue;
        }
        var rays = 0u;
        for (var i = 0u; i < iterations; i++) {
            let s = pc.sample_start + i;
            var rng: Rng;
            var start: PathStart;
            var go = true;
            var defer_slot = NO_SLOT;
            if (walks) {
                go = job_resume(job, &rng, &rays, &start);
            } else {
                rng = rng_init(p, s, params.seed);
                start.ray = camera_ray(pix, rng_next2(&rng));
                start.throughput = vec3<f32>(1.0);
                if (pc.mode == STAGE_PATHS) {
                    defer_slot = i * pixels + p;
                    job_clear(defer_slot);
                }
            }
            var ps = passes_zero();
            var l = vec3<f32>(0.0);
            if (go) {
                l = trace_path(start, p, s, defer_slot, &rng, &rays, &ps);
            }
            if (walks) {
                // The gather stage filters and adds it, one writer per pixel.
                job_finish(job, l, ps);
            }
        }
        all_rays += rays;
        if (TRAVERSAL_COUNTERS && !walks) {
            let b = TC_FIRST + TC_WORDS * p;
            atomicAdd(&counters[b], rays);
            atomicAdd(&counters[b + 1u], tc_nodes);
            atomicAdd(&counters[b + 2u], tc_prims);
            atomicAdd(&counters[b + 3u], tc_blas);
            atomicMax(&counters[b + 4u], tc_depth);
            atomicAdd(&counters[b + 5u], tc_overflow);
            atomicAdd(&counters[b + 6u], tc_nonfinite);
            atomicAdd(&counters[b + 7u], tc_turns);
            atomicAdd(&counters[b + 8u], tc_simd_turns);
            atomicAdd(&counters[b + 9u], tc_simd_prims);
            tc_reset();
        }
    }
    atomicAdd(&counters[0], all_rays);
    report_cut_loops();
}
