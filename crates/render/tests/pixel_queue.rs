//! The pixel queue (`Renderer::set_pixel_queue`: invocations take pixels off an atomic queue
//! until the image is done) changes who renders a pixel, never what: a pixel's samples depend on
//! its index, the sample and the seed only. So a render with the queue equals one without it
//! bit for bit, in both walk schedules, including images whose edge tiles are partly outside.

mod common;

use glam::Vec3;
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::Camera;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{RenderError, RenderOutput, RenderSettings, Renderer, WalkSchedule};

fn render(renderer: &Renderer, width: u32, height: u32, spp: u32) -> RenderOutput {
    let camera = Camera::look_at(Vec3::new(0.0, 0.02, 0.1), Vec3::ZERO, 30.0).expect("camera");
    let settings = RenderSettings {
        width,
        height,
        spp,
        seed: 11,
        max_depth: 8,
        rr_depth: 3,
        camera,
        passes: Pass::ALL.to_vec(),
    };
    let packed = pack_scene(&common::skin_floor_lens()).expect("pack");
    let lights = [common::constant_light(1.0), common::constant_light(0.4)];
    renderer
        .render(&packed, &lights, &settings, &mut |_| {})
        .expect("render")
}

fn same_bits(a: &[[f32; 3]], b: &[[f32; 3]], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: pixel counts");
    for (p, (x, y)) in a.iter().zip(b).enumerate() {
        let (xb, yb) = (x.map(f32::to_bits), y.map(f32::to_bits));
        assert_eq!(xb, yb, "{what}, pixel {p}: queue {x:?}, no queue {y:?}");
    }
}

fn assert_same(a: &RenderOutput, b: &RenderOutput) {
    assert_eq!(
        a.stats.rays, b.stats.rays,
        "the same paths cast the same rays"
    );
    assert_eq!(a.lit.len(), b.lit.len());
    for l in 0..a.lit.len() {
        same_bits(&a.lit[l], &b.lit[l], &format!("lit{l}"));
        let (pa, pb) = (&a.passes[l], &b.passes[l]);
        same_bits(&pa.diffuse, &pb.diffuse, &format!("diffuse{l}"));
        same_bits(&pa.specular, &pb.specular, &format!("specular{l}"));
        same_bits(&pa.sss, &pb.sss, &format!("sss{l}"));
        same_bits(&pa.coat, &pb.coat, &format!("coat{l}"));
        same_bits(&pa.sheen, &pb.sheen, &format!("sheen{l}"));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&pa.shadow), bits(&pb.shadow), "shadow{l}");
    }
    same_bits(&a.albedo, &b.albedo, "albedo");
    same_bits(&a.normal, &b.normal, "normal");
    same_bits(&a.normal_lens, &b.normal_lens, "normal_lens");
    assert_eq!(a.mask, b.mask, "mask");
    assert_eq!(a.id, b.id, "id");
}

/// Two renderers, one with the queue and one without; None where the driver cuts loops (Mesa
/// 22), which must refuse the queue by name.
fn pair(walk: WalkSchedule) -> Option<(Renderer, Renderer)> {
    let mut queued = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    queued.set_walk_schedule(walk);
    if queued.cuts_loops() {
        assert!(!queued.pixel_queue(), "no queue where loops are cut");
        match queued.set_pixel_queue(true) {
            Err(RenderError::InvalidSettings(m)) => {
                assert!(m.contains("65,535") && m.contains("pixel queue"), "{m}")
            }
            other => panic!("expected the queue refused, got {other:?}"),
        }
        eprintln!("this driver cuts loops: the pixel queue is refused, nothing to compare");
        return None;
    }
    queued.set_pixel_queue(true).expect("queue on");
    let mut plain = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    plain.set_walk_schedule(walk);
    plain.set_pixel_queue(false).expect("queue off");
    Some((queued, plain))
}

#[test]
fn the_megakernel_renders_the_same_bits_off_the_queue() {
    let Some((queued, plain)) = pair(WalkSchedule::Megakernel) else {
        return;
    };
    // 13 x 7: every tile is partly outside the image; 40 x 24 has whole tiles and several rows.
    for (w, h) in [(13, 7), (40, 24)] {
        let a = render(&queued, w, h, 6);
        let b = render(&plain, w, h, 6);
        assert!(
            a.lit[0].iter().any(|p| p[0] > 0.0),
            "{w}x{h}: something is lit"
        );
        assert_same(&a, &b);
    }
}

#[test]
fn the_walk_dispatch_renders_the_same_bits_off_the_queue() {
    let Some((queued, plain)) = pair(WalkSchedule::Dispatch) else {
        return;
    };
    let a = render(&queued, 13, 7, 4);
    let b = render(&plain, 13, 7, 4);
    assert!(
        a.passes[0].sss.iter().any(|p| p[0] > 0.0),
        "the skin scatters"
    );
    assert_same(&a, &b);
}

#[test]
fn cpu_devices_take_pixels_off_the_queue_by_default() {
    let r = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    let info = r.device();
    if info.kind == "cpu" {
        assert_eq!(
            r.pixel_queue(),
            !r.cuts_loops(),
            "{} ({})",
            info.name,
            info.driver
        );
    } else {
        assert!(
            !r.pixel_queue(),
            "a GPU rebalances its own workgroups: {}",
            info.name
        );
    }
}
