//! The kernels' WGSL preprocessing (crates/render/kernel_source.rs): `//!include_counters ON OFF`
//! picks ON only in the kernels with traversal counters, and a malformed directive or a missing
//! file is refused with an error naming the shader file.

// spirv_bytes serves compile_kernel only.
#[allow(dead_code)]
#[path = "../kernel_source.rs"]
mod kernel_source;

use std::path::{Path, PathBuf};

fn tree(name: &str, kernel: &str) -> PathBuf {
    let root = std::env::temp_dir().join(format!("lf-kernel-source-{}-{name}", std::process::id()));
    std::fs::create_dir_all(root.join("kernels")).expect("temp dir");
    std::fs::create_dir_all(root.join("inc")).expect("temp dir");
    std::fs::write(root.join("kernels/k.wgsl"), kernel).expect("write");
    std::fs::write(
        root.join("inc/on.wgsl"),
        "fn picked() -> u32 { return 1u; }\n",
    )
    .expect("write");
    std::fs::write(
        root.join("inc/off.wgsl"),
        "fn picked() -> u32 { return 2u; }\n",
    )
    .expect("write");
    root
}

const KERNEL: &str = "//!include_counters inc/on.wgsl inc/off.wgsl
@group(0) @binding(0) var<storage, read_write> out: array<u32>;
@compute @workgroup_size(1)
fn main() {
    out[0] = picked();
}
";

#[test]
fn include_counters_picks_its_first_file_only_with_counters() {
    let root = tree("pick", KERNEL);
    let on = kernel_source::compile(&root, "k", true, false).expect("compiles with counters");
    let off = kernel_source::compile(&root, "k", false, false).expect("compiles without");
    assert!(on.wgsl.contains("return 1u") && !on.wgsl.contains("return 2u"));
    assert!(off.wgsl.contains("return 2u") && !off.wgsl.contains("return 1u"));
    assert!(on.files.iter().any(|f| f.ends_with("inc/on.wgsl")));
    assert!(!off.files.iter().any(|f| f.ends_with("inc/on.wgsl")));
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn a_malformed_include_counters_or_a_missing_file_is_refused_naming_the_file() {
    let root = tree("bad", "//!include_counters inc/on.wgsl\n");
    let e = kernel_source::compile(&root, "k", true, false)
        .err()
        .expect("one file is refused");
    assert!(e.contains("k.wgsl") && e.contains("needs two files"), "{e}");
    let root2 = tree("missing", "//!include_counters inc/on.wgsl inc/gone.wgsl\n");
    let e = kernel_source::compile(&root2, "k", false, false)
        .err()
        .expect("a missing file is refused");
    assert!(
        e.contains(&Path::new("inc/gone.wgsl").display().to_string()),
        "{e}"
    );
    std::fs::remove_dir_all(&root).ok();
    std::fs::remove_dir_all(&root2).ok();
}
