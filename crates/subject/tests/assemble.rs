//! Whole samples: every head with every accessory assembles into a scene the camera frames,
//! deterministically; rendered small on the CPU device, faces are not inside-out, the subject
//! fills the frame without being cut off, and glasses show up in the lens pass.

use glam::Vec3;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::{expand, SampleSpec};
use lightfarm_scene::spec::{DatasetSpec, ResolvedSpec};
use lightfarm_scene::Catalog;
use lightfarm_subject::render::render_sample;
use lightfarm_subject::{assemble, Assembled};

fn catalog() -> Catalog {
    Catalog::builtin().unwrap_or_else(|e| panic!("catalog: {e}"))
}

/// Every head, glasses always, a headset on every other sample or so, all hair styles.
fn spec(catalog: &Catalog, extra: &str) -> ResolvedSpec {
    let text = format!(
        "name = \"assemble-test\"\nseed = 11\ncount = 1000\nwidth = 64\nheight = 64\nspp = 4\n\
         [subject]\nglasses_probability = 1.0\nheadset_probability = 0.5\n{extra}"
    );
    DatasetSpec::from_toml_str(&text, "assemble-test.toml")
        .and_then(|s| s.validate(catalog))
        .unwrap_or_else(|e| panic!("spec: {e}"))
}

/// Projects a world point into [0,1]² image coordinates (x right, y down); None if behind.
fn project(a: &Assembled, p: Vec3) -> Option<(f32, f32)> {
    let c = a.camera;
    let right = c.forward.cross(c.up);
    let d = p - c.position;
    let z = d.dot(c.forward);
    if z <= 0.0 {
        return None;
    }
    let t = (c.yfov_deg.to_radians() * 0.5).tan();
    let aspect = a.width as f32 / a.height as f32;
    let x = d.dot(right) / (z * t * aspect);
    let y = d.dot(c.up) / (z * t);
    Some((0.5 + 0.5 * x, 0.5 - 0.5 * y))
}

fn assembled(catalog: &Catalog, spec: &ResolvedSpec, index: u64) -> (SampleSpec, Assembled) {
    let sample = expand(spec, index).expect("expand");
    let a = assemble(&sample, catalog).unwrap_or_else(|e| panic!("sample {index}: {e}"));
    (sample, a)
}

#[test]
fn every_head_and_style_assembles_inside_the_frame() {
    let catalog = catalog();
    let spec = spec(&catalog, "");
    let mut heads = std::collections::BTreeSet::new();
    let mut styles = std::collections::BTreeSet::new();
    let mut glasses = std::collections::BTreeSet::new();
    for index in 0..40 {
        let (sample, a) = assembled(&catalog, &spec, index);
        heads.insert(sample.head.id.clone());
        styles.insert(sample.hair.style.clone());
        glasses.insert(sample.glasses.as_ref().map(|g| g.id.clone()));
        assert!(a.stats.hair_strands > 100, "{index}: {:?}", a.stats);
        assert!(a.stats.eyebrow_strands > 100, "{index}: {:?}", a.stats);
        assert!(a.stats.triangles < 2_500_000, "{index}: {:?}", a.stats);
        if sample.garment.is_some() {
            assert!(
                a.stats.hidden_skin_triangles > 0,
                "{index}: garment hides no skin"
            );
        }
        // Every skin vertex above the collar (the head) projects inside the image: the
        // camera frames the whole head.
        let (lo, hi) = a.scene.world_bounds().expect("bounds");
        assert!(lo.is_finite() && hi.is_finite());
        let head_mesh = &a.scene.meshes[a.scene.instances[0].mesh as usize];
        let m = a.scene.instances[0].transform;
        let top = head_mesh
            .positions
            .iter()
            .map(|p| m.transform_point3(Vec3::from(*p)))
            .max_by(|p, q| p.y.total_cmp(&q.y))
            .expect("vertices");
        let (u, v) = project(&a, top).expect("crown in front of the camera");
        assert!(
            (0.0..1.0).contains(&u) && (0.0..1.0).contains(&v),
            "{index}: crown at {u},{v}"
        );
        // Lighting: two different maps, files that exist.
        assert_eq!(a.lighting.len(), 2);
        assert!(a.lighting.iter().all(|(p, ..)| p.is_file()));
    }
    assert!(heads.len() >= 8, "heads seen: {heads:?}");
    assert_eq!(styles.len(), 6, "styles seen: {styles:?}");
    assert!(glasses.len() >= 3, "glasses seen: {glasses:?}");
}

#[test]
fn assembly_is_deterministic() {
    let catalog = catalog();
    let spec = spec(&catalog, "");
    let digest = |a: &Assembled| {
        let mut h = blake3::Hasher::new();
        for inst in &a.scene.instances {
            let mesh = &a.scene.meshes[inst.mesh as usize];
            h.update(bytemuck::cast_slice(&mesh.positions));
            h.update(bytemuck::cast_slice(&mesh.indices));
            h.update(bytemuck::cast_slice(&inst.transform.to_cols_array()));
        }
        h.finalize()
    };
    for index in [3, 17] {
        let (_, a) = assembled(&catalog, &spec, index);
        let (_, b) = assembled(&catalog, &spec, index);
        assert_eq!(digest(&a), digest(&b), "sample {index}");
        let (_, c) = assembled(&catalog, &spec, index + 1);
        assert_ne!(digest(&a), digest(&c));
    }
}

#[test]
fn a_sample_from_another_catalog_is_refused() {
    let catalog = catalog();
    let spec = spec(&catalog, "");
    let mut sample = expand(&spec, 0).expect("expand");
    sample.head.blake3 = "0".repeat(64);
    let err = assemble(&sample, &catalog).expect_err("hash mismatch");
    assert!(
        err.to_string().contains(&sample.head.id) && err.to_string().contains("blake3"),
        "{err}"
    );
    let mut sample = expand(&spec, 0).expect("expand");
    sample.lighting[1].hdri = "no_such_hdri".into();
    let err = assemble(&sample, &catalog).expect_err("unknown hdri");
    assert!(err.to_string().contains("no_such_hdri"), "{err}");
}

/// Renders a few samples at 64² on the default device (lavapipe in CI) and checks the image
/// passes: a subject inside-out or off-screen, or glasses off the face, would fail here.
#[test]
fn rendered_samples_look_like_portraits() {
    let catalog = catalog();
    let spec = spec(&catalog, "");
    let renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device (lavapipe in CI)");
    for index in [0, 5, 9] {
        let (sample, a) = assembled(&catalog, &spec, index);
        let out = render_sample(&renderer, &a, &mut |_| {}).expect("render");
        let n = (a.width * a.height) as usize;
        let covered = out.mask.iter().filter(|m| **m > 0.5).count();
        // The subject fills a good part of the frame, and is not cut off at the top: the top
        // row is background (the crown is inside the image).
        let fill = covered as f32 / n as f32;
        assert!(
            (0.15..0.9).contains(&fill),
            "sample {index}: coverage {fill}"
        );
        let top_row = out.mask[..a.width as usize]
            .iter()
            .filter(|m| **m > 0.5)
            .count();
        assert!(
            top_row < a.width as usize / 4,
            "sample {index}: {top_row} top-row pixels covered"
        );
        // Camera-space normals face the camera (+Z towards the viewer) on nearly every
        // covered pixel: an inside-out mesh shows up as normals pointing away.
        let away = out
            .normal
            .iter()
            .zip(&out.mask)
            .filter(|(nrm, m)| **m > 0.5 && nrm[2] < -0.2)
            .count();
        assert!(
            (away as f32) < 0.03 * covered as f32,
            "sample {index}: {away}/{covered} normals face away"
        );
        // Glasses: normal_lens differs from normal on the lenses, which lie in the upper-middle
        // of the image; elsewhere it is the normal.
        if sample.glasses.is_some() {
            let lens: Vec<(usize, usize)> = out
                .normal_lens
                .iter()
                .zip(&out.normal)
                .enumerate()
                .filter(|(_, (nl, n))| nl != n)
                .map(|(i, _)| (i % a.width as usize, i / a.width as usize))
                .collect();
            assert!(
                lens.len() > 10,
                "sample {index}: {} lens pixels",
                lens.len()
            );
            let cy = lens.iter().map(|p| p.1).sum::<usize>() as f32 / lens.len() as f32;
            assert!(
                cy < 0.6 * a.height as f32,
                "sample {index}: lenses at row {cy}"
            );
        }
        // Both lightings produced light on the subject.
        for lit in &out.lit {
            let sum: f32 = lit
                .iter()
                .zip(&out.mask)
                .map(|(p, m)| (p[0] + p[1] + p[2]) * m)
                .sum();
            assert!(
                sum > 0.0 && sum.is_finite(),
                "sample {index}: lit sum {sum}"
            );
        }
    }
}

/// The trainer orients light maps with `CameraSample::camera_to_world`; it must be the basis of
/// the camera the renderer actually used (right, up, and back = −forward).
#[test]
fn camera_to_world_is_the_rendered_cameras_basis() {
    let catalog = catalog();
    let spec = spec(&catalog, "");
    for index in 0..20 {
        let sample = expand(&spec, index).unwrap();
        let camera = lightfarm_subject::assemble::sample_camera(&sample).unwrap();
        let m = sample.camera.camera_to_world();
        let col = |j: usize| Vec3::new(m[0][j] as f32, m[1][j] as f32, m[2][j] as f32);
        let right = camera.forward.cross(camera.up).normalize();
        for (got, want) in [
            (col(0), right),
            (col(1), camera.up),
            (col(2), -camera.forward),
        ] {
            assert!(
                (got - want).length() < 1e-5,
                "sample {index}: {got} vs {want}"
            );
        }
    }
}
