//!include inc/bindings.wgsl
//!include inc/frame.wgsl
//!include inc/traverse.wgsl

// Closest-hit queries for arbitrary rays, used to check the shader traversal against obvhs'
// CPU traversal and brute force: probe_in[2i] = (origin, tmin), probe_in[2i+1] = (dir, tmax);
// probe_out[i] = (t or -1, bitcast instance, bitcast triangle slot, u).

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    stack_base = lid;
    let i = gid.x;
    if (i >= pc.count) {
        return;
    }
    let a = probe_in[2u * i];
    let b = probe_in[2u * i + 1u];
    let h = trace_closest(Ray(a.xyz, b.xyz, a.w, b.w));
    probe_out[i] = vec4<f32>(h.t, bitcast<f32>(h.instance), bitcast<f32>(h.tri), h.u);
}
