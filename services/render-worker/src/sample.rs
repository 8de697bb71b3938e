//! One sample from its spec to its EXR, in two steps that a worker overlaps: [`prepare`] (the
//! CPU's part: the subject's assembly, the environment maps, the BVH builds) and
//! [`Prepared::render_to_exr`] (the device's render, then the EXR). While the device renders one
//! sample the CPU prepares the next, so on a GPU the CPU phases stop adding to each sample.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use lightfarm_render::output::write_exr;
use lightfarm_render::{Renderer, RENDERER_VERSION};
use lightfarm_scene::expand::SampleSpec;
use lightfarm_subject::render::{render_inputs, render_prepared, RenderInputs};
use lightfarm_subject::Assembled;

/// A sample ready for the device: assembled, its maps loaded and its scene packed.
pub struct Prepared {
    assembled: Assembled,
    inputs: RenderInputs,
    assemble_seconds: f64,
    setup_seconds: f64,
}

/// The CPU's part of a sample: assembles the subject, loads the environment maps and builds the
/// BVHs.
pub fn prepare(catalog: &lightfarm_scene::Catalog, sample: &SampleSpec) -> Result<Prepared> {
    let start = Instant::now();
    let assembled = lightfarm_subject::assemble(sample, catalog)?;
    let assemble_seconds = start.elapsed().as_secs_f64();
    let inputs = render_inputs(&assembled)?;
    Ok(Prepared {
        assembled,
        inputs,
        assemble_seconds,
        setup_seconds: start.elapsed().as_secs_f64() - assemble_seconds,
    })
}

impl Prepared {
    /// Renders the sample (whose JSON is `sample_json`) and writes the sample EXR to `path`;
    /// returns the statistics as JSON (see [`render_to_exr`]).
    pub fn render_to_exr(
        &self,
        renderer: &Renderer,
        sample_json: &str,
        path: &Path,
    ) -> Result<String> {
        let start = Instant::now();
        let out = render_prepared(renderer, &self.assembled, &self.inputs, &mut |_| {})?;
        let rendered_at = start.elapsed().as_secs_f64();
        let meta = serde_json::json!({
            "renderer": RENDERER_VERSION,
            "sample": serde_json::from_str::<serde_json::Value>(sample_json)?,
            // Every material of the assembled scene (models, classes, all parameters).
            "materials": lightfarm_render::scene::materials_json(&self.assembled.scene),
            // What the id pass's values mean (here, not as a second attribute: see id_table_json).
            "id_table": serde_json::from_str::<serde_json::Value>(&lightfarm_render::output::id_table_json())?,
        });
        write_exr(
            path,
            &out,
            &[("lightfarm.sample".to_string(), meta.to_string())],
        )?;
        let write_seconds = start.elapsed().as_secs_f64() - rendered_at;
        let mut stats = serde_json::to_value(&out.stats)?;
        let render_seconds = out.stats.seconds + out.stats.olat_seconds;
        // The device work outside the render's own timer (the OLAT basis, the upload) is setup.
        let setup_seconds = self.setup_seconds + (rendered_at - render_seconds).max(0.0);
        stats["assemble_seconds"] = serde_json::json!(self.assemble_seconds);
        stats["setup_seconds"] = serde_json::json!(setup_seconds);
        stats["write_seconds"] = serde_json::json!(write_seconds);
        stats["sample_seconds"] = serde_json::json!(
            self.assemble_seconds + setup_seconds + render_seconds + write_seconds
        );
        Ok(stats.to_string())
    }
}

/// Renders `sample` (whose JSON is `sample_json`) and writes the sample EXR to `path`;
/// returns the render statistics as JSON. The EXR has one header attribute (renderer, sample
/// and the assembled scene's materials), so its bytes are a pure function of the sample and
/// the device: render times go to the index, not the file, and a re-render is bit-identical.
/// Besides the render's own statistics, the JSON says where the sample's time went, in
/// seconds: `assemble_seconds` (the subject: head, hair growth, garment, textures),
/// `setup_seconds` (environment maps, BVH builds, upload), the render's `seconds` (and
/// `olat_seconds`), `write_seconds` (the EXR) and `sample_seconds` (their sum: the sample's own
/// work; a worker overlaps the next sample's assembly and setup with this one's render).
pub fn render_to_exr(
    renderer: &Renderer,
    catalog: &lightfarm_scene::Catalog,
    sample: &SampleSpec,
    sample_json: &str,
    path: &Path,
) -> Result<String> {
    prepare(catalog, sample)?.render_to_exr(renderer, sample_json, path)
}
