//! Compiles the WGSL kernels under `shaders/kernels/` to SPIR-V with naga at build time, so a
//! broken shader fails `cargo build` with naga's diagnostic rather than a user's render.
//! `//!include path` lines (relative to `shaders/`) splice in shared code, once per file.
//! Every kernel gets `TRAVERSAL_COUNTERS` prepended: false, except in `integrator_counters`
//! (the integrator with the per-pixel traversal counters of shaders/inc/traverse.wgsl).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

fn expand(root: &Path, rel: &str, seen: &mut HashSet<String>, out: &mut String) {
    if !seen.insert(rel.to_string()) {
        return;
    }
    let path = root.join(rel);
    println!("cargo:rerun-if-changed={}", path.display());
    let src = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read shader {}: {e}", path.display()));
    for line in src.lines() {
        if let Some(inc) = line.trim().strip_prefix("//!include ") {
            expand(root, inc.trim(), seen, out);
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
}

fn main() {
    let manifest =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let root = manifest.join("../../shaders");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo:rerun-if-changed={}", root.display());
    let kernels = [
        ("integrator", "integrator", false),
        ("integrator_counters", "integrator", true),
        ("probe", "probe", false),
        ("trace_rays", "trace_rays", false),
        ("tables", "tables", false),
    ];
    for (kernel, file, counters) in kernels {
        let rel = format!("kernels/{file}.wgsl");
        let mut src = format!("const TRAVERSAL_COUNTERS: bool = {counters};\n");
        expand(&root, &rel, &mut HashSet::new(), &mut src);
        std::fs::write(out_dir.join(format!("{kernel}.wgsl")), &src).expect("write expanded WGSL");
        let module = match naga::front::wgsl::parse_str(&src) {
            Ok(m) => m,
            Err(e) => panic!("{}", e.emit_to_string_with_path(&src, &rel)),
        };
        let info = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(&src, &rel)));
        let mut options = naga::back::spv::Options {
            lang_version: (1, 3),
            // The traversal stacks in workgroup memory are written before they are read; naga's
            // zero-fill polyfill would add a barrier, which makes lavapipe run compute
            // invocations as coroutines.
            zero_initialize_workgroup_memory:
                naga::back::spv::ZeroInitializeWorkgroupMemoryMode::None,
            // naga's guards for WGSL's portability rules cost time in the traversal loops and
            // buy nothing here (BENCHMARKS.md, "The kernel": +8% on the sphere, +12% on the
            // head on lavapipe with the deferred material read): every loop ends (the
            // traversal when its stack empties, walks and paths at their caps), and every
            // integer divisor is a constant or a size the host checked non-zero (texture and
            // environment widths).
            force_loop_bounding: false,
            emit_int_div_checks: false,
            ..Default::default()
        };
        // naga labels everything when it was built with debug assertions: the SPIR-V, and so
        // the Mesa shader cache key, would then differ between debug and release builds.
        options.flags.remove(naga::back::spv::WriterFlags::DEBUG);
        let pipeline = naga::back::spv::PipelineOptions {
            shader_stage: naga::ShaderStage::Compute,
            entry_point: "main".into(),
        };
        let spv = naga::back::spv::write_vec(&module, &info, &options, Some(&pipeline))
            .unwrap_or_else(|e| panic!("SPIR-V generation failed for {rel}: {e}"));
        let bytes: Vec<u8> = spv.iter().flat_map(|w| w.to_le_bytes()).collect();
        std::fs::write(out_dir.join(format!("{kernel}.spv")), bytes).expect("write SPIR-V");
    }
}
