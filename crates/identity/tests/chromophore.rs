//! Tests of the chromophore skin-colour model (`lightfarm_identity::skin::chromophore`): the
//! tabulated data, the colour pipeline, monotonicity, ITA coverage and inversion, plausibility
//! against measured skin colour, and robustness.

use lightfarm_identity::skin::chromophore::{
    category_ita_bounds, deoxyhaemoglobin_mua, eumelanin_mua, ita_deg, linear_srgb_to_lab,
    melanin_for_ita, oxyhaemoglobin_mua, pheomelanin_mua, reflectance_to_linear_srgb,
    reflectance_to_xyz, skin_category, wavelengths_nm, AlbedoTable, Chromophores, N_WAVELENGTHS,
};
use lightfarm_identity::skin::spectra;

fn skin(melanin: f64, haemoglobin: f64) -> Chromophores {
    Chromophores {
        melanin,
        eumelanin_ratio: 0.7,
        haemoglobin,
        oxygenation: 0.75,
    }
}

fn luminance([r, g, b]: [f64; 3]) -> f64 {
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

fn assert_close3(got: [f64; 3], want: [f64; 3], tol: f64, what: &str) {
    for c in 0..3 {
        assert!(
            (got[c] - want[c]).abs() <= tol,
            "{what}: channel {c} is {} (want {} ± {tol}); all {got:?}",
            got[c],
            want[c]
        );
    }
}

// ---- colour pipeline (CIE 1931 CMFs, D65, sRGB matrix) ----

#[test]
fn flat_reflectance_maps_to_grey() {
    let one = [1.0; N_WAVELENGTHS];
    // Unbalanced XYZ of a perfect reflector is the D65 white point (CIE: 0.95047, 1, 1.08883);
    // this fails if a CMF or D65 value is wrong.
    assert_close3(
        reflectance_to_xyz(&one),
        [0.95047, 1.0, 1.08883],
        2e-3,
        "XYZ of R = 1",
    );
    assert_close3(
        reflectance_to_linear_srgb(&one),
        [1.0; 3],
        1e-2,
        "sRGB of R = 1",
    );
    let half = [0.5; N_WAVELENGTHS];
    assert_close3(
        reflectance_to_linear_srgb(&half),
        [0.5; 3],
        1e-2,
        "sRGB of R = 0.5",
    );
    // A long-pass reflector (only ≥ 600 nm) is red, a short-pass one (≤ 480 nm) blue.
    let nm = wavelengths_nm();
    let red: [f64; N_WAVELENGTHS] = std::array::from_fn(|i| f64::from(u8::from(nm[i] >= 600.0)));
    let [r, g, b] = reflectance_to_linear_srgb(&red);
    assert!(
        r > 0.3 && r > 3.0 * g.max(b),
        "long-pass reflector not red: {:?}",
        [r, g, b]
    );
    let blue: [f64; N_WAVELENGTHS] = std::array::from_fn(|i| f64::from(u8::from(nm[i] <= 480.0)));
    let [r, g, b] = reflectance_to_linear_srgb(&blue);
    assert!(
        b > 0.3 && b > 3.0 * r.max(g),
        "short-pass reflector not blue: {:?}",
        [r, g, b]
    );
}

#[test]
fn lab_and_ita_of_reference_colours() {
    // sRGB white: L* = 100, a* = b* = 0; 18 % grey: L* ≈ 49.5.
    assert_close3(
        linear_srgb_to_lab([1.0; 3]),
        [100.0, 0.0, 0.0],
        1e-6,
        "Lab of white",
    );
    let [l, a, b] = linear_srgb_to_lab([0.18; 3]);
    assert!(
        (l - 49.5).abs() < 0.1 && a.abs() < 1e-6 && b.abs() < 1e-6,
        "grey Lab {l} {a} {b}"
    );
    // A yellowish light colour has ITA in (0, 90); a darker one of the same hue a lower ITA.
    let light = ita_deg([0.6, 0.45, 0.35]);
    let dark = ita_deg([0.06, 0.045, 0.035]);
    assert!(
        light > 0.0 && light < 90.0 && dark < 0.0 && dark < light,
        "{light} {dark}"
    );
}

// ---- tabulated chromophore data ----

#[test]
fn haemoglobin_table_has_soret_and_q_bands() {
    let t = &spectra::HAEMOGLOBIN_EPSILON;
    assert_eq!((t[0].0, t[t.len() - 1].0), (380.0, 780.0));
    let argmax = |col: fn(&(f64, f64, f64)) -> f64, lo: f64, hi: f64| {
        t.iter()
            .filter(|r| r.0 >= lo && r.0 <= hi)
            .max_by(|a, b| col(a).total_cmp(&col(b)))
            .unwrap()
            .0
    };
    // Oxy-Hb: Soret peak 414 nm, Q-bands 542 and 576 nm (Prahl's table).
    let soret = argmax(|r| r.1, 380.0, 780.0);
    assert!((410.0..=420.0).contains(&soret), "HbO2 Soret at {soret} nm");
    let local_max: Vec<f64> = t
        .windows(3)
        .filter(|w| w[0].0 >= 500.0 && w[2].0 <= 620.0 && w[1].1 > w[0].1 && w[1].1 > w[2].1)
        .map(|w| w[1].0)
        .collect();
    assert_eq!(local_max.len(), 2, "HbO2 Q-bands: {local_max:?}");
    assert!(
        (local_max[0] - 542.0).abs() <= 3.0,
        "alpha/beta band {local_max:?}"
    );
    assert!(
        (local_max[1] - 576.0).abs() <= 3.0,
        "alpha band {local_max:?}"
    );
    // Deoxy-Hb: Soret at 430–436 nm, a single broad Q-band near 555 nm.
    let soret_deoxy = argmax(|r| r.2, 380.0, 780.0);
    assert!(
        (428.0..=438.0).contains(&soret_deoxy),
        "Hb Soret at {soret_deoxy} nm"
    );
    let q_deoxy = argmax(|r| r.2, 500.0, 620.0);
    assert!(
        (550.0..=560.0).contains(&q_deoxy),
        "Hb Q-band at {q_deoxy} nm"
    );
    // Red window: deoxy-Hb absorbs far more than oxy-Hb (why venous blood looks darker).
    for nm in [620.0, 650.0, 680.0] {
        assert!(
            deoxyhaemoglobin_mua(nm) > 5.0 * oxyhaemoglobin_mua(nm),
            "{nm} nm"
        );
    }
    // Prahl's conversion: μa = 2.303 ε 150/64500 cm⁻¹ → at 414 nm, 2808 cm⁻¹ = 280.8 mm⁻¹.
    let mua = oxyhaemoglobin_mua(414.0);
    assert!((mua - 280.8).abs() < 0.5, "HbO2 μa(414) = {mua} mm⁻¹");
    // Interpolation between the 2 nm samples.
    let mid = oxyhaemoglobin_mua(415.0);
    assert!((mid - 0.5 * (oxyhaemoglobin_mua(414.0) + oxyhaemoglobin_mua(416.0))).abs() < 1e-9);
}

#[test]
fn melanin_absorption_decreases_with_wavelength() {
    let nm = wavelengths_nm();
    for w in nm.windows(2) {
        assert!(
            eumelanin_mua(w[1]) < eumelanin_mua(w[0]),
            "eumelanin at {w:?}"
        );
        assert!(
            pheomelanin_mua(w[1]) < pheomelanin_mua(w[0]),
            "pheomelanin at {w:?}"
        );
        // Pheomelanin falls off faster (λ^−4.75 vs λ^−3.33): the red–yellow pigment.
        assert!(
            eumelanin_mua(w[1]) / pheomelanin_mua(w[1])
                > eumelanin_mua(w[0]) / pheomelanin_mua(w[0])
        );
    }
    // Units guard: 6.6e10 · 500^−3.33 = 67.8 mm⁻¹ (= Jacques' 678 cm⁻¹), not 678 mm⁻¹.
    let eu500 = eumelanin_mua(500.0);
    assert!(
        (eu500 - 67.8).abs() < 0.5,
        "eumelanin μa(500) = {eu500} mm⁻¹"
    );
}

// ---- monotonicity ----

#[test]
fn luminance_and_ita_decrease_with_melanin() {
    for ratio in [0.0, 0.3, 0.7, 1.0] {
        for haemoglobin in [0.0, 0.01, 0.05, 0.2] {
            for oxygenation in [0.0, 0.75, 1.0] {
                let at = |m: f64| {
                    Chromophores {
                        melanin: m,
                        eumelanin_ratio: ratio,
                        haemoglobin,
                        oxygenation,
                    }
                    .albedo()
                };
                let mut prev = at(0.0);
                for k in 1..=100 {
                    let cur = at(0.005 * k as f64);
                    let ctx = format!("ratio {ratio} hb {haemoglobin} oxy {oxygenation} m {k}");
                    assert!(luminance(cur) < luminance(prev), "luminance: {ctx}");
                    assert!(ita_deg(cur) < ita_deg(prev), "ITA: {ctx}");
                    prev = cur;
                }
            }
        }
    }
}

/// Over the typical blood range (0–0.07) with normally oxygenated blood, more haemoglobin gives a
/// redder colour (R/G rises) for melanin up to 0.2. (In very dark skin, melanin ≳ 0.3, or with
/// fully deoxygenated blood, extra blood mostly darkens instead; see the module docs.)
#[test]
fn haemoglobin_makes_skin_redder() {
    for melanin in [0.0, 0.01, 0.02, 0.05, 0.1, 0.2] {
        for oxygenation in [0.75, 1.0] {
            let mut prev = f64::NEG_INFINITY;
            for k in 0..=14 {
                let haemoglobin = 0.005 * k as f64;
                let c = Chromophores {
                    haemoglobin,
                    oxygenation,
                    ..skin(melanin, 0.0)
                };
                let [r, g, _] = c.albedo();
                assert!(r / g > prev, "R/G not increasing: {c:?}");
                prev = r / g;
            }
        }
    }
}

// ---- ITA coverage and inversion ----

#[test]
fn ita_range_spans_all_six_categories() {
    for haemoglobin in [0.01, 0.02, 0.035, 0.05] {
        let base = skin(0.0, haemoglobin);
        let top = ita_deg(base.albedo());
        let bottom = ita_deg(skin(0.5, haemoglobin).albedo());
        assert!(top > 55.0, "hb {haemoglobin}: ITA at melanin 0 is {top}");
        assert!(
            bottom < -30.0,
            "hb {haemoglobin}: ITA at melanin 0.5 is {bottom}"
        );
        let mut seen = [false; 6];
        for k in 0..=500 {
            let c = skin_category(ita_deg(skin(0.001 * k as f64, haemoglobin).albedo()));
            seen[usize::from(c) - 1] = true;
        }
        assert_eq!(seen, [true; 6], "hb {haemoglobin}");
    }
}

#[test]
fn melanin_for_ita_inverts_ita() {
    for haemoglobin in [0.01, 0.02, 0.05] {
        let base = skin(0.3, haemoglobin);
        for target in [60.0, 55.0, 41.0, 28.0, 10.0, 0.0, -30.0, -50.0, -60.0] {
            let m = melanin_for_ita(target, &base)
                .unwrap_or_else(|| panic!("ITA {target} unreachable at hb {haemoglobin}"));
            assert!((0.0..=0.5).contains(&m));
            let got = ita_deg(Chromophores { melanin: m, ..base }.albedo());
            assert!(
                (got - target).abs() < 0.1,
                "target {target}, got {got} at melanin {m}"
            );
        }
        // Outside the reachable range, and NaN.
        assert_eq!(melanin_for_ita(89.9, &base), None);
        assert_eq!(melanin_for_ita(-89.9, &base), None);
        assert_eq!(melanin_for_ita(f64::NAN, &base), None);
    }
}

#[test]
fn categories_and_bounds_agree() {
    assert_eq!(category_ita_bounds(1).1, 90.0);
    assert_eq!(category_ita_bounds(6).0, -90.0);
    for c in 1..=6u8 {
        let (lo, hi) = category_ita_bounds(c);
        assert!(lo < hi);
        assert_eq!(
            skin_category(0.5 * (lo + hi)),
            c,
            "midpoint of category {c}"
        );
        assert_eq!(skin_category(hi), c, "upper bound belongs to category {c}");
        if c < 6 {
            assert_eq!(
                category_ita_bounds(c + 1).1,
                lo,
                "bounds of {c} and {} meet",
                c + 1
            );
        }
    }
    // Chardon / Del Bino thresholds.
    let cases = [
        (56.0, 1),
        (55.0, 2),
        (42.0, 2),
        (41.0, 3),
        (29.0, 3),
        (28.0, 4),
    ];
    let more = [
        (11.0, 4),
        (10.0, 5),
        (-29.0, 5),
        (-30.0, 6),
        (-80.0, 6),
        (120.0, 1),
    ];
    for (ita, c) in cases.into_iter().chain(more) {
        assert_eq!(skin_category(ita), c, "ITA {ita}");
    }
    assert_eq!(category_ita_bounds(0), category_ita_bounds(1));
    assert_eq!(category_ita_bounds(9), category_ita_bounds(6));
}

// ---- plausibility against measured skin ----

/// Literature: very light skin is ITA > 55° (Chardon 1991; Del Bino & Bernerd 2013), i.e. with
/// a typical b* ≈ 14 an L* above ~70; L*a*b* (72, 8, 14) (ITA 57.5°) is linear sRGB
/// ≈ (0.58, 0.41, 0.31). The target box here is (0.6–0.8, 0.4–0.6, 0.3–0.5) with R > G > B.
/// Dark skin (ITA < −30°) with b* ≈ 15 has L* below ~41, i.e. linear R well below 0.15.
#[test]
fn albedo_is_plausible_for_light_and_dark_skin() {
    let light = skin(0.02, 0.02).albedo();
    let [r, g, b] = light;
    eprintln!(
        "very light (melanin 0.02, hb 0.02): {light:?}, ITA {:.1}",
        ita_deg(light)
    );
    assert!((0.6..=0.8).contains(&r), "light R {r}");
    assert!((0.4..=0.6).contains(&g), "light G {g}");
    assert!((0.3..=0.5).contains(&b), "light B {b}");
    assert!(r > g && g > b, "light skin not R > G > B: {light:?}");
    assert_eq!(skin_category(ita_deg(light)), 1);
    let l_star = linear_srgb_to_lab(light)[0];
    assert!((68.0..=80.0).contains(&l_star), "light L* {l_star}");

    let dark = skin(0.4, 0.02).albedo();
    eprintln!(
        "very dark (melanin 0.4, hb 0.02): {dark:?}, ITA {:.1}",
        ita_deg(dark)
    );
    assert!(dark[0] < 0.15, "dark R {}", dark[0]);
    assert!(
        dark[0] > dark[1] && dark[1] > dark[2],
        "dark skin not R > G > B: {dark:?}"
    );
    assert_eq!(skin_category(ita_deg(dark)), 6);
    // Not black: measured dark skin keeps L* above ~20.
    let l_dark = linear_srgb_to_lab(dark)[0];
    assert!(l_dark > 20.0, "dark L* {l_dark}");
}

#[test]
fn spectrum_is_skin_like() {
    let s = skin(0.02, 0.02).spectrum();
    assert_eq!(s.len(), N_WAVELENGTHS);
    let r = |nm: f64| s.iter().find(|p| p.0 == nm).unwrap().1;
    // Skin reflectance rises from blue to red and shows the haemoglobin "W" dip at 540–580 nm
    // (the 560 nm sample lies between the two Q-band samples and reflects more).
    assert!(r(450.0) < r(550.0) && r(550.0) < r(650.0) && r(650.0) < r(700.0));
    assert!(
        r(560.0) > r(540.0) && r(560.0) > r(580.0),
        "no Q-band dip: {s:?}"
    );
    assert!(s.iter().all(|p| p.1 > 0.0 && p.1 < 1.0));
    // The albedo is exactly the colour of the spectrum.
    let spec: [f64; N_WAVELENGTHS] = std::array::from_fn(|i| s[i].1);
    assert_close3(
        reflectance_to_linear_srgb(&spec),
        skin(0.02, 0.02).albedo(),
        1e-12,
        "albedo",
    );
}

// ---- robustness ----

#[test]
fn corner_cases_are_finite() {
    let cases = [
        Chromophores {
            melanin: 0.0,
            eumelanin_ratio: 0.0,
            haemoglobin: 0.0,
            oxygenation: 0.0,
        },
        Chromophores {
            melanin: 0.5,
            eumelanin_ratio: 1.0,
            haemoglobin: 0.2,
            oxygenation: 1.0,
        },
        Chromophores {
            melanin: 0.5,
            eumelanin_ratio: 0.0,
            haemoglobin: 0.2,
            oxygenation: 0.0,
        },
        Chromophores {
            melanin: 7.0,
            eumelanin_ratio: -3.0,
            haemoglobin: 9.0,
            oxygenation: 2.0,
        },
        Chromophores {
            melanin: f64::NAN,
            eumelanin_ratio: f64::NAN,
            haemoglobin: f64::NAN,
            oxygenation: f64::NAN,
        },
        Chromophores {
            melanin: f64::INFINITY,
            eumelanin_ratio: f64::NEG_INFINITY,
            haemoglobin: f64::INFINITY,
            oxygenation: f64::NEG_INFINITY,
        },
    ];
    for c in cases {
        let rgb = c.albedo();
        assert!(
            rgb.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
            "{c:?}: {rgb:?}"
        );
        assert!(c
            .spectrum()
            .iter()
            .all(|p| p.1.is_finite() && p.1 >= 0.0 && p.1 <= 1.0));
        assert!(ita_deg(rgb).is_finite(), "{c:?}");
    }
    // Clamping: out of range equals the bound; NaN reads as the lower bound.
    let over = Chromophores {
        melanin: 7.0,
        eumelanin_ratio: 2.0,
        haemoglobin: 9.0,
        oxygenation: 2.0,
    };
    let max = Chromophores {
        melanin: 0.5,
        eumelanin_ratio: 1.0,
        haemoglobin: 0.2,
        oxygenation: 1.0,
    };
    assert_eq!(over.albedo(), max.albedo());
    let nan = Chromophores {
        melanin: f64::NAN,
        ..skin(0.2, 0.02)
    };
    assert_eq!(nan.albedo(), skin(0.0, 0.02).albedo());
}

#[test]
fn albedo_table_matches_direct_evaluation() {
    let table = AlbedoTable::new(0.7, 0.75, 64, 32);
    let mut worst = 0.0f64;
    for i in 0..=50 {
        for j in 0..=20 {
            let (m, h) = (
                0.5 * (i as f64 / 50.0).powf(1.3),
                0.2 * (j as f64 / 20.0).powf(1.7),
            );
            let want = skin(m, h).albedo();
            let got = table.albedo(m, h);
            for c in 0..3 {
                worst = worst.max((got[c] - want[c]).abs());
            }
        }
    }
    eprintln!("AlbedoTable 64×32 worst error {worst:.2e}");
    assert!(worst < 5e-3, "table error {worst}");
    // Exact at nodes and at the corners; clamped outside.
    assert_close3(
        table.albedo(0.0, 0.0),
        skin(0.0, 0.0).albedo(),
        1e-12,
        "corner",
    );
    assert_close3(
        table.albedo(0.5, 0.2),
        skin(0.5, 0.2).albedo(),
        1e-12,
        "corner",
    );
    assert_close3(
        table.albedo(3.0, -1.0),
        skin(0.5, 0.0).albedo(),
        1e-12,
        "clamped",
    );
    assert_eq!((table.eumelanin_ratio(), table.oxygenation()), (0.7, 0.75));
}

// ---- report (values quoted in the module docs and the hand-over) ----

#[test]
fn report_albedo_ita_and_category_bounds() {
    let mut prev_ita = f64::INFINITY;
    for m in [0.01, 0.05, 0.1, 0.2, 0.3, 0.45] {
        let c = skin(m, 0.02);
        let rgb = c.albedo();
        let [l, a, b] = linear_srgb_to_lab(rgb);
        let ita = ita_deg(rgb);
        eprintln!(
            "melanin {m:.2}: linear sRGB ({:.3}, {:.3}, {:.3})  L*a*b* ({l:.1}, {a:.1}, {b:.1})  \
             ITA {ita:.1}°  category {}",
            rgb[0],
            rgb[1],
            rgb[2],
            skin_category(ita)
        );
        assert!(ita < prev_ita);
        prev_ita = ita;
    }
    let base = skin(0.0, 0.02);
    let mut prev_m = -1.0;
    for bound in [55.0, 41.0, 28.0, 10.0, -30.0] {
        let m = melanin_for_ita(bound, &base).expect("bound reachable");
        eprintln!("ITA {bound:>5.1}° ↔ melanin {m:.4} (hb 0.02, ratio 0.7, oxy 0.75)");
        assert!(m > prev_m);
        prev_m = m;
    }
}

/// `cargo test -p lightfarm-identity --release --test chromophore -- --ignored --nocapture`
#[test]
#[ignore = "timing; run explicitly (in release for the real number)"]
fn albedo_timing() {
    let n = 200_000;
    let start = std::time::Instant::now();
    let mut acc = 0.0;
    for k in 0..n {
        let m = 0.5 * (k % 1000) as f64 / 1000.0;
        let h = 0.2 * (k % 777) as f64 / 777.0;
        acc += std::hint::black_box(skin(m, h)).albedo()[0];
    }
    let per_call = start.elapsed().as_secs_f64() / n as f64;
    eprintln!(
        "albedo(): {:.3} µs/call (checksum {acc:.3})",
        per_call * 1e6
    );
    let budget = if cfg!(debug_assertions) { 50e-6 } else { 2e-6 };
    assert!(per_call < budget, "{per_call} s per call");
    let table = AlbedoTable::new(0.7, 0.75, 64, 32);
    let start = std::time::Instant::now();
    for k in 0..n {
        let m = 0.5 * (k % 1000) as f64 / 1000.0;
        acc += std::hint::black_box(&table).albedo(m, 0.02)[1];
    }
    let per_lookup = start.elapsed().as_secs_f64() / n as f64;
    eprintln!(
        "AlbedoTable::albedo(): {:.1} ns/lookup ({acc:.1})",
        per_lookup * 1e9
    );
}
