//! The walk-dispatch schedule (walks parked, queued and run by a dispatch of their own) renders
//! the megakernel's paths: the same rays, the same image and passes up to float summation order.
//! Its job slots hold one lighting, so it traces lightings separately: the megakernel it is
//! compared with does too (tests/shared_paths.rs compares shared and separate lightings).

mod common;

use glam::Vec3;
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::Camera;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{
    LightingSchedule, RenderError, RenderOutput, RenderSettings, Renderer, WalkSchedule,
};

fn render(renderer: &Renderer, size: u32, spp: u32) -> Result<RenderOutput, RenderError> {
    let camera = Camera::look_at(Vec3::new(0.0, 0.02, 0.1), Vec3::ZERO, 30.0).expect("camera");
    let settings = RenderSettings {
        width: size,
        height: size,
        spp,
        seed: 5,
        max_depth: 8,
        rr_depth: 3,
        camera,
        passes: Pass::ALL.to_vec(),
    };
    let packed = pack_scene(&common::skin_floor_lens()).expect("pack");
    let lights = [common::constant_light(1.0), common::constant_light(0.5)];
    renderer.render(&packed, &lights, &settings, &mut |_| {})
}

fn close(a: &[[f32; 3]], b: &[[f32; 3]], what: &str) {
    assert_eq!(a.len(), b.len());
    for (p, (x, y)) in a.iter().zip(b).enumerate() {
        for k in 0..3 {
            let tol = 1e-4 * x[k].abs().max(y[k].abs()).max(1.0);
            assert!(
                (x[k] - y[k]).abs() <= tol,
                "{what}, pixel {p}: megakernel {x:?}, walk dispatch {y:?}"
            );
        }
    }
}

#[test]
fn the_walk_dispatch_renders_the_megakernels_paths() {
    let mut dispatch = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    dispatch.set_walk_schedule(WalkSchedule::Dispatch);
    let mut megakernel = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    megakernel.set_lighting_schedule(LightingSchedule::Separate);
    assert_eq!(megakernel.walk_schedule(), WalkSchedule::Megakernel);
    let (size, spp) = (24, 8);
    let a = render(&megakernel, size, spp).expect("megakernel");
    let b = render(&dispatch, size, spp).expect("walk dispatch");
    println!(
        "megakernel {} rays in {:.2} s, walk dispatch {} rays in {:.2} s",
        a.stats.rays, a.stats.seconds, b.stats.rays, b.stats.seconds
    );
    assert_eq!(
        a.stats.rays, b.stats.rays,
        "the same paths cast the same rays"
    );
    assert!(
        a.stats.rays > 20 * (size * size * spp * 2) as u64 / 10,
        "the walks cast rays: {}",
        a.stats.rays
    );
    for l in 0..2 {
        close(&a.lit[l], &b.lit[l], &format!("lit{l}"));
        let (pa, pb) = (&a.passes[l], &b.passes[l]);
        close(&pa.diffuse, &pb.diffuse, "diffuse");
        close(&pa.specular, &pb.specular, "specular");
        close(&pa.sss, &pb.sss, "sss");
        close(&pa.coat, &pb.coat, "coat");
        close(&pa.sheen, &pb.sheen, "sheen");
        assert!(pa.sss.iter().any(|p| p[0] > 0.05), "the skin scatters");
        for (p, (x, y)) in pa.shadow.iter().zip(&pb.shadow).enumerate() {
            assert!((x - y).abs() <= 1e-4, "shadow{l}, pixel {p}: {x} vs {y}");
        }
    }
    assert_eq!(a.albedo, b.albedo);
    assert_eq!(a.normal, b.normal);
    assert_eq!(a.mask, b.mask);
    assert_eq!(a.id, b.id);
}

#[test]
fn the_walk_dispatch_refuses_images_its_job_slots_cannot_hold() {
    let mut dispatch = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    dispatch.set_walk_schedule(WalkSchedule::Dispatch);
    match render(&dispatch, 1024, 1) {
        Err(RenderError::InvalidSettings(m)) => {
            assert!(m.contains("1024x1024") && m.contains("megakernel"), "{m}")
        }
        other => panic!(
            "expected an error naming the size, got {:?}",
            other.map(|o| o.width)
        ),
    }
}
