// The random walk of subsurface scattering through the medium under a layered surface whose
// subsurface lobe was picked (layered.wgsl). Cycles' subsurface_random_walk.h is the model:
// enter through the specular interface, free flights with the channel picked by spectral MIS,
// Henyey–Greenstein scattering, boundaries found by rays that see only the entry object's
// triangles of the entry material, a bounded number of steps; the light leaves through a
// diffuse (Lambertian, index-matched) exit, which the integrator shades as its next vertex.

const WALK_MAX_STEPS: u32 = 256u;

struct WalkExit {
    ok: bool,
    weight: vec3<f32>,  // the walk's throughput: exit transmittance × scattering over the pdfs
    sp: ShadingPoint,   // exit point; ng and the frame face out of the medium
};

// Closest hit of `ray` among the triangles of one instance with material `mat`, within tmax.
fn trace_in_object(inst_id: u32, mat: u32, ray: Ray) -> Hit {
    var best = no_hit();
    best.t = ray.tmax;
    let inst = instances[inst_id];
    let o = transform_point(inst.world_to_obj, ray.origin);
    let d = transform_dir(inst.world_to_obj, ray.dir);
    if (traverse_blas(inst_id, o, d, ray.tmin, &best, false, mat)) {
        return best;
    }
    return no_hit();
}

// Below the entry surface by a few float ulps of the position: the blue mean free path of skin
// is 0.45 mm, so the 0.1 mm of `offset_origin` would be a fifth of it.
fn walk_offset(p: vec3<f32>) -> f32 {
    return 2e-6 * (1.0 + max3(abs(p)));
}

// The surface a walk leaves through: white Lambert (the medium's colour is in the walk weight).
fn exit_surface() -> Surface {
    return Surface(vec3<f32>(1.0), 0.0, 1.0, 0.0, vec3<f32>(0.0), 0.0, 1.5,
        MODEL_GLTF, 0.0, vec3<f32>(0.0), vec3<f32>(1.0), 0.0, 0.0, vec3<f32>(0.0), 1.0, 1.5, 0.0, vec3<f32>(0.0), 1.0, false,
        vec3<f32>(0.0), vec4<f32>(0.0));
}

fn random_walk(sp: ShadingPoint, inst: u32, wo: vec3<f32>, rng: ptr<function, Rng>, rays: ptr<function, u32>) -> WalkExit {
    var out: WalkExit;
    out.ok = false;
    let s = sp.surface;
    let alpha = sss_albedo(s.sss_color, s.sss_g);
    let sigma_t = vec3<f32>(1.0) / max(s.sss_mfp, vec3<f32>(1e-7));
    let sigma_s = alpha * sigma_t;
    let d_local = sss_entry_dir(wo, s.alpha, s.ior, rng_next2(rng));
    if (d_local.z >= 0.0) {
        return out;
    }
    var dir = to_world(sp.frame, d_local);
    if (dot(dir, sp.ng) >= 0.0) {
        // A normal map tilted the refraction above the geometry: mirror it into the medium.
        dir = dir - 2.0 * dot(dir, sp.ng) * sp.ng;
    }
    var pos = sp.p - sp.ng * walk_offset(sp.p);
    var tp = vec3<f32>(1.0);
    for (var step = 0u; step < WALK_MAX_STEPS; step++) {
        let probs = sss_channel_probs(tp, alpha);
        let c = sss_pick_channel(probs, rng_next(rng));
        let t = sss_flight(sigma_t, c, rng_next(rng));
        *rays += 1u;
        let h = trace_in_object(inst, sp.material, Ray(pos, dir, 0.0, t));
        if (h.t >= 0.0) {
            tp *= exp(-sigma_t * h.t) / sss_pass_pdf(probs, sigma_t, h.t);
            var ex = shade_hit(Ray(pos, dir, 0.0, 3.4e38), h);
            // shade_hit faces the walk's ray (inside); the light leaves to the other side.
            ex.ng = -ex.ng;
            ex.frame = frame_from_normal_tangent(-ex.frame.n, ex.frame.t);
            ex.surface = exit_surface();
            out.ok = all(tp == tp);
            out.weight = tp;
            out.sp = ex;
            return out;
        }
        tp *= sigma_s * exp(-sigma_t * t) / sss_collision_pdf(probs, sigma_t, t);
        if (!(max3(tp) > 0.0)) {
            return out;
        }
        pos = pos + dir * t;
        dir = hg_sample(dir, s.sss_g, rng_next2(rng));
    }
    return out;
}
