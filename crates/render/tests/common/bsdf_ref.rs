//! An independent CPU evaluation (f64) of the surface model that shaders/inc/bsdf.wgsl
//! implements, written from the formulas rather than from the shader: Lambert diffuse
//! attenuated by the specular layer's Schlick reflectance at the viewing angle, GGX (Trowbridge–
//! Reitz) microfacets with the height-correlated Smith G2 (Heitz 2014, eq. 99), Schlick Fresnel
//! between F0 and F90, and the sampling pdf of the shader's strategy: cosine-weighted diffuse
//! and visible-normal GGX reflection (Heitz 2018: D_wo(m) = G1(wo) max(0, wo·m) D(m) / cos θo,
//! reflected: pdf = D_wo(m) / (4 wo·m)), mixed by the lobe probability the shader documents.
//! The device tests compare the shader against this, so neither can drift alone.
#![allow(dead_code)]

use std::f64::consts::PI;

use lightfarm_render::probe::ProbeSurface;

type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: V3) -> V3 {
    let l = dot(a, a).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

fn luminance(c: V3) -> f64 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// GGX normal distribution for a microfacet normal with cosine `cos_m` to the surface normal.
pub fn ggx_d(cos_m: f64, alpha: f64) -> f64 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let c2 = cos_m * cos_m;
    let t2 = (1.0 - c2) / c2;
    let a2 = alpha * alpha;
    // D = 1 / (π α² cos⁴θ (1 + tan²θ / α²)²)
    1.0 / (PI * a2 * c2 * c2 * (1.0 + t2 / a2).powi(2))
}

/// Smith Λ of GGX for a direction with cosine `cos_w`.
pub fn ggx_lambda(cos_w: f64, alpha: f64) -> f64 {
    let c2 = cos_w * cos_w;
    if c2 >= 1.0 {
        return 0.0;
    }
    let t2 = (1.0 - c2) / c2;
    ((1.0 + alpha * alpha * t2).sqrt() - 1.0) / 2.0
}

/// The model's parameters in f64, as the shader's `Surface` holds them.
#[derive(Clone, Copy, Debug)]
pub struct RefSurface {
    pub base: V3,
    pub metallic: f64,
    pub alpha: f64,
    pub specular: f64,
    pub spec_color: V3,
    pub ior: f64,
}

impl From<&ProbeSurface> for RefSurface {
    fn from(s: &ProbeSurface) -> Self {
        RefSurface {
            base: s.base.map(f64::from),
            metallic: s.metallic.into(),
            alpha: s.alpha.into(),
            specular: s.specular.into(),
            spec_color: s.spec_color.map(f64::from),
            ior: s.ior.into(),
        }
    }
}

impl RefSurface {
    /// Reflectance at normal incidence: the dielectric's ((η−1)/(η+1))² tinted and weighted by
    /// KHR_materials_specular, blended towards the base colour by metalness.
    fn f0(&self) -> V3 {
        let r = ((self.ior - 1.0) / (self.ior + 1.0)).powi(2);
        let m = self.metallic;
        [0, 1, 2].map(|k| {
            let dielectric = (r * self.spec_color[k]).min(1.0) * self.specular;
            dielectric * (1.0 - m) + self.base[k] * m
        })
    }

    fn f90(&self) -> f64 {
        self.specular * (1.0 - self.metallic) + self.metallic
    }

    fn fresnel(&self, cos: f64) -> V3 {
        let w = (1.0 - cos).clamp(0.0, 1.0).powi(5);
        let f90 = self.f90();
        self.f0().map(|f0| f0 + (f90 - f0) * w)
    }

    fn diffuse(&self) -> V3 {
        self.base.map(|b| b * (1.0 - self.metallic))
    }

    /// Probability of sampling the specular lobe at viewing cosine `cos_o`.
    pub fn spec_probability(&self, cos_o: f64) -> f64 {
        let f = self.fresnel(cos_o);
        let fs = luminance(f);
        let fd = luminance(self.diffuse()) * (1.0 - f[0].max(f[1]).max(f[2]));
        if fs <= 0.0 {
            0.0
        } else if fd <= 0.0 {
            1.0
        } else {
            (fs / (fs + fd)).clamp(0.1, 0.9)
        }
    }

    /// (f(wo, wi)·cos θi, pdf of sampling wi) in the local frame (z = normal).
    pub fn eval(&self, wo: [f32; 3], wi: [f32; 3]) -> (V3, f64) {
        let (wo, wi) = (normalize(wo.map(f64::from)), normalize(wi.map(f64::from)));
        if wo[2] <= 0.0 || wi[2] <= 0.0 {
            return ([0.0; 3], 0.0);
        }
        let (co, ci) = (wo[2], wi[2]);
        let alpha = self.alpha.max(1e-4);
        let f_view = self.fresnel(co);
        let m = self.metallic;
        let mut f_cos =
            [0, 1, 2].map(|k| self.diffuse()[k] * (1.0 - f_view[k] * (1.0 - m)) / PI * ci);
        let p_spec = self.spec_probability(co);
        let mut pdf = (1.0 - p_spec) * ci / PI;
        let h = normalize([wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]]);
        let d = ggx_d(h[2], alpha);
        let g2 = 1.0 / (1.0 + ggx_lambda(co, alpha) + ggx_lambda(ci, alpha));
        let f = self.fresnel(dot(wo, h));
        for k in 0..3 {
            f_cos[k] += f[k] * d * g2 / (4.0 * co);
        }
        let g1 = 1.0 / (1.0 + ggx_lambda(co, alpha));
        let d_visible = g1 * dot(wo, h).max(0.0) * d / co;
        pdf += p_spec * d_visible / (4.0 * dot(wo, h));
        (f_cos, pdf)
    }
}

/// Unpolarised Fresnel reflectance of a smooth dielectric for light arriving at cosine `cos_i`
/// from the side whose relative index of refraction is `eta` (η_transmitted / η_incident).
pub fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Directional albedo of a GGX mirror-metal (F = 1) at viewing cosine `cos_o`: the integral of
/// D·G2 / (4 cos θo) over the hemisphere, by the midpoint rule on an n×n grid in (cos θi, φ)
/// (equal-area cells). Below 1 because single scattering loses what the shadowing removes.
pub fn ggx_albedo(cos_o: f64, alpha: f64, n: usize) -> f64 {
    let wo = [(1.0 - cos_o * cos_o).max(0.0).sqrt(), 0.0, cos_o];
    let mut sum = 0.0;
    for i in 0..n {
        let ci = (i as f64 + 0.5) / n as f64;
        let si = (1.0 - ci * ci).sqrt();
        for j in 0..n {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
            let wi = [si * phi.cos(), si * phi.sin(), ci];
            let h = normalize([wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]]);
            let g2 = 1.0 / (1.0 + ggx_lambda(cos_o, alpha) + ggx_lambda(ci, alpha));
            sum += ggx_d(h[2], alpha) * g2 / (4.0 * cos_o);
        }
    }
    sum * 2.0 * PI / (n * n) as f64
}
