//! Distribution tables and the environment importance sampler: table layout (read by the
//! GPU), pdf consistency, normalization, and a chi-square goodness-of-fit test.

use std::f64::consts::PI;

use lightfarm_light::{dir_to_uv, uv_to_dir, Distribution1D, Distribution2D, EnvSampler, Hdri};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// splitmix64: a tiny deterministic generator so failures reproduce without extra deps.
struct Rng(u64);

impl Rng {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// 16x8 map, dim gradient plus one hot texel and one black row, so the test sees a peak,
/// a zero region and pole stretching at once.
fn hot_texel_map() -> Hdri {
    let (w, h) = (16u32, 8u32);
    let mut texels = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let base = 0.05 + 0.02 * x as f32 + 0.1 * y as f32;
            texels.push(if y == 5 {
                [0.0; 3]
            } else {
                [base, base * 0.5, base * 2.0]
            });
        }
    }
    texels[(2 * w + 11) as usize] = [300.0, 250.0, 200.0];
    Hdri::from_texels(w, h, texels).expect("valid synthetic map")
}

#[test]
fn distribution1d_layout_and_sampling() {
    let d = Distribution1D::new(&[1.0, 0.0, 3.0, 4.0]);
    assert_eq!(d.count(), 4);
    assert_eq!(d.cdf.len(), 5);
    assert_eq!(d.cdf[0], 0.0);
    assert_eq!(d.cdf[4], 1.0);
    assert!((d.integral - 2.0).abs() < 1e-6, "integral = mean of func");
    assert!((d.cdf[1] - 0.125).abs() < 1e-6 && d.cdf[2] == d.cdf[1]);
    let (x, pdf, offset) = d.sample_continuous(0.125);
    assert_eq!(offset, 2, "zero-valued cell 1 is skipped");
    assert!((x - 0.5).abs() < 1e-6);
    assert!((pdf - 1.5).abs() < 1e-6 && d.pdf(x) == pdf);
    let (x, _, offset) = d.sample_continuous(1.0);
    assert!(x < 1.0 && offset == 3);

    let zero = Distribution1D::new(&[0.0; 5]);
    assert_eq!(zero.integral, 0.0);
    assert!((zero.cdf[2] - 0.4).abs() < 1e-6, "all-zero func is uniform");
    assert_eq!(zero.sample_continuous(0.5).1, 1.0);
    assert_eq!(zero.pdf(0.3), 1.0);
}

#[test]
fn env_tables_match_the_gpu_contract() {
    let hdri = hot_texel_map();
    let s = EnvSampler::new(&hdri);
    let (w, h) = (hdri.width as usize, hdri.height as usize);
    assert_eq!(s.dist.conditional.len(), h);
    assert_eq!(s.dist.marginal.count(), h);
    for (y, row) in s.dist.conditional.iter().enumerate() {
        assert_eq!(row.count(), w);
        let sin_theta = (std::f32::consts::PI * (y as f32 + 0.5) / h as f32).sin();
        for x in 0..w {
            let expected = Hdri::luminance(hdri.texels[y * w + x]) * sin_theta;
            assert!((row.func[x] - expected).abs() <= 1e-6 * expected.max(1.0));
        }
        let mean = row.func.iter().sum::<f32>() / w as f32;
        assert!((row.integral - mean).abs() <= 1e-5 * mean.max(1.0));
        assert_eq!(s.dist.marginal.func[y], row.integral);
        assert_eq!((row.cdf[0], row.cdf[w]), (0.0, 1.0));
        assert!(row.cdf.windows(2).all(|c| c[0] <= c[1]), "cdf is monotonic");
    }
}

#[test]
fn sample_pdf_equals_pdf() {
    let hdri = hot_texel_map();
    let s = EnvSampler::new(&hdri);
    let mut rng = Rng(7);
    let mut mismatches = 0;
    for _ in 0..100_000 {
        let u = [rng.next_f32(), rng.next_f32()];
        let (uv, pdf_uv) = s.dist.sample_continuous(u);
        assert_eq!(pdf_uv, s.dist.pdf(uv), "Distribution2D at {u:?}");
        assert!(pdf_uv > 0.0, "sampled a zero-pdf cell at {u:?} -> {uv:?}");

        let (dir, pdf) = s.sample(u);
        let again = s.pdf(dir);
        // dir -> uv rounding can put a sample within an ulp of a cell border on the other
        // side; allow that to happen very rarely, never systematically.
        if (pdf - again).abs() > 1e-4 * pdf {
            mismatches += 1;
        }
        assert!(
            dir_to_uv(dir)[1] < 5.0 / 8.0 || dir_to_uv(dir)[1] >= 6.0 / 8.0,
            "black row sampled"
        );
    }
    assert!(
        mismatches <= 2,
        "{mismatches} samples whose pdf differs from pdf(dir)"
    );
}

/// Midpoint-rule integral of `f(dir)` over the sphere on a fine uv grid.
fn integrate_sphere(f: impl Fn([f32; 3]) -> f64, nu: usize, nv: usize) -> f64 {
    let mut sum = 0.0;
    for iv in 0..nv {
        let v = (iv as f64 + 0.5) / nv as f64;
        let jacobian = 2.0 * PI * PI * (PI * v).sin();
        for iu in 0..nu {
            let u = (iu as f64 + 0.5) / nu as f64;
            sum += f(uv_to_dir([u as f32, v as f32])) * jacobian;
        }
    }
    sum / (nu * nv) as f64
}

#[test]
fn pdf_integrates_to_one_over_the_sphere() {
    for hdri in [hot_texel_map(), Hdri::constant(32, 16, [1.0; 3])] {
        let s = EnvSampler::new(&hdri);
        let total = integrate_sphere(|d| f64::from(s.pdf(d)), 512, 256);
        assert!((total - 1.0).abs() < 2e-3, "integral of pdf = {total}");
    }
    // The uv density alone integrates to 1 as well.
    let d = Distribution2D::new(&[0.0, 1.0, 2.0, 3.0, 0.0, 0.0, 5.0, 1.0], 4, 2);
    let mut total = 0.0;
    for i in 0..400 {
        for j in 0..200 {
            total += f64::from(d.pdf([(i as f32 + 0.5) / 400.0, (j as f32 + 0.5) / 200.0]));
        }
    }
    assert!((total / 80_000.0 - 1.0).abs() < 1e-5);
}

#[test]
fn chi_square_env_sampler_matches_pdf() {
    let hdri = hot_texel_map();
    let s = EnvSampler::new(&hdri);
    // Bins finer than texels and offset from them, so expected counts depend on sinθ inside
    // each texel, i.e. on the solid-angle pdf, not just on the uv table.
    let (bu, bv) = (40usize, 20usize);
    let samples = 1_000_000usize;

    let mut observed = vec![0f64; bu * bv];
    let mut rng = Rng(42);
    for _ in 0..samples {
        let (dir, pdf) = s.sample([rng.next_f32(), rng.next_f32()]);
        assert!(pdf > 0.0 && pdf.is_finite(), "bad pdf {pdf} for {dir:?}");
        let [u, v] = dir_to_uv(dir);
        let i = ((u * bu as f32) as usize).min(bu - 1);
        let j = ((v * bv as f32) as usize).min(bv - 1);
        observed[j * bu + i] += 1.0;
    }

    // Expected counts: integrate pdf(ω) dω over each bin (midpoint rule, 8x8 per bin).
    let sub = 8usize;
    let mut expected = vec![0f64; bu * bv];
    for j in 0..bv {
        for i in 0..bu {
            let mut acc = 0.0;
            for sj in 0..sub {
                let v = (j as f64 + (sj as f64 + 0.5) / sub as f64) / bv as f64;
                let jac = 2.0 * PI * PI * (PI * v).sin();
                for si in 0..sub {
                    let u = (i as f64 + (si as f64 + 0.5) / sub as f64) / bu as f64;
                    acc += f64::from(s.pdf(uv_to_dir([u as f32, v as f32]))) * jac;
                }
            }
            let area = 1.0 / (bu * bv * sub * sub) as f64;
            expected[j * bu + i] = acc * area * samples as f64;
        }
    }

    // Pool cells with expected < 5 (Mitsuba chi2.py); samples in zero-pdf cells are fatal.
    let mut order: Vec<usize> = (0..bu * bv).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let (mut chi2, mut dof, mut pool_obs, mut pool_exp) = (0.0f64, 0i64, 0.0f64, 0.0f64);
    for &k in &order {
        if expected[k] == 0.0 {
            assert_eq!(observed[k], 0.0, "samples landed in zero-pdf bin {k}");
        } else if expected[k] < 5.0 {
            pool_obs += observed[k];
            pool_exp += expected[k];
        } else {
            chi2 += (observed[k] - expected[k]).powi(2) / expected[k];
            dof += 1;
        }
    }
    if pool_exp > 0.0 {
        chi2 += (pool_obs - pool_exp).powi(2) / pool_exp;
        dof += 1;
    }
    dof -= 1;
    assert!(dof > 50, "too few usable bins: {dof}");
    let p_value = 1.0 - ChiSquared::new(dof as f64).expect("dof > 0").cdf(chi2);
    assert!(
        p_value > 0.01,
        "chi-square rejects: chi2 = {chi2:.1}, dof = {dof}, p = {p_value:.2e}"
    );
}
