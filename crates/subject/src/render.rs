//! Rendering an assembled sample: the one path the preview, the demo and farm workers share.

use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::renderer::Progress;
use lightfarm_render::{EnvLight, RenderOutput, RenderSettings, Renderer};

use crate::{Assembled, SubjectError};

/// Path depth of dataset renders: enough for light through a lens, off the skin and back out.
pub const MAX_DEPTH: u32 = 8;
/// Bounce at which Russian roulette starts.
pub const RR_DEPTH: u32 = 5;

/// The two environment maps of a sample, loaded and posed.
pub fn load_lights(assembled: &Assembled) -> Result<Vec<EnvLight>, SubjectError> {
    assembled
        .lighting
        .iter()
        .map(|(path, rotation_deg, flip)| {
            let hdri = Hdri::load(path).map_err(|e| SubjectError::Asset {
                asset: path.display().to_string(),
                reason: e.to_string(),
            })?;
            Ok(EnvLight {
                name: path.display().to_string(),
                hdri,
                transform: EnvTransform {
                    rotation_deg: *rotation_deg,
                    flip: *flip,
                },
            })
        })
        .collect()
}

/// The settings an assembled sample renders with.
pub fn settings(assembled: &Assembled) -> RenderSettings {
    RenderSettings {
        width: assembled.width,
        height: assembled.height,
        spp: assembled.spp,
        passes: assembled.passes.clone(),
        seed: assembled.seed,
        max_depth: MAX_DEPTH,
        rr_depth: RR_DEPTH,
        camera: assembled.camera,
    }
}

/// Renders both lightings and the passes of `assembled` on `renderer`.
pub fn render_sample(
    renderer: &Renderer,
    assembled: &Assembled,
    progress: &mut dyn FnMut(Progress),
) -> Result<RenderOutput, SubjectError> {
    let lights = load_lights(assembled)?;
    let packed = pack_scene(&assembled.scene)?;
    Ok(renderer.render(&packed, &lights, &settings(assembled), progress)?)
}
