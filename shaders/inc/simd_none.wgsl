// The production kernels' stand-ins for simd_counting.wgsl: only integrator_counters counts
// SIMD-group turns, and these keep subgroup operations (an optional Vulkan feature) out of
// every other kernel. They are called only under `if (TRAVERSAL_COUNTERS)`.

fn simd_leader() -> bool {
    return false;
}

fn simd_width() -> u32 {
    return 0u;
}
