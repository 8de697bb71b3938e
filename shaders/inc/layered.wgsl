// The layered Standard Surface (Autodesk Standard Surface / OpenPBR, the paper's aiStandardSurface)
// for every material model but MODEL_GLTF, and the dispatch between it and the glTF mapping.
//
// Layers, top to bottom, each albedo-scaled by the directional albedo E(μo) of the layers above:
//   coat·f_coat + [(1 − coat) + coat·coat_color·(1 − E_coat)] ·
//     ( metal·f_metal + (1 − metal) · ( ws·f_spec + (1 − ws·E_spec) ·
//        ( sheen·sheen_color·f_sheen + (1 − sheen·max(sheen_color)·E_sheen) ·
//           ((1 − subsurface)·base/π·cos + subsurface·[random walk]) ) ) )
// with ws = specular·specular_color. The directional albedo at μo of the whole stack is then at
// most 1 whatever the parameters. The E tables are integrals of this file's own lobes, written
// once per device by kernels/tables.wgsl. GGX lobes use Schlick's Fresnel (F0 from the IOR,
// F90 = 1), so one split table (F0·A + B) serves every IOR and the metal's coloured F0.
//
// The subsurface lobe has no direction at the entry point: `bsdf_sample` only reports that it was
// picked and what enters the medium; `bsdf_eval` leaves it out (its pdf share is 1 − p_sss of the
// other lobes'), and the integrator's random walk (walk.wgsl) carries the light to its exit.

struct Layering {
    f0_coat: f32,
    f0_spec: f32,
    under_coat: vec3<f32>,  // what passes the coat
    spec_w: vec3<f32>,      // specular weight · colour
    under_spec: vec3<f32>,  // what passes the specular layer
    sheen_scale: f32,       // 1 / max(1, E_sheen): keeps the sheen lobe's albedo ≤ 1
    under_sheen: f32,       // what passes the sheen
    sss_weight: vec3<f32>,  // what enters the subsurface medium (before the walk's albedo)
    // lobe selection probabilities: coat, metal, specular, sheen, diffuse; subsurface is the rest
    p_coat: f32,
    p_metal: f32,
    p_spec: f32,
    p_sheen: f32,
    p_diffuse: f32,
    p_sss: f32,
};

fn sq(x: f32) -> f32 {
    return x * x;
}

fn schlick_f0(ior: f32) -> f32 {
    return sq((ior - 1.0) / (ior + 1.0));
}

// Bilinear lookup: cos θ over cell centres, roughness over grid points, clamped at the edges.
fn lut(mu: f32, rough: f32) -> vec4<f32> {
    let n = f32(LUT_N);
    let fx = clamp(mu * n - 0.5, 0.0, n - 1.0);
    let fy = clamp(rough * (n - 1.0), 0.0, n - 1.0);
    let x0 = min(u32(fx), LUT_N - 1u);
    let y0 = min(u32(fy), LUT_N - 1u);
    let x1 = min(x0 + 1u, LUT_N - 1u);
    let y1 = min(y0 + 1u, LUT_N - 1u);
    let tx = fx - f32(x0);
    let ty = fy - f32(y0);
    let a = mix(tables[y0 * LUT_N + x0], tables[y0 * LUT_N + x1], tx);
    let b = mix(tables[y1 * LUT_N + x0], tables[y1 * LUT_N + x1], tx);
    return mix(a, b, ty);
}

// The table's roughness coordinate of a GGX α (α = r², floored as shading.wgsl floors it).
fn lut_rough(alpha: f32) -> f32 {
    return sqrt(max(alpha, 1e-4));
}

// Directional albedo of a Schlick GGX reflection lobe with F0 `f0` (F90 = 1).
fn ggx_albedo(mu: f32, alpha: f32, f0: vec3<f32>) -> vec3<f32> {
    let t = lut(mu, lut_rough(alpha));
    return f0 * t.x + vec3<f32>(t.y);
}

fn sheen_albedo(mu: f32, rough: f32) -> f32 {
    return lut(mu, rough).z;
}

// GGX reflection with Schlick Fresnel (F90 = 1): f·cos.
fn ggx_reflect_eval(wo: vec3<f32>, wi: vec3<f32>, a_in: f32, f0: vec3<f32>) -> vec3<f32> {
    let a = max(a_in, 1e-4);
    let m = normalize(wo + wi);
    return schlick(f0, vec3<f32>(1.0), dot(wo, m)) * (ggx_d(m, a) * ggx_g2(wo, wi, a) / (4.0 * wo.z));
}

fn ggx_reflect_pdf(wo: vec3<f32>, wi: vec3<f32>, a_in: f32) -> f32 {
    let a = max(a_in, 1e-4);
    return ggx_reflection_pdf(wo, normalize(wo + wi), a);
}

// Charlie sheen (Estevez & Kulla 2017): D(m) = (2 + 1/r) sin^(1/r) θm / 2π, with Neubelt &
// Pettineo's visibility 1 / (4 (μi + μo − μi μo)); f·cos. Sampled by the cosine hemisphere.
fn sheen_rough_clamped(r: f32) -> f32 {
    return clamp(r, 0.02, 1.0);
}

fn sheen_eval(wo: vec3<f32>, wi: vec3<f32>, rough: f32) -> f32 {
    let r = sheen_rough_clamped(rough);
    let m = normalize(wo + wi);
    let sin2 = max(0.0, 1.0 - m.z * m.z);
    let d = (2.0 + 1.0 / r) * pow(sin2, 0.5 / r) / (2.0 * PI);
    let v = 1.0 / (4.0 * (wi.z + wo.z - wi.z * wo.z));
    return d * v * wi.z;
}

fn layering(s: Surface, mu: f32) -> Layering {
    var l: Layering;
    l.f0_coat = schlick_f0(s.coat_ior);
    l.f0_spec = schlick_f0(s.ior);
    let e_coat = ggx_albedo(mu, s.coat_alpha, vec3<f32>(l.f0_coat)).x;
    l.under_coat = vec3<f32>(1.0 - s.coat) + s.coat * s.coat_color * (1.0 - e_coat);
    l.spec_w = s.specular * s.spec_color;
    let e_spec = ggx_albedo(mu, s.alpha, vec3<f32>(l.f0_spec)).x;
    l.under_spec = vec3<f32>(1.0) - l.spec_w * e_spec;
    let e_sheen_raw = sheen_albedo(mu, sheen_rough_clamped(s.sheen_rough));
    l.sheen_scale = 1.0 / max(1.0, e_sheen_raw);
    let e_sheen = min(e_sheen_raw, 1.0);
    l.under_sheen = 1.0 - s.sheen * max3(s.sheen_color) * e_sheen;
    let e_metal = ggx_albedo(mu, s.alpha, s.base);
    let dielectric = l.under_coat * (1.0 - s.metallic);
    let base_level = dielectric * l.under_spec * l.under_sheen;
    l.sss_weight = base_level * s.sss;

    let w_coat = s.coat * e_coat;
    let w_metal = luminance(l.under_coat * s.metallic * e_metal);
    let w_spec = luminance(dielectric * l.spec_w * e_spec);
    let w_sheen = luminance(dielectric * l.under_spec * s.sheen * s.sheen_color * e_sheen);
    let w_diffuse = luminance(base_level * (1.0 - s.sss) * s.base);
    let w_sss = luminance(l.sss_weight * s.sss_color);
    let total = w_coat + w_metal + w_spec + w_sheen + w_diffuse + w_sss;
    if (total > 0.0) {
        l.p_coat = w_coat / total;
        l.p_metal = w_metal / total;
        l.p_spec = w_spec / total;
        l.p_sheen = w_sheen / total;
        l.p_diffuse = w_diffuse / total;
        l.p_sss = w_sss / total;
    }
    return l;
}

// f·cos of each lobe family, for the appendix passes (their sum is bsdf_eval's f_cos).
struct Lobes {
    diffuse: vec3<f32>,
    specular: vec3<f32>, // dielectric specular and metal
    coat: vec3<f32>,
    sheen: vec3<f32>,
};

fn lobes_sum(l: Lobes) -> vec3<f32> {
    return l.diffuse + l.specular + l.coat + l.sheen;
}

fn layered_lobes(s: Surface, l: Layering, wo: vec3<f32>, wi: vec3<f32>) -> Lobes {
    var out = Lobes(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    if (wo.z <= 0.0 || wi.z <= 0.0) {
        return out;
    }
    let dielectric = l.under_coat * (1.0 - s.metallic);
    let below_spec = dielectric * l.under_spec;
    out.sheen = below_spec * (s.sheen * l.sheen_scale) * s.sheen_color * sheen_eval(wo, wi, s.sheen_rough);
    out.diffuse = below_spec * l.under_sheen * (1.0 - s.sss) * s.base * (wi.z * INV_PI);
    if (max3(l.spec_w) > 0.0) {
        out.specular = dielectric * l.spec_w * ggx_reflect_eval(wo, wi, s.alpha, vec3<f32>(l.f0_spec));
    }
    if (s.metallic > 0.0) {
        out.specular += l.under_coat * s.metallic * ggx_reflect_eval(wo, wi, s.alpha, s.base);
    }
    if (s.coat > 0.0) {
        out.coat = vec3<f32>(s.coat) * ggx_reflect_eval(wo, wi, s.coat_alpha, vec3<f32>(l.f0_coat));
    }
    return out;
}

fn layered_pdf(s: Surface, l: Layering, wo: vec3<f32>, wi: vec3<f32>) -> f32 {
    if (wo.z <= 0.0 || wi.z <= 0.0) {
        return 0.0;
    }
    var pdf = (l.p_sheen + l.p_diffuse) * wi.z * INV_PI;
    if (l.p_spec + l.p_metal > 0.0) {
        pdf += (l.p_spec + l.p_metal) * ggx_reflect_pdf(wo, wi, s.alpha);
    }
    if (l.p_coat > 0.0) {
        pdf += l.p_coat * ggx_reflect_pdf(wo, wi, s.coat_alpha);
    }
    return pdf;
}

fn layered_eval_with(s: Surface, l: Layering, wo: vec3<f32>, wi: vec3<f32>) -> BsdfEval {
    return BsdfEval(lobes_sum(layered_lobes(s, l, wo, wi)), layered_pdf(s, l, wo, wi));
}

fn layered_sample(s: Surface, wo: vec3<f32>, u_lobe: f32, u: vec2<f32>) -> BsdfSample {
    var out = BsdfSample(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, false, false, false);
    if (wo.z <= 0.0) {
        return out;
    }
    let l = layering(s, wo.z);
    var wi: vec3<f32>;
    let c_coat = l.p_coat;
    let c_gloss = c_coat + l.p_metal + l.p_spec;
    let c_cos = c_gloss + l.p_sheen + l.p_diffuse;
    if (u_lobe < c_coat) {
        wi = reflect(-wo, ggx_sample_vndf(wo, max(s.coat_alpha, 1e-4), u));
    } else if (u_lobe < c_gloss) {
        wi = reflect(-wo, ggx_sample_vndf(wo, max(s.alpha, 1e-4), u));
    } else if (u_lobe < c_cos || l.p_sss <= 0.0) {
        wi = sample_cosine_hemisphere(u);
    } else {
        out.subsurface = true;
        out.weight = l.sss_weight / l.p_sss;
        out.pdf = l.p_sss;
        out.valid = true;
        return out;
    }
    if (wi.z <= 0.0) {
        return out;
    }
    let e = layered_eval_with(s, l, wo, wi);
    if (e.pdf <= 0.0) {
        return out;
    }
    out.wi = wi;
    out.pdf = e.pdf;
    out.weight = e.f_cos / e.pdf;
    out.valid = true;
    return out;
}

fn gltf_lobes(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> Lobes {
    let parts = gltf_lobes_parts(s, wo, wi);
    return Lobes(parts[0], parts[1], vec3<f32>(0.0), vec3<f32>(0.0));
}

// The lobe families of either model at (wo, wi); the glTF mapping has diffuse and specular.
fn bsdf_lobes(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> Lobes {
    if (s.model == MODEL_HAIR) {
        return hair_lobes(s, wo, wi);
    }
    if (is_layered(s)) {
        return layered_lobes(s, layering(s, max(wo.z, 1e-6)), wo, wi);
    }
    return gltf_lobes(s, wo, wi);
}

fn is_layered(s: Surface) -> bool {
    return s.model != MODEL_GLTF && s.model != MODEL_HAIR && !is_dielectric_delta(s);
}

// f·cos and the pdf of sampling wi by `bsdf_sample` (the subsurface lobe excluded).
fn bsdf_eval(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> BsdfEval {
    if (s.model == MODEL_HAIR) {
        return hair_eval(s, wo, wi);
    }
    if (is_layered(s)) {
        if (wo.z <= 0.0) {
            return BsdfEval(vec3<f32>(0.0), 0.0);
        }
        return layered_eval_with(s, layering(s, wo.z), wo, wi);
    }
    return gltf_eval(s, wo, wi);
}

fn bsdf_sample(s: Surface, wo: vec3<f32>, u_lobe: f32, u: vec2<f32>) -> BsdfSample {
    if (s.model == MODEL_HAIR) {
        return hair_sample(s, wo, u_lobe, u);
    }
    if (is_layered(s)) {
        return layered_sample(s, wo, u_lobe, u);
    }
    return gltf_sample(s, wo, u_lobe, u);
}
