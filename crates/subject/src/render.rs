//! Rendering an assembled sample: the one path the preview, the demo and farm workers share.

use lightfarm_light::{EnvTransform, Hdri, OlatBasis, OLAT_DISC_DEG};
use lightfarm_render::gpu_scene::{pack_scene, PackedScene};
use lightfarm_render::renderer::Progress;
use lightfarm_render::{DiscLight, EnvLight, Lighting, RenderOutput, RenderSettings, Renderer};

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

/// The OLAT basis of a sample that asks for `lights` lights: 4° discs (the paper's), world
/// frame. Its maps are 512 × 256, which any count up to `lightfarm_scene::spec::MAX_OLAT`
/// separates.
pub fn olat_basis(lights: u32) -> Result<OlatBasis, SubjectError> {
    OlatBasis::new(lights as usize, OLAT_DISC_DEG, 512, 256).map_err(|e| SubjectError::Asset {
        asset: "render.olat".into(),
        reason: e.to_string(),
    })
}

/// What a sample's render needs besides the device, built on the CPU: its environment maps and
/// its scene packed for the kernels (the BVHs). A worker builds the next sample's while the
/// device renders the current one.
pub struct RenderInputs {
    pub lights: Vec<EnvLight>,
    pub packed: PackedScene,
}

/// Loads the environment maps of `assembled` and packs its scene (BVH builds).
pub fn render_inputs(assembled: &Assembled) -> Result<RenderInputs, SubjectError> {
    Ok(RenderInputs {
        lights: load_lights(assembled)?,
        packed: pack_scene(&assembled.scene)?,
    })
}

/// Renders both lightings and the passes of `assembled` on `renderer`, then, when the sample
/// asks for them, its OLAT images (`RenderOutput::olat`): every light of the basis on one set
/// of camera paths, without the appendix passes (they belong to the two lightings).
pub fn render_sample(
    renderer: &Renderer,
    assembled: &Assembled,
    progress: &mut dyn FnMut(Progress),
) -> Result<RenderOutput, SubjectError> {
    render_prepared(renderer, assembled, &render_inputs(assembled)?, progress)
}

/// [`render_sample`] with inputs built beforehand by [`render_inputs`].
pub fn render_prepared(
    renderer: &Renderer,
    assembled: &Assembled,
    inputs: &RenderInputs,
    progress: &mut dyn FnMut(Progress),
) -> Result<RenderOutput, SubjectError> {
    let (lights, packed) = (&inputs.lights, &inputs.packed);
    let settings = settings(assembled);
    if assembled.olat == 0 {
        return Ok(renderer.render(packed, lights, &settings, progress)?);
    }
    let basis = olat_basis(assembled.olat)?;
    let discs = DiscLight::olat(&basis);
    let olat_lights: Vec<Lighting> = discs.iter().map(Lighting::Disc).collect();
    // One progress over both renders, in camera samples per pixel: the OLAT render's count
    // K times (its cost is about K shadow rays per vertex).
    let k = discs.len() as u64;
    let spp = settings.spp as u64;
    let total = spp * (1 + k);
    let scaled = |p: Progress, weight: u64| p.done * spp * weight / p.total.max(1);
    let mut out = renderer.render(packed, lights, &settings, &mut |p| {
        progress(Progress {
            done: scaled(p, 1),
            total,
        })
    })?;
    let olat_settings = RenderSettings {
        passes: Vec::new(),
        ..settings
    };
    let olat = renderer.render_lightings(packed, &olat_lights, &olat_settings, &mut |p| {
        progress(Progress {
            done: spp + scaled(p, k),
            total,
        })
    })?;
    out.stats.olat_lights = olat.lit.len();
    out.stats.olat_seconds = olat.stats.seconds;
    out.stats.rays += olat.stats.rays;
    out.olat = olat.lit;
    Ok(out)
}
