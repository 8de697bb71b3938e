// Surface scattering for glTF metallic-roughness materials (MODEL_GLTF; the layered Standard
// Surface of the other models is layered.wgsl, which dispatches between both): Lambert diffuse + GGX specular
// (roughness r -> α = r², visible-normal sampling with spherical caps, Dupuy & Benyoub 2023),
// metals through F0 = base colour, KHR_materials_specular (specular 0 => pure diffuse), and a
// smooth dielectric for transmissive materials (eyeglass lenses; thin-walled: a clear sheet such as
// a cornea, thin_sheet_reflectance). All directions are in the local
// shading frame (z = normal). `f` values include the cosine of the incoming direction.

struct Surface {
    base: vec3<f32>,
    metallic: f32,
    alpha: f32,
    specular: f32,
    spec_color: vec3<f32>,
    transmission: f32,
    ior: f32,
    // The layered Standard Surface (layered.wgsl) when model != MODEL_GLTF; the glTF mapping
    // below ignores the rest.
    model: u32,
    sss: f32,
    sss_color: vec3<f32>,
    sss_mfp: vec3<f32>,
    sss_g: f32,
    coat: f32,
    coat_color: vec3<f32>,
    coat_alpha: f32,
    coat_ior: f32,
    sheen: f32,
    sheen_color: vec3<f32>,
    sheen_rough: f32,
    // Transmissive and thin-walled (MAT_FLAG_THIN): a clear sheet, not a refracting boundary.
    thin: bool,
    // A fibre (MODEL_HAIR, hair.wgsl): absorption per unit radius, and (βm, βn, tilt α in
    // radians, h). Zero for surfaces.
    hair_sigma: vec3<f32>,
    hair: vec4<f32>,
};

struct BsdfEval {
    f_cos: vec3<f32>, // f(wo, wi) * |cos θi|
    pdf: f32,          // solid-angle pdf of sampling wi given wo
};

struct BsdfSample {
    wi: vec3<f32>,
    weight: vec3<f32>, // f * cos / pdf (delta lobes: the lobe's weight)
    pdf: f32,
    is_delta: bool,
    valid: bool,
    // The subsurface lobe was picked: no direction here; the integrator runs the random walk
    // and `weight` is what enters the medium over the probability of picking the lobe.
    subsurface: bool,
};

fn is_dielectric_delta(s: Surface) -> bool {
    return s.transmission > 0.5;
}

// --- GGX (isotropic) ---

fn ggx_d(m: vec3<f32>, a: f32) -> f32 {
    let a2 = a * a;
    let c2 = m.z * m.z;
    let d = c2 * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

fn ggx_lambda(w: vec3<f32>, a: f32) -> f32 {
    let c2 = w.z * w.z;
    if (c2 >= 1.0) {
        return 0.0;
    }
    let t2 = (1.0 - c2) / max(c2, 1e-12);
    return (sqrt(1.0 + a * a * t2) - 1.0) * 0.5;
}

fn ggx_g1(w: vec3<f32>, a: f32) -> f32 {
    return 1.0 / (1.0 + ggx_lambda(w, a));
}

fn ggx_g2(wo: vec3<f32>, wi: vec3<f32>, a: f32) -> f32 {
    return 1.0 / (1.0 + ggx_lambda(wo, a) + ggx_lambda(wi, a));
}

// Visible normal of the upper hemisphere, wo.z > 0.
fn ggx_sample_vndf(wo: vec3<f32>, a: f32, u: vec2<f32>) -> vec3<f32> {
    let wh = normalize(vec3<f32>(a * wo.x, a * wo.y, wo.z));
    let phi = 2.0 * PI * u.x;
    let z = (1.0 - u.y) * (1.0 + wh.z) - wh.z;
    let sin_theta = sqrt(clamp(1.0 - z * z, 0.0, 1.0));
    let c = vec3<f32>(sin_theta * cos(phi), sin_theta * sin(phi), z);
    let h = c + wh;
    return normalize(vec3<f32>(a * h.x, a * h.y, max(h.z, 0.0)));
}

// pdf of a reflected direction sampled through the VNDF: D_wo(m) / (4 wo·m) = G1(wo) D(m) / (4 wo.z).
fn ggx_reflection_pdf(wo: vec3<f32>, m: vec3<f32>, a: f32) -> f32 {
    return ggx_g1(wo, a) * ggx_d(m, a) / (4.0 * wo.z);
}

// --- Fresnel ---

fn schlick(f0: vec3<f32>, f90: vec3<f32>, c: f32) -> vec3<f32> {
    let m = clamp(1.0 - c, 0.0, 1.0);
    let m2 = m * m;
    return f0 + (f90 - f0) * (m2 * m2 * m);
}

// Unpolarised Fresnel reflectance of a smooth dielectric; cos_i signed (negative = from inside).
fn fresnel_dielectric(cos_i_in: f32, eta_in: f32) -> f32 {
    var cos_i = clamp(cos_i_in, -1.0, 1.0);
    var eta = eta_in;
    if (cos_i < 0.0) {
        eta = 1.0 / eta;
        cos_i = -cos_i;
    }
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0) {
        return 1.0;
    }
    let cos_t = sqrt(max(0.0, 1.0 - sin2_t));
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5 * (r_parl * r_parl + r_perp * r_perp);
}

// A thin smooth sheet of index `eta` in air, both faces and the light bouncing between them
// summed: R + T²R / (1 − R²) = 2R / (1 + R), with R the single-interface Fresnel. What is not
// reflected passes straight through (nothing absorbs), so the shadow rays' transmittance
// 1 − this is exact for a sheet, which is what MIS through it relies on.
fn thin_sheet_reflectance(cos_i: f32, eta: f32) -> f32 {
    let r = fresnel_dielectric(abs(cos_i), eta);
    return 2.0 * r / (1.0 + r);
}

// --- the glTF metallic-roughness model (MODEL_GLTF) ---

fn surface_f0(s: Surface) -> vec3<f32> {
    let r = (s.ior - 1.0) / (s.ior + 1.0);
    let f0_dielectric = min(vec3<f32>(r * r) * s.spec_color, vec3<f32>(1.0)) * s.specular;
    return mix(f0_dielectric, s.base, s.metallic);
}

fn surface_f90(s: Surface) -> vec3<f32> {
    return vec3<f32>(mix(s.specular, 1.0, s.metallic));
}

fn diffuse_color(s: Surface) -> vec3<f32> {
    return s.base * (1.0 - s.metallic);
}

// Probability of picking the specular lobe: its Fresnel weight at the viewing angle against the
// diffuse weight, so that neither lobe is starved.
fn spec_probability(s: Surface, wo: vec3<f32>) -> f32 {
    let fs = luminance(schlick(surface_f0(s), surface_f90(s), wo.z));
    let fd = luminance(diffuse_color(s)) * (1.0 - max3(schlick(surface_f0(s), surface_f90(s), wo.z)));
    if (fs <= 0.0) {
        return 0.0;
    }
    if (fd <= 0.0) {
        return 1.0;
    }
    return clamp(fs / (fs + fd), 0.1, 0.9);
}

fn gltf_eval(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> BsdfEval {
    var out = BsdfEval(vec3<f32>(0.0), 0.0);
    if (is_dielectric_delta(s) || wo.z <= 0.0 || wi.z <= 0.0) {
        return out;
    }
    let p_spec = spec_probability(s, wo);
    let f0 = surface_f0(s);
    let f90 = surface_f90(s);
    // Diffuse, attenuated by the energy the specular layer reflects at the viewing angle.
    let kd = diffuse_color(s) * (vec3<f32>(1.0) - schlick(f0, f90, wo.z) * (1.0 - s.metallic));
    out.f_cos = kd * INV_PI * wi.z;
    out.pdf = (1.0 - p_spec) * wi.z * INV_PI;
    if (p_spec > 0.0) {
        let m = normalize(wo + wi);
        let a = max(s.alpha, 1e-4);
        let d = ggx_d(m, a);
        let g = ggx_g2(wo, wi, a);
        let f = schlick(f0, f90, dot(wo, m));
        out.f_cos += f * (d * g / (4.0 * wo.z));
        out.pdf += p_spec * ggx_reflection_pdf(wo, m, a);
    }
    return out;
}

// gltf_eval's f·cos split into its diffuse and specular terms (the appendix passes): zero in
// the coat and sheen members, which layered.wgsl's Lobes also has.
fn gltf_lobes_parts(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> array<vec3<f32>, 2> {
    if (is_dielectric_delta(s) || wo.z <= 0.0 || wi.z <= 0.0) {
        return array<vec3<f32>, 2>(vec3<f32>(0.0), vec3<f32>(0.0));
    }
    let f0 = surface_f0(s);
    let f90 = surface_f90(s);
    let kd = diffuse_color(s) * (vec3<f32>(1.0) - schlick(f0, f90, wo.z) * (1.0 - s.metallic));
    var spec = vec3<f32>(0.0);
    if (spec_probability(s, wo) > 0.0) {
        let m = normalize(wo + wi);
        let a = max(s.alpha, 1e-4);
        spec = schlick(f0, f90, dot(wo, m)) * (ggx_d(m, a) * ggx_g2(wo, wi, a) / (4.0 * wo.z));
    }
    return array<vec3<f32>, 2>(kd * INV_PI * wi.z, spec);
}

fn gltf_sample(s: Surface, wo: vec3<f32>, u_lobe: f32, u: vec2<f32>) -> BsdfSample {
    var out = BsdfSample(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, false, false, false);
    if (is_dielectric_delta(s) && s.thin) {
        let f = thin_sheet_reflectance(wo.z, s.ior);
        out.wi = select(-wo, vec3<f32>(-wo.x, -wo.y, wo.z), u_lobe < f);
        out.weight = vec3<f32>(1.0);
        out.pdf = select(1.0 - f, f, u_lobe < f);
        out.is_delta = true;
        out.valid = true;
        return out;
    }
    if (is_dielectric_delta(s)) {
        let f = fresnel_dielectric(wo.z, s.ior);
        if (u_lobe < f) {
            out.wi = vec3<f32>(-wo.x, -wo.y, wo.z);
            out.weight = vec3<f32>(1.0);
            out.pdf = f;
        } else {
            // Refraction; radiance is scaled by 1/η² (pbrt's radiance transport mode).
            var eta = s.ior;
            var n = vec3<f32>(0.0, 0.0, 1.0);
            var cos_i = wo.z;
            if (cos_i < 0.0) {
                eta = 1.0 / eta;
                n = -n;
                cos_i = -cos_i;
            }
            let sin2_t = max(0.0, 1.0 - cos_i * cos_i) / (eta * eta);
            let cos_t = sqrt(max(0.0, 1.0 - sin2_t));
            out.wi = -wo / eta + (cos_i / eta - cos_t) * n;
            out.weight = vec3<f32>(1.0 / (eta * eta));
            out.pdf = 1.0 - f;
        }
        out.is_delta = true;
        out.valid = true;
        return out;
    }
    if (wo.z <= 0.0) {
        return out;
    }
    let p_spec = spec_probability(s, wo);
    var wi: vec3<f32>;
    if (u_lobe < p_spec) {
        let m = ggx_sample_vndf(wo, max(s.alpha, 1e-4), u);
        wi = reflect(-wo, m);
    } else {
        wi = sample_cosine_hemisphere(u);
    }
    if (wi.z <= 0.0) {
        return out;
    }
    let e = gltf_eval(s, wo, wi);
    if (e.pdf <= 0.0) {
        return out;
    }
    out.wi = wi;
    out.pdf = e.pdf;
    out.weight = e.f_cos / e.pdf;
    out.valid = true;
    return out;
}
