//! Fibres through the whole integrator: a white-furnace render of clear fibres (σa = 0 returns
//! every bit of a uniform environment), and the passes of a fibre (albedo, normal, mask, id).

mod common;

use common::fibres::{hair_material, hanging_strands};
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::{Curves, ObjectClass, Scene};

fn fibre_scene(melanin: f32, strands: Curves) -> Scene {
    Scene {
        materials: vec![hair_material(melanin, 0.0)],
        curves: vec![strands],
        ..Default::default()
    }
}

/// 80 strands, 1.2 m x 1.2 m x 0.6 m deep, radius 3 mm, facing `front_camera` at 3 m.
fn patch() -> Curves {
    let mut c = hanging_strands(80, 40, 0.6, 1.2, 3e-3, 11);
    for p in c.points.iter_mut() {
        p[0] *= 2.0;
        p[1] += 0.6;
    }
    c
}

#[test]
fn clear_fibres_in_a_white_furnace_return_one() {
    let out = common::render_deep(
        &fibre_scene(0.0, patch()),
        common::front_camera(),
        64,
        64,
        3,
        Vec::new(),
    );
    let lit: f64 = out.lit[0]
        .iter()
        .map(|c| f64::from(c[0] + c[1] + c[2]) / 3.0)
        .sum();
    let mask: f64 = out.mask.iter().map(|&m| f64::from(m)).sum();
    assert!(
        mask > 64.0 * 64.0 * 0.05,
        "the fibres cover only {mask} pixels"
    );
    let ratio = lit / mask;
    eprintln!("furnace: radiance over coverage {ratio:.4} ({mask:.0} covered pixels)");
    assert!(
        (ratio - 1.0).abs() < 0.01,
        "fibres with σa = 0 return {ratio}, not 1"
    );
    // Colourless fibres return a grey furnace.
    let ch = |k: usize| out.lit[0].iter().map(|c| f64::from(c[k])).sum::<f64>();
    assert!(
        (ch(0) - ch(2)).abs() < 1e-3 * ch(0),
        "{} vs {}",
        ch(0),
        ch(2)
    );
}

#[test]
fn melanin_absorbs_in_the_furnace() {
    let out = common::render_deep(
        &fibre_scene(0.6, patch()),
        common::front_camera(),
        48,
        32,
        5,
        Vec::new(),
    );
    let mask: f64 = out.mask.iter().map(|&m| f64::from(m)).sum();
    let ch = |k: usize| out.lit[0].iter().map(|c| f64::from(c[k])).sum::<f64>() / mask;
    let (r, g, b) = (ch(0), ch(1), ch(2));
    assert!(r < 0.9 && b < g && g < r, "brown fibres: {r} {g} {b}");
}

#[test]
fn fibre_passes_report_its_colour_normal_coverage_and_id() {
    // Straight vertical strands: the normal is horizontal.
    let mut c = hanging_strands(40, 8, 0.6, 1.2, 4e-3, 3);
    for w in c.offsets.windows(2) {
        let root = c.points[w[0] as usize];
        for (k, i) in (w[0]..w[1]).enumerate() {
            c.points[i as usize] = [root[0] * 2.0, 0.6 - 0.16 * k as f32, root[2]];
        }
    }
    let scene = fibre_scene(0.5, c);
    let out = common::render_deep(&scene, common::front_camera(), 48, 16, 9, vec![Pass::Id]);
    let want = lightfarm_render::hair::color_of_sigma_a(
        lightfarm_render::hair::sigma_a_from_melanin(0.5, 0.0),
        scene.materials[0].azimuthal_roughness,
    );
    let hair_id = ObjectClass::Hair as u32 + 1;
    let (mut covered, mut full) = (0, 0);
    for (i, &m) in out.mask.iter().enumerate() {
        if m <= 0.0 {
            assert_eq!(out.id[i], 0, "pixel {i}: id without coverage");
            continue;
        }
        covered += 1;
        // Strands are thinner than a pixel (2.5 cm) at their radius: partial coverage.
        if m > 0.999 {
            full += 1;
        }
        // The albedo pass is the colour of what covers the pixel (divided by the coverage).
        let a = out.albedo[i];
        for k in 0..3 {
            assert!(
                (a[k] - want[k]).abs() < 1e-4,
                "pixel {i}: albedo {a:?} vs {want:?}"
            );
        }
        let n = out.normal[i];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!(
            n[1].abs() < 1e-3 * len.max(1e-6) + 1e-4,
            "pixel {i}: normal {n:?} is not across the fibre"
        );
        assert!(
            n[2] > 0.0,
            "pixel {i}: normal {n:?} faces away from the camera"
        );
        if out.id[i] != 0 {
            assert_eq!(out.id[i], hair_id, "pixel {i}");
        }
    }
    assert!(covered > 200, "{covered} covered pixels");
    assert!(
        full < covered / 2,
        "{full} of {covered} fully covered: fibres should be fine"
    );
}
