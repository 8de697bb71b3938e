// The SIMD-group side of the traversal counters (integrator_counters only, through
// `//!include_counters`; the production kernels include simd_none.wgsl and use no subgroup
// operation). A SIMD group is what the device runs in lockstep: a vector of 8 lanes on
// lavapipe with 256-bit llvmpipe, a warp of 32 on NVIDIA. Counting a loop's turns once per lane
// and once per group gives how many of the group's lanes did work in each turn: lanes that have
// left the loop, or wait in a branch, are idle but still pay for the turn.

// True in one active invocation of the SIMD group: the first, by subgroupBroadcastFirst.
// stack_base (the local invocation index) is unique within a workgroup, and so within a group.
fn simd_leader() -> bool {
    return subgroupBroadcastFirst(stack_base) == stack_base;
}

// Invocations in the SIMD group; called where every invocation of the group is active.
fn simd_width() -> u32 {
    return subgroupAdd(1u);
}
