//! The virtual light stage's OLAT basis seen by a diffuse sphere: every one of the 168 lights
//! gives the same irradiance facing it, and lights the sphere from its own direction.

use lightfarm_light::{olat_directions, OlatBasis, ShRadiance, OLAT_LIGHTS};

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[test]
fn each_olat_light_lights_a_diffuse_sphere_from_its_direction_equally() {
    let basis = OlatBasis::paper();
    // Normals of a diffuse sphere, spread evenly (the basis's own spiral, denser).
    let normals: Vec<[f32; 3]> = olat_directions(4000)
        .into_iter()
        .map(|d| d.map(|v| v as f32))
        .collect();
    let mut facing = Vec::with_capacity(OLAT_LIGHTS);
    for (i, d) in olat_directions(OLAT_LIGHTS).into_iter().enumerate() {
        let d = d.map(|v| v as f32);
        let sh = ShRadiance::project(&basis.map(i));
        let lum = |n: [f32; 3]| {
            let e = sh.irradiance(n);
            (e[0] + e[1] + e[2]) / 3.0
        };
        // The brightest normal of the sphere faces the light (within the 4000-point spacing
        // of ~3.6°, plus the order-2 SH's own blur).
        let brightest = normals
            .iter()
            .copied()
            .max_by(|a, b| lum(*a).total_cmp(&lum(*b)))
            .expect("normals");
        let angle = dot(brightest, d).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(
            angle < 5.0,
            "light {i}: brightest normal {angle:.1}° from the light"
        );
        // The far side is dark: order-2 SH of a small light rings a little below zero.
        let back = lum(d.map(|v| -v));
        let front = lum(d);
        assert!(
            back.abs() < 0.1 * front,
            "light {i}: back {back} vs front {front}"
        );
        facing.push(front);
    }
    // Equal power wherever a light falls in lat-long: equal irradiance facing it.
    let mean = facing.iter().sum::<f32>() / facing.len() as f32;
    for (i, e) in facing.iter().enumerate() {
        assert!(
            (e / mean - 1.0).abs() < 0.01,
            "light {i}: irradiance {e} vs the mean {mean}"
        );
    }
    // A small light of power P (= ∫L dω) facing the normal gives irradiance E ≈ P. Order-2 SH
    // sees a point light's clamped cosine as Σ_l Â_l (2l+1)/4π = 1.0625 at its peak, and
    // `irradiance` is E/π.
    let p = basis.power() as f32;
    let ratio = mean * std::f32::consts::PI / p;
    assert!(
        (0.98..1.08).contains(&ratio),
        "π·E/P facing a light is {ratio}, expected ≈ 1.0625"
    );
}

#[test]
fn two_lights_prefiltered_apart_and_summed_equal_both_prefiltered_at_once() {
    use lightfarm_light::{Hdri, PrefilteredEnv};
    let basis = OlatBasis::paper();
    let (a, b) = (basis.map(3), basis.map(100));
    let both = Hdri::from_texels(
        a.width,
        a.height,
        a.texels
            .iter()
            .zip(&b.texels)
            .map(|(x, y)| [x[0] + y[0], x[1] + y[1], x[2] + y[2]])
            .collect(),
    )
    .expect("sum");
    let (pa, pb) = (PrefilteredEnv::compute(&a), PrefilteredEnv::compute(&b));
    let summed = pa.sum(&pb).expect("same resolutions");
    let direct = PrefilteredEnv::compute(&both);
    for (s, d) in summed.sh.coeffs.iter().zip(&direct.sh.coeffs) {
        for c in 0..3 {
            assert!((s[c] - d[c]).abs() < 1e-6, "SH {s:?} vs {d:?}");
        }
    }
    for (s, d) in summed.phong.iter().zip(&direct.phong) {
        let peak = d.texels.iter().map(|t| t[0]).fold(0.0, f32::max);
        assert!(peak > 0.0);
        let worst = s
            .texels
            .iter()
            .zip(&d.texels)
            .map(|(x, y)| (x[0] - y[0]).abs())
            .fold(0.0, f32::max);
        assert!(
            worst < 1e-5 * peak,
            "exponent {}: {worst} vs peak {peak}",
            d.exponent
        );
    }
    // Maps of different resolutions do not add.
    let small = PrefilteredEnv {
        phong: pa.phong[..2].to_vec(),
        ..pa.clone()
    };
    assert!(small.sum(&pb).is_none());
}
