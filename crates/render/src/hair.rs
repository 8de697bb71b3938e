//! The fibre material's parameters as the shader (shaders/inc/hair.wgsl) takes them: absorption
//! from melanin, and the diffuse-equivalent colour the albedo pass reports for a fibre.
//!
//! **σ set.** Absorption per unit fibre radius is the sum of eumelanin's and pheomelanin's,
//! σa = c_e (0.506, 0.841, 1.653) + c_p (0.343, 0.733, 1.924), the linear-Rec.709 coefficients
//! Blender Cycles' Principled Hair BSDF uses (d'Eon et al. 2011's measurements, as fitted
//! there), so the Cycles cross-check (bench/cycles_hair.py) renders the same fibre from the same
//! numbers. Melanin m ∈ [0, 1] and redness r ∈ [0, 1] map to concentrations as Cycles and
//! Arnold do: c = -ln(max(1 - m, 1e-4)), c_e = c (1 - r), c_p = c r.

/// Names the σ set in material records.
pub const SIGMA_SET: &str =
    "cycles-principled-hair: eumelanin (0.506, 0.841, 1.653), pheomelanin (0.343, 0.733, 1.924)";

/// Eumelanin absorption per unit radius and concentration (linear Rec.709).
pub const EUMELANIN_SIGMA_A: [f32; 3] = [0.506, 0.841, 1.653];
/// Pheomelanin absorption per unit radius and concentration (linear Rec.709).
pub const PHEOMELANIN_SIGMA_A: [f32; 3] = [0.343, 0.733, 1.924];

/// σa per unit radius for melanin `m` and redness `r` (both clamped to [0, 1]).
pub fn sigma_a_from_melanin(m: f32, r: f32) -> [f32; 3] {
    let m = m.clamp(0.0, 1.0);
    let r = r.clamp(0.0, 1.0);
    let c = -(1.0 - m).max(1e-4).ln();
    let (ce, cp) = (c * (1.0 - r), c * r);
    std::array::from_fn(|i| ce * EUMELANIN_SIGMA_A[i] + cp * PHEOMELANIN_SIGMA_A[i])
}

/// The inverse of Chiang et al. 2016's colour → σa fit (their eq. 9): the colour a fibre of
/// absorption `sigma_a` and azimuthal roughness `beta_n` shows under multiple scattering. It is
/// what the albedo pass reports for hair.
pub fn color_of_sigma_a(sigma_a: [f32; 3], beta_n: f32) -> [f32; 3] {
    let x = beta_n;
    let k = ((((0.245 * x + 5.574) * x - 10.73) * x + 2.532) * x - 0.215) * x + 5.969;
    sigma_a.map(|s| (-s.max(0.0).sqrt() * k).exp())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_melanin_absorbs_nothing_and_more_melanin_darkens() {
        assert_eq!(sigma_a_from_melanin(0.0, 0.3), [0.0; 3]);
        let light = color_of_sigma_a(sigma_a_from_melanin(0.2, 0.0), 0.3);
        let dark = color_of_sigma_a(sigma_a_from_melanin(0.9, 0.0), 0.3);
        for c in 0..3 {
            assert!(dark[c] < light[c], "{dark:?} vs {light:?}");
        }
        // Blue is absorbed most: brown, not grey.
        assert!(light[2] < light[1] && light[1] < light[0]);
    }

    #[test]
    fn colour_inverts_chiangs_fit() {
        // Chiang's forward fit: σa = (ln c / k(βn))².
        let bn = 0.4f32;
        let k = 5.969 - 0.215 * bn + 2.532 * bn.powi(2) - 10.73 * bn.powi(3)
            + 5.574 * bn.powi(4)
            + 0.245 * bn.powi(5);
        let colour = [0.6f32, 0.35, 0.1];
        let sigma = colour.map(|c| (c.ln() / k).powi(2));
        let back = color_of_sigma_a(sigma, bn);
        for c in 0..3 {
            assert!((back[c] - colour[c]).abs() < 1e-5, "{back:?}");
        }
    }
}
