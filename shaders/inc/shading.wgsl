// From a traversal hit to what the integrator shades: world position, geometric and shading
// normals (with normal mapping), and the material's parameters at the hit (with textures).

struct ShadingPoint {
    p: vec3<f32>,
    ng: vec3<f32>,      // geometric normal, world space, unit, facing the incoming ray
    frame: Frame,       // shading frame (z = shading normal, same side as ng)
    material: u32,
    flags: u32,         // material flags (MAT_FLAG_LENS, MAT_FLAG_THIN)
    opacity: f32,       // glTF alpha coverage
    surface: Surface,
    albedo: vec3<f32>,  // base colour at the hit (the albedo pass)
    // A fibre (hair.wgsl): frame.t is its tangent, frame.n the cylinder normal at the hit, ng
    // the same; there is no inside or outside hemisphere, and `p` is already the spawn point
    // just inside the fibre (see `spawn_origin`).
    fibre: bool,
};

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

fn unpack_rgba8(w: u32) -> vec4<f32> {
    return vec4<f32>(f32(w & 0xffu), f32((w >> 8u) & 0xffu), f32((w >> 16u) & 0xffu), f32(w >> 24u)) / 255.0;
}

fn texel_fetch(d: vec4<u32>, x: i32, y: i32) -> vec4<f32> {
    let w = i32(d.y);
    let h = i32(d.z);
    let xi = ((x % w) + w) % w;
    let yi = ((y % h) + h) % h;
    return unpack_rgba8(tex_data[d.x + u32(yi * w + xi)]);
}

// Bilinear lookup with repeat wrapping (the glTF default sampler).
fn texture_sample(index: u32, uv: vec2<f32>) -> vec4<f32> {
    let d = tex_desc[index];
    let st = uv * vec2<f32>(f32(d.y), f32(d.z)) - vec2<f32>(0.5);
    let fl = floor(st);
    let fr = st - fl;
    let x = i32(fl.x);
    let y = i32(fl.y);
    let a = mix(texel_fetch(d, x, y), texel_fetch(d, x + 1, y), fr.x);
    let b = mix(texel_fetch(d, x, y + 1), texel_fetch(d, x + 1, y + 1), fr.x);
    return mix(a, b, fr.y);
}

fn shade_hit(ray: Ray, hit: Hit) -> ShadingPoint {
    if (hit_is_curve(hit)) {
        return shade_fibre(ray, hit);
    }
    let inst = instances[hit.instance];
    let slot = hit.tri;
    let a0 = tri_attr[slot * TRI_ATTR_VEC4S];
    let a1 = tri_attr[slot * TRI_ATTR_VEC4S + 1u];
    let a2 = tri_attr[slot * TRI_ATTR_VEC4S + 2u];
    let a3 = tri_attr[slot * TRI_ATTR_VEC4S + 3u];
    let a4 = tri_attr[slot * TRI_ATTR_VEC4S + 4u];
    let w = 1.0 - hit.u - hit.v;
    let uv = vec2<f32>(a0.w, a1.w) * w + vec2<f32>(a2.w, a3.x) * hit.u + a3.yz * hit.v;
    let mat_id = triangle_material(slot);
    let mat = materials[mat_id];

    let v0 = tri_record(slot * 3u).xyz;
    let v1 = tri_record(slot * 3u + 1u).xyz;
    let v2 = tri_record(slot * 3u + 2u).xyz;
    let p_obj = v0 * w + v1 * hit.u + v2 * hit.v;
    let p = transform_point(inst.obj_to_world, p_obj);

    // Normals transform with the inverse transpose: n_world = transpose(world_to_obj) * n_obj.
    let nt = transpose(inst.world_to_obj);
    var ng = normalize(transform_dir(nt, cross(v1 - v0, v2 - v0)));
    var ns_obj = a0.xyz * w + a1.xyz * hit.u + a2.xyz * hit.v;
    if (dot(ns_obj, ns_obj) < 1e-12) {
        ns_obj = cross(v1 - v0, v2 - v0);
    }
    var ns = normalize(transform_dir(nt, ns_obj));
    // A mesh without UVs has all-zero tangents: the frame then comes from the normal alone.
    // (Not `normalize(t + 1e-20)`: its squared length is a denormal, which llvmpipe with LLVM 19
    // and NVIDIA flush to zero, and the frame became NaN, and with it every later ray.)
    let t_world = transform_dir(inst.obj_to_world, a4.xyz);
    let t_len2 = dot(t_world, t_world);
    let tangent = select(vec3<f32>(0.0), normalize(t_world), t_len2 > 1e-30);

    // Face the incoming ray; the shading normal follows the geometric side.
    let from_back = dot(ng, ray.dir) > 0.0;
    if (from_back) {
        ng = -ng;
    }
    if (dot(ns, ng) < 0.0) {
        ns = -ns;
    }

    var frame = frame_from_normal_tangent(ns, tangent);
    if (mat.tex.z != NO_TEX && dot(a4.xyz, a4.xyz) > 0.0) {
        let t = texture_sample(mat.tex.z, uv).xyz * 2.0 - vec3<f32>(1.0);
        let sign = select(1.0, -1.0, a4.w < 0.0);
        let tn = vec3<f32>(t.xy * mat.extra.x, t.z);
        let mapped = normalize(frame.t * tn.x + frame.b * sign * tn.y + frame.n * max(tn.z, 1e-3));
        if (dot(mapped, ng) > 0.0) {
            frame = frame_from_normal_tangent(mapped, frame.t);
        }
    }

    var base = mat.base_color.xyz;
    if (mat.tex.x != NO_TEX) {
        base *= srgb_to_linear(texture_sample(mat.tex.x, uv).xyz);
    }
    var metallic = mat.mrst.x;
    var roughness = mat.mrst.y;
    if (mat.tex.y != NO_TEX) {
        let mr = texture_sample(mat.tex.y, uv);
        roughness *= mr.y;
        metallic *= mr.z;
    }
    let alpha = max(roughness * roughness, 1e-3);
    // Frames face the incoming ray, so a dielectric learns from the side it was hit on whether the
    // ray leaves the (outward-facing) surface: then the relative index of refraction inverts.
    // A thin sheet has air on both sides: its index never inverts.
    let thin = (mat.tex.w & MAT_FLAG_THIN) != 0u;
    var ior = max(mat.spec_color_ior.w, 1.0001);
    if (from_back && mat.mrst.w > 0.5 && !thin) {
        ior = 1.0 / ior;
    }
    var specular = mat.mrst.z;
    if (mat.tex2.x != NO_TEX) {
        // KHR_materials_specular: the specular texture's A channel.
        specular *= texture_sample(mat.tex2.x, uv).w;
    }
    // The paper's skin scatters its diffuse texture: a negative subsurface colour means "the base".
    let sss_color = select(mat.sss.xyz, base, mat.sss.x < 0.0);
    let coat_alpha = max(mat.coat_sheen.x * mat.coat_sheen.x, 1e-3);
    let surface = Surface(base, clamp(metallic, 0.0, 1.0), alpha, specular, mat.spec_color_ior.xyz, mat.mrst.w, ior,
        mat.tex2.y, mat.sss.w, sss_color, mat.sss_mfp.xyz, mat.sss_mfp.w,
        mat.coat.w, mat.coat.xyz, coat_alpha, mat.coat_sheen.y, mat.coat_sheen.z, mat.sheen_color.xyz, mat.coat_sheen.w, thin,
        vec3<f32>(0.0), vec4<f32>(0.0));
    return ShadingPoint(p, ng, frame, mat_id, mat.tex.w, mat.extra.y, surface, base, false);
}

// The signed offset h ∈ [-1, 1] of hair.wgsl for a ray leaving along `wo` from the fibre point
// with cylinder normal `n` around tangent `t`: with ŵ the projection of wo across the fibre,
// n = cos γ ŵ - sin γ (t × ŵ) and h = sin γ, so that the mirror reflection turns ŵ by -2γ.
fn fibre_h(wo: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> f32 {
    let w = wo - t * dot(wo, t);
    let len2 = dot(w, w);
    if (len2 < 1e-12) {
        return 0.0;
    }
    return clamp(dot(n, cross(w * inverseSqrt(len2), t)), -1.0, 1.0);
}


// How far inside the fibre its rays start, as a fraction of the radius.
const FIBRE_SPAWN_DEPTH: f32 = 0.05;

fn shade_fibre(ray: Ray, hit: Hit) -> ShadingPoint {
    let inst = instances[hit.instance];
    let a = tri_record(hit.tri);
    let b = tri_record(hit.tri + 1u);
    let mat_id = inst.material;
    let mat = materials[mat_id];
    // Object space: the ray point, the closest point on the axis and the radius there.
    let p = transform_point(inst.world_to_obj, ray.origin + hit.t * ray.dir);
    let axis = b.xyz - a.xyz;
    let len = max(length(axis), 1e-30);
    let ax = axis / len;
    let z = clamp(dot(p - a.xyz, ax), 0.0, len);
    let c = a.xyz + ax * z;
    var radial = p - c;
    radial -= ax * dot(radial, ax);
    let d_obj = transform_dir(inst.world_to_obj, ray.dir);
    if (dot(radial, radial) < 1e-24) {
        // The pole of a cap: the side facing the ray.
        radial = -(d_obj - ax * dot(d_obj, ax));
    }
    let n_obj = normalize(radial + vec3<f32>(1e-30));
    let t = normalize(transform_dir(inst.obj_to_world, ax));
    var n = transform_dir(transpose(inst.world_to_obj), n_obj);
    n = normalize(n - t * dot(n, t) + vec3<f32>(1e-30));
    let frame = Frame(t, cross(n, t), n);
    // Rays leave from just inside the hit: traversal only counts entering crossings, so no ray
    // from there sees the walls of this fibre, and FIBRE_SPAWN_DEPTH keeps it clear of the
    // slivers where two tapered cones meet at a mitre. Leaving from the axis instead shadowed
    // grazing light between packed fibres that reaches their fronts (bench/cycles_hair.py:
    // 1% of Cycles' radiance with light 5° above a sheet).
    let rz = mix(abs(a.w), abs(b.w), z / len);
    let spawn = transform_point(inst.obj_to_world, c + n_obj * (rz * (1.0 - FIBRE_SPAWN_DEPTH)));
    let h = fibre_h(-ray.dir, n, t);
    var surface = Surface(mat.base_color.xyz, 0.0, 1.0, 0.0, vec3<f32>(0.0), 0.0, max(mat.spec_color_ior.w, 1.0001),
        MODEL_HAIR, 0.0, vec3<f32>(0.0), vec3<f32>(1.0), 0.0, 0.0, vec3<f32>(0.0), 1.0, 1.5, 0.0, vec3<f32>(0.0), 1.0, false,
        mat.hair_sigma.xyz, vec4<f32>(mat.hair.xyz, h));
    return ShadingPoint(spawn, n, frame, mat_id, 0u, 1.0, surface, mat.base_color.xyz, true);
}

// Where a ray leaving `sp` along `dir` starts: off a surface on dir's side, or a fibre's
// spawn point.
fn spawn_origin(sp: ShadingPoint, dir: vec3<f32>) -> vec3<f32> {
    if (sp.fibre) {
        return sp.p;
    }
    return offset_origin(sp.p, sp.ng, dir);
}

// Offsets a ray origin off the surface along the geometric normal, scaled with the magnitude of
// the position so float precision is respected away from the origin.
fn offset_origin(p: vec3<f32>, ng: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let scale = 1e-4 * (1.0 + max3(abs(p)));
    return p + ng * select(-scale, scale, dot(dir, ng) > 0.0);
}
