// The fibre scattering model of Chiang, Bitterli, Tappan and Burley 2016 ("A Practical and
// Controllable Hair and Fur Model for Production Path Tracing"): lobes R, TT, TRT with d'Eon's
// longitudinal term M_p, a trimmed-logistic azimuthal term N_p and an isotropic residual TRRT+,
// cuticle tilt α, longitudinal / azimuthal roughness βm / βn, absorption σa per unit radius.
//
// Frame: x is the fibre tangent (sin θ = w.x), azimuth φ = atan2(w.z, w.y) around it,
// counter-clockwise in the right-handed frame (t, b, n). h ∈ [-1, 1] is where the ray met the
// fibre's cross-section, signed so that the mirror reflection off the cylinder turns the
// azimuth by -2 asin(h) (shading.wgsl `fibre_h`). `f_cos` here is the scattering function S
// times cos θi, the quantity that integrates to the fibre's albedo over the sphere: there is
// no surface cosine on a fibre.

const MODEL_HAIR: u32 = 10u;
const SQRT_PI_OVER_8: f32 = 0.626657069;
const TWO_PI: f32 = 6.28318530718;

// asin through atan2: lavapipe's built-in asin is a polynomial off by up to 4e-4 rad for
// |x| ≥ 0.5, which moves every lobe centre Φ_p and is a 6% error in a βn = 0.1 lobe (found by
// tests/hair_model.rs against the f64 oracle).
fn asin_precise(x: f32) -> f32 {
    return atan2(x, sqrt(max(1.0 - x * x, 0.0)));
}

struct Hair {
    sigma_a: vec3<f32>,
    h: f32,
    eta: f32,
    v: vec4<f32>,        // longitudinal variances of R, TT, TRT, TRRT+
    s: f32,              // logistic scale of N_p
    sin2k: vec3<f32>,    // sin(2^k α), k = 0, 1, 2
    cos2k: vec3<f32>,
    gamma_o: f32,
};

fn hair_setup(s: Surface) -> Hair {
    let bm = clamp(s.hair.x, 1e-3, 1.0);
    let bn = clamp(s.hair.y, 1e-3, 1.0);
    let v0 = sq(0.726 * bm + 0.812 * bm * bm + 3.7 * pow(bm, 20.0));
    let sn = SQRT_PI_OVER_8 * (0.265 * bn + 1.194 * bn * bn + 5.372 * pow(bn, 22.0));
    // The fibre's x runs from root to tip and the cuticle scales' free edges point tipward, so
    // R (its peak at -θo - 2α) shifts toward the root and TRT toward the tip, as Marschner et
    // al. 2003 measured: pbrt's formulas below take the tilt as -α (Cycles negates it too;
    // bench/cycles_hair.py found the opposite sign here).
    let a = -s.hair.z;
    let s0 = sin(a);
    let c0 = sqrt(max(0.0, 1.0 - s0 * s0));
    let s1 = 2.0 * c0 * s0;
    let c1 = c0 * c0 - s0 * s0;
    let s2 = 2.0 * c1 * s1;
    let c2 = c1 * c1 - s1 * s1;
    let h = clamp(s.hair.w, -1.0, 1.0);
    return Hair(max(s.hair_sigma, vec3<f32>(0.0)), h, max(s.ior, 1.0001), vec4<f32>(v0, 0.25 * v0, 4.0 * v0, 4.0 * v0),
        sn, vec3<f32>(s0, s1, s2), vec3<f32>(c0, c1, c2), asin_precise(h));
}

// I0 by its power series, Σ (x²/4)^i / (i!)², term by term; 24 terms keep the truncation
// below 1e-7 relative for x ≤ 12 (log_bessel_i0 takes over above).
fn bessel_i0(x: f32) -> f32 {
    let q = 0.25 * x * x;
    var term = 1.0;
    var val = 1.0;
    for (var i = 1; i < 24; i++) {
        term *= q / f32(i * i);
        val += term;
    }
    return val;
}

fn log_bessel_i0(x: f32) -> f32 {
    if (x > 12.0) {
        // The asymptotic expansion I0(x) ~ e^x / sqrt(2πx) (1 + 1/8x + 9/128x²).
        return x - 0.5 * log(TWO_PI * x) + log(1.0 + 1.0 / (8.0 * x) + 9.0 / (128.0 * x * x));
    }
    return log(bessel_i0(x));
}

// d'Eon et al. 2011: normalised over the sphere (∫ M_p cos θi dθi = 1 for any θo).
fn hair_mp(cos_i: f32, cos_o: f32, sin_i: f32, sin_o: f32, v: f32) -> f32 {
    let a = cos_i * cos_o / v;
    let b = sin_i * sin_o / v;
    if (v <= 0.1) {
        return exp(log_bessel_i0(a) - b - 1.0 / v + 0.693147181 - log(2.0 * v));
    }
    return exp(-b) * bessel_i0(a) / (sinh(1.0 / v) * 2.0 * v);
}

// Attenuation of each lobe: Fresnel at the cuticle, absorption T along each internal chord.
struct HairAp {
    a0: vec3<f32>,
    a1: vec3<f32>,
    a2: vec3<f32>,
    a3: vec3<f32>,
};

fn hair_ap(cos_o: f32, eta: f32, h: f32, t: vec3<f32>) -> HairAp {
    let cos_gamma_o = sqrt(max(0.0, 1.0 - h * h));
    let f = fresnel_dielectric(cos_o * cos_gamma_o, eta);
    let a0 = vec3<f32>(f);
    let a1 = sq(1.0 - f) * t;
    let a2 = a1 * t * f;
    let a3 = a2 * f * t / max(vec3<f32>(1.0) - t * f, vec3<f32>(1e-6));
    return HairAp(a0, a1, a2, a3);
}

fn hair_phi(p: f32, gamma_o: f32, gamma_t: f32) -> f32 {
    return 2.0 * p * gamma_t - 2.0 * gamma_o + p * PI;
}

fn logistic(x: f32, s: f32) -> f32 {
    let e = exp(-abs(x) / s);
    return e / (s * sq(1.0 + e));
}

fn logistic_cdf(x: f32, s: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x / s));
}

fn trimmed_logistic(x: f32, s: f32) -> f32 {
    return logistic(x, s) / (logistic_cdf(PI, s) - logistic_cdf(-PI, s));
}

fn sample_trimmed_logistic(u: f32, s: f32) -> f32 {
    let lo = logistic_cdf(-PI, s);
    let k = logistic_cdf(PI, s) - lo;
    let x = -s * log(1.0 / (u * k + lo) - 1.0);
    return clamp(x, -PI, PI);
}

fn wrap_pi(x: f32) -> f32 {
    return x - TWO_PI * round(x / TWO_PI);
}

fn hair_np(phi: f32, p: f32, s: f32, gamma_o: f32, gamma_t: f32) -> f32 {
    return trimmed_logistic(wrap_pi(phi - hair_phi(p, gamma_o, gamma_t)), s);
}

// sin/cos of θo tilted by the cuticle scales for lobe p (R: -2α, TT: +α, TRT: +4α).
fn hair_tilt(hr: Hair, p: u32, sin_o: f32, cos_o: f32) -> vec2<f32> {
    var st = sin_o;
    var ct = cos_o;
    if (p == 0u) {
        st = sin_o * hr.cos2k.y - cos_o * hr.sin2k.y;
        ct = cos_o * hr.cos2k.y + sin_o * hr.sin2k.y;
    } else if (p == 1u) {
        st = sin_o * hr.cos2k.x + cos_o * hr.sin2k.x;
        ct = cos_o * hr.cos2k.x - sin_o * hr.sin2k.x;
    } else if (p == 2u) {
        st = sin_o * hr.cos2k.z + cos_o * hr.sin2k.z;
        ct = cos_o * hr.cos2k.z - sin_o * hr.sin2k.z;
    }
    return vec2<f32>(st, abs(ct));
}

// Everything that depends on wo alone: angles, refracted chord, absorption, lobe attenuations.
struct HairWo {
    sin_o: f32,
    cos_o: f32,
    phi_o: f32,
    gamma_t: f32,
    ap: HairAp,
};

fn hair_wo(hr: Hair, wo: vec3<f32>) -> HairWo {
    let sin_o = clamp(wo.x, -1.0, 1.0);
    let cos_o = sqrt(max(0.0, 1.0 - sin_o * sin_o));
    let phi_o = atan2(wo.z, wo.y);
    let sin_t = sin_o / hr.eta;
    let cos_t = sqrt(max(0.0, 1.0 - sin_t * sin_t));
    let etap = sqrt(max(0.0, hr.eta * hr.eta - sin_o * sin_o)) / max(cos_o, 1e-6);
    let sin_gamma_t = clamp(hr.h / etap, -1.0, 1.0);
    let cos_gamma_t = sqrt(max(0.0, 1.0 - sin_gamma_t * sin_gamma_t));
    let t = exp(-hr.sigma_a * (2.0 * cos_gamma_t / max(cos_t, 1e-6)));
    return HairWo(sin_o, cos_o, phi_o, asin_precise(sin_gamma_t), hair_ap(cos_o, hr.eta, hr.h, t));
}

// The probability of sampling each lobe: its attenuation averaged over the channels.
fn hair_lobe_pdf(w: HairWo) -> vec4<f32> {
    let a = vec4<f32>(dot(w.ap.a0, vec3<f32>(1.0)), dot(w.ap.a1, vec3<f32>(1.0)), dot(w.ap.a2, vec3<f32>(1.0)), dot(w.ap.a3, vec3<f32>(1.0)));
    let total = a.x + a.y + a.z + a.w;
    if (total <= 0.0) {
        return vec4<f32>(1.0, 0.0, 0.0, 0.0);
    }
    return a / total;
}

// M_p N_p of each lobe at wi (the residual's N is 1/2π); lobe p's share of f is this times A_p,
// of the pdf this times the lobe pdf.
fn hair_mn(hr: Hair, w: HairWo, wi: vec3<f32>) -> vec4<f32> {
    let sin_i = clamp(wi.x, -1.0, 1.0);
    let cos_i = sqrt(max(0.0, 1.0 - sin_i * sin_i));
    let phi = atan2(wi.z, wi.y) - w.phi_o;
    let t0 = hair_tilt(hr, 0u, w.sin_o, w.cos_o);
    let t1 = hair_tilt(hr, 1u, w.sin_o, w.cos_o);
    let t2 = hair_tilt(hr, 2u, w.sin_o, w.cos_o);
    return vec4<f32>(
        hair_mp(cos_i, t0.y, sin_i, t0.x, hr.v.x) * hair_np(phi, 0.0, hr.s, hr.gamma_o, w.gamma_t),
        hair_mp(cos_i, t1.y, sin_i, t1.x, hr.v.y) * hair_np(phi, 1.0, hr.s, hr.gamma_o, w.gamma_t),
        hair_mp(cos_i, t2.y, sin_i, t2.x, hr.v.z) * hair_np(phi, 2.0, hr.s, hr.gamma_o, w.gamma_t),
        hair_mp(cos_i, w.cos_o, sin_i, w.sin_o, hr.v.w) / TWO_PI);
}

fn hair_eval(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> BsdfEval {
    let hr = hair_setup(s);
    let w = hair_wo(hr, wo);
    let mn = hair_mn(hr, w, wi);
    let f = w.ap.a0 * mn.x + w.ap.a1 * mn.y + w.ap.a2 * mn.z + w.ap.a3 * mn.w;
    let pdf = dot(hair_lobe_pdf(w), mn);
    return BsdfEval(select(vec3<f32>(0.0), f, f == f), select(0.0, pdf, pdf == pdf));
}

// The appendix passes: R is the fibre's specular, everything that entered it the diffuse.
fn hair_lobes(s: Surface, wo: vec3<f32>, wi: vec3<f32>) -> Lobes {
    let hr = hair_setup(s);
    let w = hair_wo(hr, wo);
    let mn = hair_mn(hr, w, wi);
    return Lobes(w.ap.a1 * mn.y + w.ap.a2 * mn.z + w.ap.a3 * mn.w, w.ap.a0 * mn.x, vec3<f32>(0.0), vec3<f32>(0.0));
}

// Picks a lobe by its attenuation (u_lobe, then reused for N_p), samples M_p of that lobe
// exactly (u) and N_p by the logistic's inverse CDF; the pdf is the full mixture's.
fn hair_sample(s: Surface, wo: vec3<f32>, u_lobe: f32, u: vec2<f32>) -> BsdfSample {
    var out: BsdfSample;
    out.is_delta = false;
    out.subsurface = false;
    out.valid = false;
    let hr = hair_setup(s);
    let w = hair_wo(hr, wo);
    let lp = hair_lobe_pdf(w);
    var p = 3u;
    var uc = u_lobe;
    var v = hr.v.w;
    if (uc < lp.x) {
        p = 0u;
        uc = uc / lp.x;
        v = hr.v.x;
    } else if (uc < lp.x + lp.y) {
        p = 1u;
        uc = (uc - lp.x) / lp.y;
        v = hr.v.y;
    } else if (uc < lp.x + lp.y + lp.z) {
        p = 2u;
        uc = (uc - lp.x - lp.y) / lp.z;
        v = hr.v.z;
    } else {
        uc = (uc - lp.x - lp.y - lp.z) / max(lp.w, 1e-12);
    }
    uc = clamp(uc, 0.0, 0.99999994);
    let tilt = hair_tilt(hr, p, w.sin_o, w.cos_o);
    let u0 = max(u.x, 1e-5);
    let cos_theta = 1.0 + v * log(u0 + (1.0 - u0) * exp(-2.0 / v));
    let sin_theta = sqrt(max(0.0, 1.0 - cos_theta * cos_theta));
    let cos_phi = cos(TWO_PI * u.y);
    let sin_i = clamp(-cos_theta * tilt.x + sin_theta * cos_phi * tilt.y, -1.0, 1.0);
    let cos_i = sqrt(max(0.0, 1.0 - sin_i * sin_i));
    var dphi = TWO_PI * uc;
    if (p < 3u) {
        dphi = hair_phi(f32(p), hr.gamma_o, w.gamma_t) + sample_trimmed_logistic(uc, hr.s);
    }
    let phi_i = w.phi_o + dphi;
    let wi = vec3<f32>(sin_i, cos_i * cos(phi_i), cos_i * sin(phi_i));
    let mn = hair_mn(hr, w, wi);
    let f = w.ap.a0 * mn.x + w.ap.a1 * mn.y + w.ap.a2 * mn.z + w.ap.a3 * mn.w;
    let pdf = dot(lp, mn);
    if (!(pdf > 0.0) || !(pdf < 3.0e38) || any(f != f)) {
        return out;
    }
    out.wi = wi;
    out.pdf = pdf;
    out.weight = f / pdf;
    out.valid = true;
    return out;
}
