// HDR environment lights: lat-long maps with the project's convention (u = atan2(x, -z) / 2π,
// v = acos(y) / π, +Y up), a per-light rotation about +Y and a horizontal flip, importance-sampled
// with the piecewise-constant 2D distribution built by `lightfarm_light::EnvSampler`.

fn env_world_to_local(e: EnvDesc, d: vec3<f32>) -> vec3<f32> {
    // R_y(-θ): x' = cosθ x - sinθ z, z' = sinθ x + cosθ z; then the flip negates x.
    var l = vec3<f32>(e.cos_rot * d.x - e.sin_rot * d.z, d.y, e.sin_rot * d.x + e.cos_rot * d.z);
    if (e.flip != 0u) {
        l.x = -l.x;
    }
    return l;
}

fn env_local_to_world(e: EnvDesc, l_in: vec3<f32>) -> vec3<f32> {
    var l = l_in;
    if (e.flip != 0u) {
        l.x = -l.x;
    }
    return vec3<f32>(e.cos_rot * l.x + e.sin_rot * l.z, l.y, -e.sin_rot * l.x + e.cos_rot * l.z);
}

fn env_dir_to_uv(l: vec3<f32>) -> vec2<f32> {
    var u = atan2(l.x, -l.z) * (0.5 * INV_PI);
    if (u < 0.0) {
        u += 1.0;
    }
    let v = acos(clamp(l.y, -1.0, 1.0)) * INV_PI;
    return vec2<f32>(u, v);
}

fn env_uv_to_dir(uv: vec2<f32>) -> vec3<f32> {
    let phi = uv.x * 2.0 * PI;
    let theta = uv.y * PI;
    let s = sin(theta);
    return vec3<f32>(s * sin(phi), cos(theta), -s * cos(phi));
}

fn env_texel(e: EnvDesc, uv: vec2<f32>) -> vec2<u32> {
    let x = min(u32(max(uv.x, 0.0) * f32(e.width)), e.width - 1u);
    let y = min(u32(max(uv.y, 0.0) * f32(e.height)), e.height - 1u);
    return vec2<u32>(x, y);
}

// Radiance arriving from world direction d (nearest texel: the same piecewise-constant function the
// sampler's pdf is built from, so MIS weights stay exact).
fn env_eval(light: u32, d: vec3<f32>) -> vec3<f32> {
    let e = env_desc[light];
    let uv = env_dir_to_uv(env_world_to_local(e, d));
    let xy = env_texel(e, uv);
    return env_texels[e.texel_offset + xy.y * e.width + xy.x].xyz;
}

// Index of the last cdf entry <= u among `count + 1` entries starting at `off`.
fn find_interval(off: u32, count: u32, u: f32) -> u32 {
    var lo = 0u;
    var hi = count; // cdf[count] == 1 > u
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (env_dist[off + mid] <= u) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

struct EnvSample {
    dir: vec3<f32>,
    pdf: f32,
    radiance: vec3<f32>,
};

fn env_sample(light: u32, u: vec2<f32>) -> EnvSample {
    let e = env_desc[light];
    // Rows (v) from the marginal, then the column (u) from that row's conditional.
    let y = find_interval(e.marg_cdf_offset, e.height, u.y);
    let c0 = env_dist[e.marg_cdf_offset + y];
    let c1 = env_dist[e.marg_cdf_offset + y + 1u];
    var dv = u.y - c0;
    if (c1 - c0 > 0.0) {
        dv /= (c1 - c0);
    }
    let cdf_off = e.cond_cdf_offset + y * (e.width + 1u);
    let x = find_interval(cdf_off, e.width, u.x);
    let d0 = env_dist[cdf_off + x];
    let d1 = env_dist[cdf_off + x + 1u];
    var du = u.x - d0;
    if (d1 - d0 > 0.0) {
        du /= (d1 - d0);
    }
    let uv = vec2<f32>((f32(x) + clamp(du, 0.0, 1.0)) / f32(e.width), (f32(y) + clamp(dv, 0.0, 1.0)) / f32(e.height));
    let func = env_dist[e.cond_func_offset + y * e.width + x];
    var pdf_uv = 0.0;
    if (e.marg_integral > 0.0) {
        pdf_uv = func / e.marg_integral;
    }
    let local = env_uv_to_dir(uv);
    let sin_theta = sin(uv.y * PI);
    var pdf = 0.0;
    if (sin_theta > 0.0) {
        pdf = pdf_uv / (2.0 * PI * PI * sin_theta);
    }
    let radiance = env_texels[e.texel_offset + y * e.width + x].xyz;
    return EnvSample(env_local_to_world(e, local), pdf, radiance);
}

fn env_pdf(light: u32, d: vec3<f32>) -> f32 {
    let e = env_desc[light];
    let uv = env_dir_to_uv(env_world_to_local(e, d));
    let xy = env_texel(e, uv);
    let sin_theta = sin(uv.y * PI);
    if (sin_theta <= 0.0 || e.marg_integral <= 0.0) {
        return 0.0;
    }
    let func = env_dist[e.cond_func_offset + xy.y * e.width + xy.x];
    return (func / e.marg_integral) / (2.0 * PI * PI * sin_theta);
}
