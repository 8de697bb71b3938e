//! Compiles the integrator of any `shaders/` tree to SPIR-V with the renderer's own options, for
//! `bench/kernel_ab.sh`: `LIGHTFARM_INTEGRATOR_SPV=<out>` then makes `lightfarm` render with it.
//! Usage: compile_kernel SHADERS_DIR OUT.spv [--naga-guards]
//! (`--naga-guards` keeps naga's loop-bounding counters and integer-division checks.)

#[path = "../kernel_source.rs"]
mod kernel_source;

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let guards = args.iter().any(|a| a == "--naga-guards");
    let paths: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let [root, out] = paths[..] else {
        return Err("usage: compile_kernel SHADERS_DIR OUT.spv [--naga-guards]".into());
    };
    let compiled = kernel_source::compile(std::path::Path::new(root), "integrator", false, guards)
        .map_err(|e| format!("{root}: {e}"))?;
    std::fs::write(out, compiled.spirv_bytes()).map_err(|e| format!("cannot write {out}: {e}"))?;
    eprintln!(
        "{out}: {} words from {} lines of WGSL in {} files under {root}",
        compiled.spirv.len(),
        compiled.wgsl.lines().count(),
        compiled.files.len()
    );
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}
