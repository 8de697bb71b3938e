//! A tiny dataset rendered by the project itself (lavapipe on CPU machines): four 32×32
//! samples of four identities, exported as a folder like `lightfarm export --format folder`.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;
use lightfarm_store::{ExportFormat, ExportWriter, SampleRecord};

pub const SIZE: usize = 32;
pub const COUNT: u64 = 4;

/// The dataset directory, rendered once per test binary.
pub fn dataset() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let tmp = tempfile::tempdir().expect("tempdir");
        let dir = tmp.path().join("export");
        render(&dir);
        (tmp, dir)
    })
    .1
}

fn render(out: &Path) {
    let catalog = Catalog::builtin().expect("catalog");
    let text = format!(
        "name = \"trainer-test\"\nseed = 5\ncount = {COUNT}\nwidth = {SIZE}\nheight = {SIZE}\nspp = 16\n\
         [subject]\nglasses_probability = 0.5\nheadset_probability = 0.0\n"
    );
    let spec = DatasetSpec::from_toml_str(&text, "trainer-test.toml")
        .and_then(|s| s.validate(&catalog))
        .expect("spec");
    let renderer =
        Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device (lavapipe on CPU machines)");
    let mut writer =
        ExportWriter::create(out, "trainer-test", &ExportFormat::Folder).expect("export dir");
    let scratch = tempfile::tempdir().expect("tempdir");
    for index in 0..COUNT {
        let sample = expand(&spec, index).expect("expand");
        let json = serde_json::to_string(&sample).expect("json");
        let path = scratch.path().join(format!("{index}.exr"));
        lightfarm_worker::render_to_exr(&renderer, &catalog, &sample, &json, &path)
            .expect("render");
        let exr = std::fs::read(&path).expect("read exr");
        let record = SampleRecord {
            job_id: "trainer-test".into(),
            index,
            split: serde_json::to_value(sample.split)
                .expect("split")
                .as_str()
                .unwrap_or("train")
                .to_owned(),
            blake3: lightfarm_store::hash_hex(&exr),
            size: exr.len() as u64,
            metadata_json: json,
            committed_unix: 0.0,
            sequence: index + 1,
        };
        writer.add(&record, &exr).expect("export add");
    }
    writer.finish().expect("export finish");
}
