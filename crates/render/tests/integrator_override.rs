//! `LIGHTFARM_INTEGRATOR_SPV` (the kernel A/B's way in): a file that is not SPIR-V, or is not
//! there, is refused with an error naming the variable, the file and the way back. Its own test
//! binary, since the variable is process-wide.

use lightfarm_render::renderer::INTEGRATOR_SPV_VAR;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;

fn refusal(path: &std::path::Path) -> String {
    std::env::set_var(INTEGRATOR_SPV_VAR, path);
    let result = Renderer::new(&DeviceRequest::Auto);
    std::env::remove_var(INTEGRATOR_SPV_VAR);
    match result {
        Ok(_) => panic!("{} was accepted as an integrator", path.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_file_that_is_not_spirv_or_is_missing_is_refused_naming_it() {
    let dir = std::env::temp_dir().join(format!("lf-integrator-override-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let text = dir.join("integrator.wgsl");
    std::fs::write(&text, "fn main() {}\n").expect("write");
    let e = refusal(&text);
    assert!(
        e.contains(INTEGRATOR_SPV_VAR) && e.contains("integrator.wgsl"),
        "{e}"
    );
    assert!(
        e.contains("not a little-endian SPIR-V module") && e.contains("unset it"),
        "{e}"
    );

    let missing = dir.join("missing.spv");
    let e = refusal(&missing);
    assert!(
        e.contains("missing.spv") && e.contains("cannot read it"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();

    // Unset, the built-in integrator renders as before.
    Renderer::new(&DeviceRequest::Auto).expect("the built-in integrator");
}
