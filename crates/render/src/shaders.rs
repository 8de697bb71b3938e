//! SPIR-V of the kernels under `shaders/kernels/`, compiled by build.rs with naga.

use crate::vulkan::BindingKind;

/// SPIR-V words from their little-endian bytes (a length not a multiple of 4 drops the tail;
/// callers reading files check it first).
pub(crate) fn words(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// The path tracer.
pub fn integrator() -> Vec<u32> {
    words(include_bytes!(concat!(env!("OUT_DIR"), "/integrator.spv")))
}

/// The path tracer with the per-pixel traversal counters (crate::counters).
pub fn integrator_counters() -> Vec<u32> {
    words(include_bytes!(concat!(
        env!("OUT_DIR"),
        "/integrator_counters.spv"
    )))
}

/// Sampling probes (BSDF and environment sampling, run by the tests).
pub fn probe() -> Vec<u32> {
    words(include_bytes!(concat!(env!("OUT_DIR"), "/probe.spv")))
}

/// Closest-hit queries for arbitrary rays (traversal tests).
pub fn trace_rays() -> Vec<u32> {
    words(include_bytes!(concat!(env!("OUT_DIR"), "/trace_rays.spv")))
}

/// The layered model's directional-albedo tables (computed once per device).
pub fn tables() -> Vec<u32> {
    words(include_bytes!(concat!(env!("OUT_DIR"), "/tables.spv")))
}

/// The bindings every kernel declares (shaders/inc/bindings.wgsl): storage buffers, but the
/// BVH nodes (binding 1) and triangle positions (binding 2) are record images
/// (crate::vulkan::GpuImage says why).
pub const BINDINGS: [BindingKind; 17] = {
    let mut b = [BindingKind::StorageBuffer; 17];
    b[1] = BindingKind::Image;
    b[2] = BindingKind::Image;
    b
};
