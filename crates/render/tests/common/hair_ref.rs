//! An independent CPU evaluation (f64) of the fibre model that shaders/inc/hair.wgsl
//! implements: Chiang, Bitterli, Tappan and Burley 2016, "A Practical and Controllable Hair and
//! Fur Model for Production Path Tracing", in the form pbrt-v4's HairBxDF documents, written
//! from the paper's formulas rather than from the shader.
//!
//! For a fibre with tangent x (sin θ = w.x, φ = atan2(w.z, w.y)), offset h ∈ [-1, 1] across
//! its cross-section, index η and absorption σa per unit radius:
//!
//! - f·|cos θi| = Σ_{p<3} M_p(θi, θ'o,p) A_p N_p(φi - φo) + M_3(θi, θo) A_3 / 2π, with θ'o,p
//!   the view angle rotated by the cuticle tilt (by -2α for R, α for TT, 4α for TRT);
//! - M_p is d'Eon et al. 2011's longitudinal lobe, the azimuth-averaged von Mises–Fisher
//!   distribution of variance v_p: exp(-sin θi sin θo / v) I0(cos θi cos θo / v) / (2v sinh 1/v),
//!   evaluated here in log space with an accurate log I0 (power series below 25, the
//!   Hankel asymptotic series above) so it holds for every v the roughness maps to;
//! - A_p is the attenuation of a smooth cylinder: Fresnel f at cos θo cos γo, A0 = f,
//!   A1 = (1 - f)² T, A2 = A1 T f, A3 = A2 f T / (1 - T f), with T = exp(-2 σa cos γt / cos θt);
//! - N_p is a logistic of scale s in Δ = φi - φo - Φ_p (wrapped to [-π, π]), trimmed to [-π, π],
//!   Φ_p = 2p γt - 2γo + pπ.
//!
//! The pdf is that of the sampler: lobe p chosen with probability A_p (averaged over the three
//! channels) / Σ A_p, then M_p (with the same tilted θo) times N_p for p < 3, or M_3 / 2π.
#![allow(dead_code)]

use std::f64::consts::PI;

use lightfarm_render::probe::ProbeFibre;

/// Below this argument ln I0 is the power series, above it the asymptotic series; both are
/// accurate to ~1e-15 relative at the switch (checked by the oracle's own test).
const I0_SWITCH: f64 = 25.0;

/// ln I0(x) by the power series Σ (x²/4)^k / (k!)², all terms positive, summed to convergence.
pub fn log_i0_series(x: f64) -> f64 {
    let q = x * x / 4.0;
    let (mut term, mut sum) = (1.0f64, 1.0f64);
    let mut k = 1.0;
    while term > 1e-18 * sum {
        term *= q / (k * k);
        sum += term;
        k += 1.0;
    }
    sum.ln()
}

/// ln I0(x) by the Hankel expansion I0(x) = e^x / √(2πx) Σ_k ((2k-1)!!)² / (k! (8x)^k), summed
/// until its terms stop shrinking or fall below 1e-18 (for x ≥ 25 that is far before the series
/// diverges: its smallest term is of order e^{-2x}).
pub fn log_i0_asymptotic(x: f64) -> f64 {
    let (mut term, mut sum) = (1.0f64, 1.0f64);
    let mut k = 1.0;
    loop {
        let next = term * (2.0 * k - 1.0) * (2.0 * k - 1.0) / (8.0 * k * x);
        if next >= term || next < 1e-18 {
            break;
        }
        term = next;
        sum += term;
        k += 1.0;
    }
    x - 0.5 * (2.0 * PI * x).ln() + sum.ln()
}

pub fn log_i0(x: f64) -> f64 {
    let x = x.abs();
    if x < I0_SWITCH {
        log_i0_series(x)
    } else {
        log_i0_asymptotic(x)
    }
}

/// ln(2 v sinh(1/v)) = ln v + 1/v + ln(1 - e^{-2/v}), safe for every v > 0.
fn log_norm(v: f64) -> f64 {
    v.ln() + 1.0 / v + (-(-2.0 / v).exp_m1()).ln()
}

/// d'Eon's longitudinal lobe M_p of variance `v`.
pub fn longitudinal(cos_i: f64, cos_o: f64, sin_i: f64, sin_o: f64, v: f64) -> f64 {
    (-sin_i * sin_o / v + log_i0(cos_i * cos_o / v) - log_norm(v)).exp()
}

/// Unpolarised Fresnel reflectance of a dielectric of relative index `eta` for light arriving
/// at cosine `cos_i` from outside.
pub fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let c = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - c * c) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let ct = (1.0 - sin2_t).sqrt();
    let r_s = (c - eta * ct) / (c + eta * ct);
    let r_p = (eta * c - ct) / (eta * c + ct);
    0.5 * (r_s * r_s + r_p * r_p)
}

/// Logistic density of scale `s`: e^{-|x|/s} / (s (1 + e^{-|x|/s})²).
pub fn logistic(x: f64, s: f64) -> f64 {
    let e = (-x.abs() / s).exp();
    e / (s * (1.0 + e) * (1.0 + e))
}

/// The logistic trimmed to [-π, π] and renormalised: CDF(π) - CDF(-π) = tanh(π / 2s).
pub fn trimmed_logistic(x: f64, s: f64) -> f64 {
    logistic(x, s) / (PI / (2.0 * s)).tanh()
}

/// `x` wrapped into [-π, π).
fn wrap(x: f64) -> f64 {
    (x + PI).rem_euclid(2.0 * PI) - PI
}

/// Sine and cosine of a fibre-frame direction's longitude and its azimuth.
fn angles(w: [f64; 3]) -> (f64, f64, f64) {
    let sin = w[0].clamp(-1.0, 1.0);
    let cos = (1.0 - sin * sin).max(0.0).sqrt();
    let phi = w[2].atan2(w[1]);
    (sin, cos, phi)
}

/// The fibre's parameters in f64 and the quantities that depend on them alone.
#[derive(Clone, Copy, Debug)]
pub struct RefFibre {
    pub sigma_a: [f64; 3],
    pub beta_m: f64,
    pub beta_n: f64,
    pub alpha: f64,
    pub eta: f64,
    pub h: f64,
    /// Longitudinal variances of R, TT, TRT and the residual.
    pub v: [f64; 4],
    /// Azimuthal logistic scale.
    pub s: f64,
}

impl From<&ProbeFibre> for RefFibre {
    fn from(f: &ProbeFibre) -> Self {
        RefFibre::new(
            f.sigma_a.map(f64::from),
            f64::from(f.beta_m),
            f64::from(f.beta_n),
            f64::from(f.alpha),
            f64::from(f.ior),
            f64::from(f.h),
        )
    }
}

/// Per-lobe quantities for one wo.
struct Lobes {
    /// A_p per channel.
    a: [[f64; 3]; 4],
    /// (sin, |cos|) of θo as lobe p sees it (tilted for p < 3, plain for the residual).
    theta_o: [(f64, f64); 4],
    /// Φ_p + φo: the azimuth of lobe p's centre.
    phi_centre: [f64; 3],
}

impl RefFibre {
    pub fn new(sigma_a: [f64; 3], beta_m: f64, beta_n: f64, alpha: f64, eta: f64, h: f64) -> Self {
        // Chiang et al. 2016 eqs. 7 and 8: roughness → variance and logistic scale.
        let v0 = (0.726 * beta_m + 0.812 * beta_m.powi(2) + 3.7 * beta_m.powi(20)).powi(2);
        let s =
            (PI / 8.0).sqrt() * (0.265 * beta_n + 1.194 * beta_n.powi(2) + 5.372 * beta_n.powi(22));
        RefFibre {
            sigma_a,
            beta_m,
            beta_n,
            alpha,
            eta,
            h,
            v: [v0, v0 / 4.0, 4.0 * v0, 4.0 * v0],
            s,
        }
    }

    fn lobes(&self, wo: [f64; 3]) -> Lobes {
        let (sin_o, cos_o, phi_o) = angles(wo);
        let eta = self.eta;
        let h = self.h.clamp(-1.0, 1.0);
        let gamma_o = h.asin();
        let cos_gamma_o = (1.0 - h * h).max(0.0).sqrt();
        // Inside: Bravais' index for the projected (azimuthal) problem, and the refracted θt.
        let sin_t = sin_o / eta;
        let cos_t = (1.0 - sin_t * sin_t).max(0.0).sqrt();
        let eta_p = (eta * eta - sin_o * sin_o).max(0.0).sqrt() / cos_o;
        let sin_gamma_t = (h / eta_p).clamp(-1.0, 1.0);
        let gamma_t = sin_gamma_t.asin();
        let cos_gamma_t = (1.0 - sin_gamma_t * sin_gamma_t).max(0.0).sqrt();
        // One chord through the fibre (length 2 cos γt in the cross-section, 1/cos θt longer).
        let t = self.sigma_a.map(|s| (-s * 2.0 * cos_gamma_t / cos_t).exp());
        let f = fresnel_dielectric(cos_o * cos_gamma_o, eta);
        let mut a = [[0.0; 3]; 4];
        for c in 0..3 {
            a[0][c] = f;
            a[1][c] = (1.0 - f) * (1.0 - f) * t[c];
            a[2][c] = a[1][c] * t[c] * f;
            a[3][c] = a[2][c] * f * t[c] / (1.0 - t[c] * f);
        }
        // Cuticle scales tilted by α: R is shifted by -2α, TT by α, TRT by 4α, toward the root
        // for R: x runs root to tip and the scales' free edges point tipward (Marschner 2003;
        // Cycles negates pbrt's α for the same reason), so the tilt enters as -α here.
        // Rotating θo by the angle ψ gives sin(θo + ψ), cos(θo + ψ).
        let alpha = -self.alpha;
        let rot = |psi: f64| {
            let (sp, cp) = psi.sin_cos();
            (sin_o * cp + cos_o * sp, (cos_o * cp - sin_o * sp).abs())
        };
        let theta_o = [
            rot(-2.0 * alpha),
            rot(alpha),
            rot(4.0 * alpha),
            (sin_o, cos_o),
        ];
        let phi_centre = std::array::from_fn(|p| {
            let p = p as f64;
            phi_o + 2.0 * p * gamma_t - 2.0 * gamma_o + p * PI
        });
        Lobes {
            a,
            theta_o,
            phi_centre,
        }
    }

    /// (f·|cos θi| per channel, sampling pdf per solid angle) for the pair (wo, wi), both in
    /// the fibre frame, as the device receives them (taken as they are, not renormalised).
    pub fn eval(&self, wo: [f32; 3], wi: [f32; 3]) -> ([f64; 3], f64) {
        self.eval_f64(wo.map(f64::from), wi.map(f64::from))
    }

    pub fn eval_f64(&self, wo: [f64; 3], wi: [f64; 3]) -> ([f64; 3], f64) {
        let l = self.lobes(wo);
        let (sin_i, cos_i, phi_i) = angles(wi);
        let total: f64 = l.a.iter().flatten().sum();
        let mut f = [0.0; 3];
        let mut pdf = 0.0;
        for p in 0..4 {
            let (sin_o, cos_o) = l.theta_o[p];
            let m = longitudinal(cos_i, cos_o, sin_i, sin_o, self.v[p]);
            let n = if p < 3 {
                trimmed_logistic(wrap(phi_i - l.phi_centre[p]), self.s)
            } else {
                1.0 / (2.0 * PI)
            };
            for (fc, a) in f.iter_mut().zip(l.a[p]) {
                *fc += m * a * n;
            }
            pdf += m * n * l.a[p].iter().sum::<f64>() / total;
        }
        (f, pdf)
    }

    /// (∫ f·cos dωi per channel, ∫ pdf dωi) over the sphere, dω = d(sin θi) dφi: Gauss–Legendre
    /// with `n_x` nodes in x = sin θi (M_p is smooth in x: I0 is even, so I0(a cos θi) is a
    /// series in cos² θi = 1 - x²) and the midpoint rule with `n_phi` points in φi (N_p is
    /// periodic, smooth but for a kink where Δ wraps at ±π).
    pub fn integrate(&self, wo: [f64; 3], n_x: usize, n_phi: usize) -> ([f64; 3], f64) {
        let (mut f_sum, mut pdf_sum) = ([0.0; 3], 0.0);
        let dp = 2.0 * PI / n_phi as f64;
        for (x, w) in gauss_legendre(n_x) {
            let r = (1.0 - x * x).sqrt();
            for j in 0..n_phi {
                let phi = -PI + (j as f64 + 0.5) * dp;
                let (f, pdf) = self.eval_f64(wo, [x, r * phi.cos(), r * phi.sin()]);
                for c in 0..3 {
                    f_sum[c] += f[c] * w;
                }
                pdf_sum += pdf * w;
            }
        }
        (f_sum.map(|v| v * dp), pdf_sum * dp)
    }
}

/// Nodes and weights of n-point Gauss–Legendre quadrature on [-1, 1] (Newton's method on the
/// Legendre recurrence from Tricomi's initial guesses).
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                // P_n(x) and P_n'(x) by the three-term recurrence.
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let k = k as f64;
                    let p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let step = p1 / dp;
                x -= step;
                if step.abs() < 1e-16 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}
