// HDR environment lights: lat-long maps with the project's convention (u = atan2(x, -z) / 2π,
// v = acos(y) / π, +Y up), a per-light rotation about +Y and a horizontal flip, importance-sampled
// with the piecewise-constant 2D distribution built by `lightfarm_light::EnvSampler`. A disc light
// (ENV_DISC) is a cone of constant radiance about a world axis, sampled uniformly inside the
// cone: its density is proportional to its radiance, as the map's is.

fn disc_inside(e: EnvDesc, d: vec3<f32>) -> bool {
    return 1.0 - dot(d, e.disc.xyz) <= e.disc.w;
}

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
    if (e.kind == ENV_DISC) {
        return select(vec3<f32>(0.0), e.disc_radiance.xyz, disc_inside(e, d));
    }
    let uv = env_dir_to_uv(env_world_to_local(e, d));
    let xy = env_texel(e, uv);
    return env_texels[e.texel_offset + xy.y * e.width + xy.x].xyz;
}

struct EnvSample {
    dir: vec3<f32>,
    pdf: f32,
    radiance: vec3<f32>,
};

// Picks a texel with Walker's alias method (one lookup instead of two binary searches): `r` picks
// the cell, u.x decides between it and its alias (an independent number: reusing the fraction of
// the cell choice would quantise the decision to a few bits on large maps), u.yz place the sample
// uniformly inside the texel, so the density is exactly the piecewise-constant one of env_pdf().
fn env_sample(light: u32, r: u32, u: vec3<f32>) -> EnvSample {
    let e = env_desc[light];
    if (e.kind == ENV_DISC) {
        // cos θ uniform in [1 - (1 - cos r), 1]; sin²θ from (1 - cos θ)(1 + cos θ) keeps the
        // precision a 4° disc needs.
        let omc = u.y * e.disc.w;
        let cos_t = 1.0 - omc;
        let sin_t = sqrt(max(omc * (2.0 - omc), 0.0));
        let phi = 2.0 * PI * u.z;
        let local = vec3<f32>(sin_t * cos(phi), sin_t * sin(phi), cos_t);
        let dir = normalize(to_world(frame_from_normal(e.disc.xyz), local));
        return EnvSample(dir, e.disc_radiance.w, e.disc_radiance.xyz);
    }
    let i = uniform_index(r, e.width * e.height);
    var cell = i;
    if (u.x >= env_dist[e.alias_offset + 2u * i]) {
        cell = bitcast<u32>(env_dist[e.alias_offset + 2u * i + 1u]);
    }
    let x = cell % e.width;
    let y = cell / e.width;
    let uv = vec2<f32>((f32(x) + u.y) / f32(e.width), (f32(y) + u.z) / f32(e.height));
    let func = env_dist[e.cond_func_offset + cell];
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
    let radiance = env_texels[e.texel_offset + cell].xyz;
    return EnvSample(env_local_to_world(e, local), pdf, radiance);
}

fn env_pdf(light: u32, d: vec3<f32>) -> f32 {
    let e = env_desc[light];
    if (e.kind == ENV_DISC) {
        return select(0.0, e.disc_radiance.w, disc_inside(e, d));
    }
    let uv = env_dir_to_uv(env_world_to_local(e, d));
    let xy = env_texel(e, uv);
    let sin_theta = sin(uv.y * PI);
    if (sin_theta <= 0.0 || e.marg_integral <= 0.0) {
        return 0.0;
    }
    let func = env_dist[e.cond_func_offset + xy.y * e.width + xy.x];
    return (func / e.marg_integral) / (2.0 * PI * PI * sin_theta);
}
