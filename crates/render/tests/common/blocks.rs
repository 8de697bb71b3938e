//! Per-block comparison of two estimators of the same image (pbrt's and Mitsuba's way of
//! testing that two renders agree "within noise"): the image is cut into blocks, each block's
//! mean is compared in standard errors, the standard errors estimated from two independent
//! renders (seeds) of each estimator.

/// One block of an estimator: the mean of its renders, the variance of that mean, and the
/// Welch–Satterthwaite denominator term Σ vᵢ² / νᵢ of that variance's pixel parts.
pub struct BlockStat {
    pub mean: f64,
    pub var: f64,
    pub dof_term: f64,
}

/// Per block of `block` × `block` pixels of a `size`-wide square image: the mean of the
/// independent renders `r` (two or more seeds) and the variance of that mean from their
/// per-pixel sample variances (with two renders, (a − b)² / 2 estimates a pixel's variance).
pub fn block_stats(r: &[&[f64]], size: usize, block: usize) -> Vec<BlockStat> {
    assert!(r.len() >= 2, "variances need two renders or more");
    let k = r.len() as f64;
    let n = size / block;
    let m2 = ((block * block) as f64).powi(2);
    let mut out = Vec::new();
    for by in 0..n {
        for bx in 0..n {
            let (mut mean, mut var, mut dof_term) = (0.0, 0.0, 0.0);
            for y in by * block..(by + 1) * block {
                for x in bx * block..(bx + 1) * block {
                    let p = y * size + x;
                    let m = r.iter().map(|img| img[p]).sum::<f64>() / k;
                    let s2 = r.iter().map(|img| (img[p] - m).powi(2)).sum::<f64>() / (k - 1.0);
                    mean += m;
                    let v = s2 / k / m2;
                    var += v;
                    dof_term += v * v / (k - 1.0);
                }
            }
            out.push(BlockStat {
                mean: mean / (block * block) as f64,
                var,
                dof_term,
            });
        }
    }
    out
}

/// Welch's t of two block means as a standard normal score: t with its Welch–Satterthwaite
/// degrees of freedom mapped through the t and normal distributions. A block whose variance
/// rests on a few noisy pixels has few degrees of freedom, and a plain t/√v would put it many
/// "standard errors" out by chance (the sss pass of a small light is such a case).
fn welch_z(diff: f64, var: f64, dof_term: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal, StudentsT};
    let t = diff / var.sqrt();
    let nu = if dof_term > 0.0 {
        (var * var / dof_term).max(1.0)
    } else {
        1e6
    };
    let p = StudentsT::new(0.0, 1.0, nu)
        .expect("t distribution")
        .cdf(-t.abs())
        .max(1e-300);
    let z = -Normal::new(0.0, 1.0).expect("normal").inverse_cdf(p);
    z.copysign(t)
}

/// z-scores of estimator x against estimator y (each as independent renders) per block with
/// light in it; `scale` multiplies y's means (1 for the real test, else a deliberate error).
/// Blocks with no noise in either must agree exactly.
pub fn block_z(
    label: &str,
    x: &[&[f64]],
    y: &[&[f64]],
    size: usize,
    block: usize,
    scale: f64,
) -> Vec<(String, f64)> {
    let sx = block_stats(x, size, block);
    let sy = block_stats(y, size, block);
    let mut z = Vec::new();
    for (i, (bx, by)) in sx.iter().zip(&sy).enumerate() {
        let v = bx.var + by.var * scale * scale;
        if v <= 0.0 {
            assert_eq!(bx.mean, by.mean, "{label} block {i}: no noise, so equal");
            continue;
        }
        let dof = bx.dof_term + by.dof_term * scale.powi(4);
        z.push((
            format!("{label} block {i}"),
            welch_z(bx.mean - by.mean * scale, v, dof),
        ));
    }
    z
}

/// Mean of the squared z-scores.
pub fn mean_z2(z: &[(String, f64)]) -> f64 {
    z.iter().map(|(_, z)| z * z).sum::<f64>() / z.len().max(1) as f64
}

/// Asserts that `z` looks like draws of N(0, 1) (Welch scores, see `welch_z`). The bounds
/// scale with the block count n: mean z² within 1 + 4 σ and max(0.5, 1 − 3 σ), σ = √(2.5 / n)
/// (var z² is 2 for independent normal scores; blocks of several quantities of one image are
/// not independent) (a much smaller value would mean inflated standard errors,
/// a test that cannot fail); at most max(2, n / 50) beyond 3 (0.27 % each under a normal) and
/// none beyond 4.5. Returns the mean z².
pub fn assert_null(what: &str, z: &[(String, f64)], min_blocks: usize) -> f64 {
    assert!(
        z.len() >= min_blocks,
        "{what}: {} blocks with light in them",
        z.len()
    );
    let n = z.len() as f64;
    let chi2 = mean_z2(z);
    let beyond3 = z.iter().filter(|(_, z)| z.abs() > 3.0).count();
    let (worst, zmax) = z
        .iter()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("blocks");
    println!(
        "{what}: {} block tests, mean z² {chi2:.3}, {beyond3} beyond 3 SE, worst {worst} at \
         {zmax:.2} SE",
        z.len()
    );
    let sigma = (2.5 / n).sqrt();
    let (lo, hi) = ((1.0 - 3.0 * sigma).max(0.5), 1.0 + 4.0 * sigma);
    assert!(
        (lo..hi).contains(&chi2),
        "{what}: mean z² {chi2:.3} outside [{lo:.2}, {hi:.2}]"
    );
    assert!(
        beyond3 <= (z.len() / 50).max(2),
        "{what}: {beyond3} of {} blocks beyond 3 SE",
        z.len()
    );
    assert!(
        zmax.abs() < 4.5,
        "{what}: {worst}: {zmax:.2} standard errors apart"
    );
    chi2
}
