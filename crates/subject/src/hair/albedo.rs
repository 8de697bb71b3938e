//! [`hair_albedo`]: the ribbon material's colour from the melanin parameters.

/// Linear-RGB diffuse colour of a hair fibre from the melanin parameters of Blender's
/// Principled Hair BSDF (Chiang et al. 2016), for the ribbon material until the renderer has a
/// hair BSDF.
///
/// The concentration mapping is Blender's: `c = -ln(1 - melanin)`, split into eumelanin
/// `c (1 - redness)` and pheomelanin `c redness`, and the absorption coefficients (per fibre
/// radius) are Cycles' `bsdf_principled_hair_sigma_from_concentration`:
/// eumelanin (0.506, 0.841, 1.653), pheomelanin (0.343, 0.733, 1.924). (pbrt-v4's
/// `HairBxDF::SigmaAFromConcentration` uses (0.419, 0.697, 1.37) and (0.187, 0.4, 1.05); with
/// those, moving a fixed concentration from eumelanin to pheomelanin narrows the gap between
/// the red and the green/blue absorption, so more redness would give a lighter but *less* red
/// colour.) The absorption is turned into a colour as the transmittance of one
/// pass straight through the fibre, `exp(-2 σ_a)` (diameter 2 in units of the radius),
/// scaled by 0.95 so that white hair is not a perfect reflector. That is an approximation: the
/// real colour of a head of hair comes from many fibres and lobes; this one lands on
/// plausible swatches (melanin 0.2: blond, 0.5: light brown, 0.8: dark chestnut, 0.95: black).
pub fn hair_albedo(melanin: f64, melanin_redness: f64) -> [f32; 3] {
    const EUMELANIN: [f64; 3] = [0.506, 0.841, 1.653];
    const PHEOMELANIN: [f64; 3] = [0.343, 0.733, 1.924];
    let melanin = if melanin.is_finite() {
        melanin.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let redness = if melanin_redness.is_finite() {
        melanin_redness.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let concentration = -libm::log((1.0 - melanin).max(1e-4));
    let eu = concentration * (1.0 - redness);
    let pheo = concentration * redness;
    std::array::from_fn(|c| {
        let sigma_a = eu * EUMELANIN[c] + pheo * PHEOMELANIN[c];
        (0.95 * libm::exp(-2.0 * sigma_a)).max(1e-6) as f32
    })
}
