//! The statistics a worker records with each sample say where its time went: the subject's
//! assembly, the setup before the render (environment maps, BVHs, upload), the render and the
//! EXR, each measured once, adding up to the sample's wall time, beside the render's own
//! figures. `examples/sample_cost.rs` and the sample index read them.

use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;

#[test]
fn sample_stats_split_the_wall_time_into_its_phases() {
    let catalog = Catalog::builtin().expect("catalog");
    let text = "name = \"stats-test\"\nseed = 3\ncount = 2\nwidth = 16\nheight = 16\nspp = 2\n";
    let spec = DatasetSpec::from_toml_str(text, "stats-test.toml")
        .and_then(|s| s.validate(&catalog))
        .expect("spec");
    let renderer =
        Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device (lavapipe on CPU machines)");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("0.exr");
    let sample = expand(&spec, 0).expect("expand");
    let json = serde_json::to_string(&sample).expect("json");
    let start = std::time::Instant::now();
    let stats = lightfarm_worker::render_to_exr(&renderer, &catalog, &sample, &json, &path)
        .expect("render");
    let wall = start.elapsed().as_secs_f64();
    let stats: serde_json::Value = serde_json::from_str(&stats).expect("stats are JSON");
    let secs = |k: &str| {
        stats
            .get(k)
            .and_then(|v| v.as_f64())
            .unwrap_or_else(|| panic!("stats have no number {k}: {stats}"))
    };
    let phases = [
        secs("assemble_seconds"),
        secs("setup_seconds"),
        secs("seconds"),
        secs("olat_seconds"),
        secs("write_seconds"),
    ];
    let total = secs("sample_seconds");
    assert!(
        phases.iter().all(|&p| p >= 0.0),
        "a phase took negative time: {stats}"
    );
    // Assembly (a head, hair grown strand by strand, a garment) and the render are never free.
    assert!(phases[0] > 0.0 && phases[2] > 0.0, "{stats}");
    let sum: f64 = phases.iter().sum();
    assert!(
        (sum - total).abs() <= 1e-6 * total.max(1.0) + 1e-9,
        "the phases add up to {sum} s, not the sample's {total} s: {stats}"
    );
    assert!(
        total <= wall,
        "sample_seconds {total} > the call's wall time {wall}"
    );
    // The render's own figures are still there, for the sample it rendered.
    assert_eq!(stats["width"], 16);
    assert_eq!(stats["spp"], 2);
    assert!(
        stats["curve_segments"].as_u64().is_some_and(|n| n > 0),
        "{stats}"
    );
}
