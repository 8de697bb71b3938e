//! Compiles the WGSL kernels under `shaders/kernels/` to SPIR-V with naga at build time
//! (`kernel_source.rs`), so a broken shader fails `cargo build` with naga's diagnostic rather
//! than a user's render. Every kernel gets `TRAVERSAL_COUNTERS` prepended: false, except in
//! `integrator_counters` (the integrator with the per-pixel traversal counters of
//! shaders/inc/traverse.wgsl).

use std::path::PathBuf;

mod kernel_source;

fn main() {
    let manifest =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let root = manifest.join("../../shaders");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo:rerun-if-changed={}", root.display());
    println!("cargo:rerun-if-changed=kernel_source.rs");
    let kernels = [
        ("integrator", "integrator", false),
        ("integrator_counters", "integrator", true),
        ("probe", "probe", false),
        ("trace_rays", "trace_rays", false),
        ("tables", "tables", false),
    ];
    for (kernel, file, counters) in kernels {
        let compiled =
            kernel_source::compile(&root, file, counters, false).unwrap_or_else(|e| panic!("{e}"));
        for f in &compiled.files {
            println!("cargo:rerun-if-changed={}", f.display());
        }
        std::fs::write(out_dir.join(format!("{kernel}.wgsl")), &compiled.wgsl)
            .expect("write expanded WGSL");
        std::fs::write(
            out_dir.join(format!("{kernel}.spv")),
            compiled.spirv_bytes(),
        )
        .expect("write SPIR-V");
    }
}
