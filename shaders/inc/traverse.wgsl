// Two-level ray traversal: a CWBVH over instances (TLAS) whose leaves are instances, each with
// its own CWBVH over triangles (BLAS). Nodes are obvhs' `CwBvhNode` (80 bytes = 20 words) uploaded
// as-is; the algorithm is Ylitie et al. 2017, with the node-group/primitive-group stack of obvhs'
// CPU traversal so that the GPU and CPU visit the same leaves.
//
// Node words: 0-2 p.xyz, 3 e[0..3] | imask << 24, 4 child_base_idx, 5 primitive_base_idx,
// 6-7 child_meta[8], 8-9 child_min_x, 10-11 child_max_x, 12-13 min_y, 14-15 max_y, 16-17 min_z, 18-19 max_z.

const NODE_WORDS: u32 = 20u;
const TRI_ATTR_VEC4S: u32 = 5u;
const STACK_SIZE: u32 = 32u;

struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    tmin: f32,
    tmax: f32,
};

struct Hit {
    t: f32,
    instance: u32,
    tri: u32,      // global triangle slot (leaf order): index into tri_pos / 3 and tri_attr / 5
    u: f32,        // barycentric weight of vertex 1
    v: f32,        // barycentric weight of vertex 2
};

fn no_hit() -> Hit {
    return Hit(-1.0, 0xffffffffu, 0xffffffffu, 0.0, 0.0);
}

fn octant_inv4(dir: vec3<f32>) -> u32 {
    return select(0x04040404u, 0u, dir.x < 0.0)
        | select(0x02020202u, 0u, dir.y < 0.0)
        | select(0x01010101u, 0u, dir.z < 0.0);
}

fn safe_inverse(x: f32) -> f32 {
    // Same rule as obvhs' Ray::new so GPU and CPU cull identically.
    let eps = 1.1920929e-7;
    if (abs(x) <= eps) {
        return select(-1.0, 1.0, x >= 0.0) / eps;
    }
    return 1.0 / x;
}

fn byte_of(w: u32, j: u32) -> f32 {
    return f32((w >> (j * 8u)) & 0xffu);
}

// Returns the hit mask of obvhs' `intersect_ray`: inner children in the high byte (by traversal
// priority), leaf primitive bits (unary counts shifted by their offset) in the low 24 bits.
fn intersect_node(base: u32, origin: vec3<f32>, inv_dir: vec3<f32>, tmin: f32, tmax: f32, oct_inv4: u32) -> u32 {
    let p = vec3<f32>(bitcast<f32>(nodes[base]), bitcast<f32>(nodes[base + 1u]), bitcast<f32>(nodes[base + 2u]));
    let w3 = nodes[base + 3u];
    let extent = vec3<f32>(
        bitcast<f32>((w3 & 0xffu) << 23u),
        bitcast<f32>(((w3 >> 8u) & 0xffu) << 23u),
        bitcast<f32>(((w3 >> 16u) & 0xffu) << 23u),
    );
    let adj_inv = extent * inv_dir;
    let adj_orig = (p - origin) * inv_dir;
    let neg = inv_dir < vec3<f32>(0.0);
    var hit_mask = 0u;
    for (var half = 0u; half < 2u; half++) {
        let meta4 = nodes[base + 6u + half];
        let is_inner4 = (meta4 & (meta4 << 1u)) & 0x10101010u;
        let inner_mask4 = (is_inner4 >> 4u) * 0xffu;
        let bit_index4 = (meta4 ^ (oct_inv4 & inner_mask4)) & 0x1f1f1f1fu;
        let child_bits4 = (meta4 >> 5u) & 0x07070707u;
        let lo_x = nodes[base + 8u + half];
        let hi_x = nodes[base + 10u + half];
        let lo_y = nodes[base + 12u + half];
        let hi_y = nodes[base + 14u + half];
        let lo_z = nodes[base + 16u + half];
        let hi_z = nodes[base + 18u + half];
        for (var j = 0u; j < 4u; j++) {
            let qlo = vec3<f32>(byte_of(lo_x, j), byte_of(lo_y, j), byte_of(lo_z, j));
            let qhi = vec3<f32>(byte_of(hi_x, j), byte_of(hi_y, j), byte_of(hi_z, j));
            let near = select(qlo, qhi, neg);
            let far = select(qhi, qlo, neg);
            let t0 = near * adj_inv + adj_orig;
            let t1 = far * adj_inv + adj_orig;
            let tn = max(max3(t0), tmin);
            let tf = min(min3(t1), tmax);
            if (tn <= tf) {
                let child_bits = (child_bits4 >> (j * 8u)) & 0xffu;
                let bit_index = (bit_index4 >> (j * 8u)) & 0xffu;
                hit_mask |= child_bits << bit_index;
            }
        }
    }
    return hit_mask;
}

// Möller–Trumbore in the exact formulation of obvhs' `Triangle::intersect`, so that the CPU
// reference and the shader agree bit for bit on which triangles are hit.
fn intersect_triangle(slot: u32, origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32) -> vec3<f32> {
    let v0 = tri_pos[slot * 3u].xyz;
    let v1 = tri_pos[slot * 3u + 1u].xyz;
    let v2 = tri_pos[slot * 3u + 2u].xyz;
    let e1 = v0 - v1;
    let e2 = v2 - v0;
    let n = cross(e1, e2);
    let c = v0 - origin;
    let r = cross(dir, c);
    let inv_det = 1.0 / dot(n, dir);
    let u = dot(r, e2) * inv_det;
    let v = dot(r, e1) * inv_det;
    let w = 1.0 - u - v;
    let signs = (bitcast<u32>(u) | bitcast<u32>(v) | bitcast<u32>(w)) & 0x80000000u;
    if (inv_det != 0.0 && signs == 0u) {
        let t = dot(n, c) * inv_det;
        if (t >= tmin && t <= tmax) {
            return vec3<f32>(t, u, v);
        }
    }
    return vec3<f32>(-1.0, 0.0, 0.0);
}

fn transform_point(m: mat4x4<f32>, p: vec3<f32>) -> vec3<f32> {
    return (m * vec4<f32>(p, 1.0)).xyz;
}

fn transform_dir(m: mat4x4<f32>, d: vec3<f32>) -> vec3<f32> {
    return (m * vec4<f32>(d, 0.0)).xyz;
}

// Closest hit (any_hit = false) or first hit found (any_hit = true) in one BLAS. The ray is in object
// space with an unnormalised direction, so t stays in world units across instances.
fn traverse_blas(inst_id: u32, origin: vec3<f32>, dir: vec3<f32>, tmin: f32, best: ptr<function, Hit>, any_hit: bool) -> bool {
    let inst = instances[inst_id];
    let inv_dir = vec3<f32>(safe_inverse(dir.x), safe_inverse(dir.y), safe_inverse(dir.z));
    let oct = octant_inv4(dir);
    var stack: array<vec2<u32>, STACK_SIZE>;
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    var found = false;
    loop {
        while (prims.y != 0u) {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            let slot = inst.tri_offset + prims.x + local;
            let tmax = select((*best).t, 3.4e38, (*best).t < 0.0);
            let h = intersect_triangle(slot, origin, dir, tmin, tmax);
            if (h.x >= 0.0 && ((*best).t < 0.0 || h.x < (*best).t)) {
                *best = Hit(h.x, inst_id, slot, h.y, h.z);
                found = true;
                if (any_hit) {
                    return true;
                }
            }
        }
        if ((current.y & 0xff000000u) != 0u) {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            if ((current.y & 0xff000000u) != 0u) {
                stack[sp] = current;
                sp = min(sp + 1u, STACK_SIZE - 1u);
            }
            let slot_index = (offset - 24u) ^ (oct & 0xffu);
            let relative = countOneBits(hits_imask & ~(0xffffffffu << slot_index));
            let node = inst.node_offset + current.x + relative;
            let base = node * NODE_WORDS;
            let tmax = select((*best).t, 3.4e38, (*best).t < 0.0);
            let hit_mask = intersect_node(base, origin, inv_dir, tmin, tmax, oct);
            current.x = nodes[base + 4u];
            prims.x = nodes[base + 5u];
            current.y = (hit_mask & 0xff000000u) | (nodes[base + 3u] >> 24u);
            prims.y = hit_mask & 0x00ffffffu;
        } else {
            current = vec2<u32>(0u, 0u);
        }
        if (prims.y == 0u && (current.y & 0xff000000u) == 0u) {
            if (sp == 0u) {
                break;
            }
            sp -= 1u;
            current = stack[sp];
        }
    }
    return found;
}

// Walks the TLAS; each leaf is an instance (TLAS primitive i = instance i after the host's
// reordering), whose BLAS is traversed with the ray moved into object space.
fn trace_impl(ray: Ray, any_hit: bool, skip_flags: u32) -> Hit {
    var best = no_hit();
    if (params.tlas_node_offset == NO_NODE) {
        return best;
    }
    if (ray.tmax < 3.0e38) {
        best.t = ray.tmax;
    }
    let inv_dir = vec3<f32>(safe_inverse(ray.dir.x), safe_inverse(ray.dir.y), safe_inverse(ray.dir.z));
    let oct = octant_inv4(ray.dir);
    var stack: array<vec2<u32>, 16>;
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    loop {
        while (prims.y != 0u) {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            let inst_id = prims.x + local;
            let inst = instances[inst_id];
            if ((inst.flags & skip_flags) == 0u) {
                let o = transform_point(inst.world_to_obj, ray.origin);
                let d = transform_dir(inst.world_to_obj, ray.dir);
                if (traverse_blas(inst_id, o, d, ray.tmin, &best, any_hit) && any_hit) {
                    return best;
                }
            }
        }
        if ((current.y & 0xff000000u) != 0u) {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            if ((current.y & 0xff000000u) != 0u) {
                stack[sp] = current;
                sp = min(sp + 1u, 15u);
            }
            let slot_index = (offset - 24u) ^ (oct & 0xffu);
            let relative = countOneBits(hits_imask & ~(0xffffffffu << slot_index));
            let base = (params.tlas_node_offset + current.x + relative) * NODE_WORDS;
            let tmax = select(best.t, 3.4e38, best.t < 0.0);
            let hit_mask = intersect_node(base, ray.origin, inv_dir, ray.tmin, tmax, oct);
            current.x = nodes[base + 4u];
            prims.x = nodes[base + 5u];
            current.y = (hit_mask & 0xff000000u) | (nodes[base + 3u] >> 24u);
            prims.y = hit_mask & 0x00ffffffu;
        } else {
            current = vec2<u32>(0u, 0u);
        }
        if (prims.y == 0u && (current.y & 0xff000000u) == 0u) {
            if (sp == 0u) {
                break;
            }
            sp -= 1u;
            current = stack[sp];
        }
    }
    if (best.instance == 0xffffffffu) {
        return no_hit();
    }
    return best;
}

fn trace_closest(ray: Ray) -> Hit {
    return trace_impl(ray, false, 0u);
}
