//! A render whose invocations would turn their loops more than 65,535 times in all: every
//! sample is taken, or the renderer refuses the render naming the driver and the fix. Mesa 22's
//! llvmpipe ends every loop of an invocation after that many turns (kernels/integrator.wgsl,
//! `report_cut_loops`); before the integrator checked for it this scene's pixels kept ~52 of
//! their 64 samples there while the image passed for converged. Since the renderer's start-up
//! probe finds such a driver and gives it one sample per dispatch, the render completes there.

mod common;

use lightfarm_render::RenderError;

/// The major version in a driver string such as "llvmpipe (Mesa 22.3.6 (LLVM 15.0.6))".
fn mesa_major(driver: &str) -> Option<u32> {
    let rest = &driver[driver.find("Mesa ")? + 5..];
    rest.split('.').next()?.parse().ok()
}

#[test]
fn every_sample_is_taken_or_the_render_is_refused() {
    const SIZE: u32 = 16;
    // 256 pixels are one dispatch of 64 samples per invocation, ~1,000 traversals each: well
    // over 65,535 loop turns per SIMD group. The scene's camera rays cross two lens surfaces
    // before the passes find the sphere, and its paths shuttle between sphere and shell.
    let result = common::try_render_deep(
        &common::white_sphere_in_a_glass_shell(),
        common::front_camera(),
        SIZE,
        64,
        6,
        Vec::new(),
    );
    let info = common::ctx().info().clone();
    match result {
        Ok(out) => {
            // The sphere's silhouette spans ~6 pixels across the middle; the central 4 x 4
            // see it through the shell with every sample.
            let mut short = Vec::new();
            for y in 6..10usize {
                for x in 6..10usize {
                    let i = y * SIZE as usize + x;
                    if out.mask[i] != 1.0 {
                        short.push((x, y, out.mask[i]));
                    }
                }
            }
            assert!(
                short.is_empty(),
                "{} ({}): pixels that lost samples (x, y, coverage): {short:?}",
                info.name,
                info.driver
            );
        }
        Err(e @ RenderError::LoopsCut { .. }) => {
            let message = e.to_string();
            println!("refused: {message}");
            assert!(
                mesa_major(&info.driver).is_some_and(|m| m < 25),
                "{} ({}) is not a driver known to cut loops: {message}",
                info.name,
                info.driver
            );
            assert!(
                message.contains(&info.driver)
                    && message.contains("65,535")
                    && message.contains("scripts/lavapipe-backports.sh"),
                "{message}"
            );
        }
        Err(e) => panic!("render failed: {e}"),
    }
}

/// The renderer's start-up probe finds Mesa 22 cutting loops and Mesa 25 and 26 (and any
/// driver that is not Mesa) not; on a driver that cuts them every dispatch takes one sample
/// per pixel, which is what lets the render above finish there.
#[test]
fn the_start_up_probe_knows_which_drivers_cut_loops() {
    let info = common::ctx().info().clone();
    let cuts = common::renderer().cuts_loops();
    match mesa_major(&info.driver) {
        Some(22) => assert!(
            cuts,
            "{}: Mesa 22 cuts loops, the probe missed it",
            info.driver
        ),
        Some(m) if m < 25 => {}
        _ => assert!(!cuts, "{}: the probe says it cuts loops", info.driver),
    }
}

#[test]
fn mesa_versions_are_read_from_driver_strings() {
    assert_eq!(mesa_major("llvmpipe (Mesa 22.3.6 (LLVM 15.0.6))"), Some(22));
    assert_eq!(
        mesa_major("llvmpipe (Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6))"),
        Some(25)
    );
    assert_eq!(mesa_major("NVIDIA (570.195.03)"), None);
}
