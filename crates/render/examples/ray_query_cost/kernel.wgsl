enable wgpu_ray_query;

// Closest hits through the device's own acceleration structure (VK_KHR_ray_query), with the
// same ray and hit layout as shaders/kernels/trace_rays.wgsl: rays[2i] = (origin, tmin),
// rays[2i+1] = (dir, tmax); hits[i] = (t or -1, bitcast instance, bitcast primitive, u).

struct Push {
    count: u32,
}

@group(0) @binding(0) var tlas: acceleration_structure;
@group(0) @binding(1) var<storage, read> rays: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> hits: array<vec4<f32>>;
var<immediate> pc: Push;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= pc.count) {
        return;
    }
    let a = rays[2u * i];
    let b = rays[2u * i + 1u];
    var rq: ray_query;
    rayQueryInitialize(&rq, tlas, RayDesc(RAY_FLAG_FORCE_OPAQUE, 0xFFu, a.w, b.w, a.xyz, b.xyz));
    // Every geometry is opaque, so the query finds the closest hit without stopping.
    while (rayQueryProceed(&rq)) {
    }
    let h = rayQueryGetCommittedIntersection(&rq);
    if (h.kind == RAY_QUERY_INTERSECTION_NONE) {
        hits[i] = vec4<f32>(-1.0, 0.0, 0.0, 0.0);
        return;
    }
    hits[i] = vec4<f32>(h.t, bitcast<f32>(h.instance_index), bitcast<f32>(h.primitive_index), h.barycentrics.x);
}
