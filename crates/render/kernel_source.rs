//! WGSL to SPIR-V for the renderer's kernels: `//!include path` lines (relative to `shaders/`)
//! splice in shared code once per file, `//!include_counters ON OFF` splices in ON in the
//! kernels with traversal counters and OFF in the others (so that only the former use subgroup
//! operations), `TRAVERSAL_COUNTERS` is prepended, and naga validates
//! and writes SPIR-V with the project's options. One implementation for build.rs (every kernel,
//! at build time) and `examples/compile_kernel.rs` (a kernel from any `shaders/` tree, for
//! `bench/kernel_ab.sh`).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// A compiled kernel: its expanded WGSL, its SPIR-V and every file it read.
pub struct Compiled {
    pub wgsl: String,
    pub spirv: Vec<u32>,
    pub files: Vec<PathBuf>,
}

fn expand(
    root: &Path,
    rel: &str,
    counters: bool,
    seen: &mut HashSet<String>,
    out: &mut String,
    files: &mut Vec<PathBuf>,
) -> Result<(), String> {
    if !seen.insert(rel.to_string()) {
        return Ok(());
    }
    let path = root.join(rel);
    let src = std::fs::read_to_string(&path)
        .map_err(|e| format!("cannot read shader {}: {e}", path.display()))?;
    files.push(path.clone());
    for line in src.lines() {
        if let Some(inc) = line.trim().strip_prefix("//!include ") {
            expand(root, inc.trim(), counters, seen, out, files)?;
        } else if let Some(pair) = line.trim().strip_prefix("//!include_counters ") {
            let pair: Vec<&str> = pair.split_whitespace().collect();
            let [on, off] = pair[..] else {
                return Err(format!(
                    "{}: `{}` needs two files: //!include_counters ON OFF",
                    path.display(),
                    line.trim()
                ));
            };
            let chosen = if counters { on } else { off };
            expand(root, chosen, counters, seen, out, files)?;
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    Ok(())
}

impl Compiled {
    /// The SPIR-V as the little-endian bytes of a `.spv` file.
    pub fn spirv_bytes(&self) -> Vec<u8> {
        self.spirv.iter().flat_map(|w| w.to_le_bytes()).collect()
    }
}

/// Compiles `shaders/kernels/<file>.wgsl` under `root`. `naga_guards` restores naga's
/// loop-bounding counters and integer-division checks, which the renderer leaves out (every
/// loop ends, every integer divisor is a constant or a size the host checked non-zero;
/// BENCHMARKS.md "The kernel on lavapipe" has what they cost). Errors carry naga's diagnostic.
pub fn compile(
    root: &Path,
    file: &str,
    counters: bool,
    naga_guards: bool,
) -> Result<Compiled, String> {
    let rel = format!("kernels/{file}.wgsl");
    let mut wgsl = format!("const TRAVERSAL_COUNTERS: bool = {counters};\n");
    let mut files = Vec::new();
    expand(
        root,
        &rel,
        counters,
        &mut HashSet::new(),
        &mut wgsl,
        &mut files,
    )?;
    let module =
        naga::front::wgsl::parse_str(&wgsl).map_err(|e| e.emit_to_string_with_path(&wgsl, &rel))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string_with_path(&wgsl, &rel))?;
    let mut options = naga::back::spv::Options {
        lang_version: (1, 3),
        // The traversal stacks in workgroup memory are written before they are read; naga's
        // zero-fill polyfill would add a barrier, which makes lavapipe run compute
        // invocations as coroutines.
        zero_initialize_workgroup_memory: naga::back::spv::ZeroInitializeWorkgroupMemoryMode::None,
        force_loop_bounding: naga_guards,
        emit_int_div_checks: naga_guards,
        ..Default::default()
    };
    // naga labels everything when it was built with debug assertions: the SPIR-V, and so the
    // Mesa shader cache key, would then differ between debug and release builds.
    options.flags.remove(naga::back::spv::WriterFlags::DEBUG);
    let pipeline = naga::back::spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: "main".into(),
    };
    let spirv = naga::back::spv::write_vec(&module, &info, &options, Some(&pipeline))
        .map_err(|e| format!("SPIR-V generation failed for {rel}: {e}"))?;
    Ok(Compiled { wgsl, spirv, files })
}
