// Two-level ray traversal: a CWBVH over instances (TLAS) whose leaves are instances, each with
// its own CWBVH over triangles (BLAS). Nodes are obvhs' `CwBvhNode` (80 bytes = 20 words) uploaded
// as-is; the algorithm is Ylitie et al. 2017, with the node-group/primitive-group stack of obvhs'
// CPU traversal so that the GPU and CPU visit the same leaves.
//
// A node is 5 vec4<u32>: (p.xyz, e[0..3] | imask << 24), (child_base_idx, primitive_base_idx,
// child_meta[0..4], child_meta[4..8]), (min_x lo/hi, max_x lo/hi), (min_y ...), (min_z ...).

//!include_counters inc/simd_counting.wgsl inc/simd_none.wgsl

const NODE_VEC4S: u32 = 5u;
const TRI_ATTR_VEC4S: u32 = 5u;
const NO_MATERIAL: u32 = 0xffffffffu;
// Traversal stacks live in workgroup memory, interleaved by invocation: lavapipe lowers a
// dynamically indexed private array to a ladder of selects over all its elements (measured as a
// fifth of the render time), while workgroup memory is plain addressable memory. Entry `sp` of
// invocation `stack_base` is at stack_slot(sp): lanes at the same depth touch consecutive words
// (no shared-memory bank conflicts on a GPU; +2-3% on lavapipe, BENCHMARKS.md).
// Every kernel including this file runs 64 invocations per workgroup and sets `stack_base` first.
const BLAS_STACK: u32 = 24u;
const TLAS_STACK: u32 = 8u;
const WG_INVOCATIONS: u32 = 64u;
var<workgroup> blas_stack: array<vec2<u32>, 1536>; // WG_INVOCATIONS * BLAS_STACK
var<workgroup> tlas_stack: array<vec2<u32>, 512>;  // WG_INVOCATIONS * TLAS_STACK
var<private> stack_base: u32;

// Index of entry `sp` of this invocation's stack in blas_stack / tlas_stack.
fn stack_slot(sp: u32) -> u32 {
    return sp * WG_INVOCATIONS + stack_base;
}

// Traversal counters: TRAVERSAL_COUNTERS is a constant that crates/render/build.rs prepends to
// every kernel (false in the production integrator, true in `integrator_counters`), so the
// production code carries no trace of them. Totals since the invocation's last flush.
var<private> tc_nodes: u32;     // node tests (8 child boxes each)
var<private> tc_prims: u32;     // triangle or fibre-segment tests
var<private> tc_blas: u32;      // BLAS entries (instances whose box a ray reached)
var<private> tc_depth: u32;     // deepest traversal stack (BLAS or TLAS entries)
var<private> tc_overflow: u32;  // pushes onto a full stack (a subtree lost)
var<private> tc_nonfinite: u32; // rays with a NaN or infinite origin or direction
// Turns of the BLAS loop (per invocation), and turns of it and of its primitive tests counted
// once per SIMD group, by the group's leader (inc/simd_counting.wgsl).
var<private> tc_turns: u32;
var<private> tc_simd_turns: u32;
var<private> tc_simd_prims: u32;

// After each pixel's flush (kernels/integrator.wgsl): an invocation may render several.
fn tc_reset() {
    tc_nodes = 0u;
    tc_prims = 0u;
    tc_blas = 0u;
    tc_depth = 0u;
    tc_overflow = 0u;
    tc_nonfinite = 0u;
    tc_turns = 0u;
    tc_simd_turns = 0u;
    tc_simd_prims = 0u;
}

fn tc_push(sp: u32, cap: u32) {
    if (TRAVERSAL_COUNTERS) {
        tc_depth = max(tc_depth, sp + 1u);
        if (sp + 1u >= cap) {
            tc_overflow += 1u;
        }
    }
}

struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    tmin: f32,
    tmax: f32,
};

struct Hit {
    t: f32,
    instance: u32,
    // Triangles: the global triangle slot (leaf order), index into tri_pos / 3 and tri_attr / 5.
    // Curves: the index in tri_pos of the segment's first vec4.
    tri: u32,
    u: f32,        // barycentric weight of vertex 1; curves: the fraction along the segment
    v: f32,        // barycentric weight of vertex 2; curves: 0
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

// Texel of record `i` in a record image: (i mod 4096, i / 4096), rows of RECORDS_PER_ROW
// (crates/render/src/vulkan/image.rs).
fn record_texel(i: u32) -> vec2<i32> {
    return vec2<i32>(i32(i & 4095u), i32(i >> 12u));
}

fn node_record(i: u32) -> vec4<u32> {
    return textureLoad(nodes, record_texel(i));
}

// vec4 `i` of the triangle and fibre-segment positions (see Hit.tri).
fn tri_record(i: u32) -> vec4<f32> {
    return bitcast<vec4<f32>>(textureLoad(tri_pos, record_texel(i)));
}

struct NodeHit {
    hit_mask: u32,
    child_base: u32,
    prim_base: u32,
    imask: u32,
};

// Tests the ray against the 8 children of node `node` (obvhs' `intersect_ray`, four children at a
// time): inner children land in the high byte of the mask by traversal priority, leaf primitive
// bits (unary counts shifted by their offset) in the low 24 bits.
fn intersect_node(node: u32, origin: vec3<f32>, inv_dir: vec3<f32>, tmin: f32, tmax: f32, oct_inv4: u32) -> NodeHit {
    let base = node * NODE_VEC4S;
    let v0 = node_record(base);
    let v1 = node_record(base + 1u);
    let v2 = node_record(base + 2u);
    let v3 = node_record(base + 3u);
    let v4 = node_record(base + 4u);
    let p = bitcast<vec3<f32>>(v0.xyz);
    let extent = vec3<f32>(
        bitcast<f32>((v0.w & 0xffu) << 23u),
        bitcast<f32>(((v0.w >> 8u) & 0xffu) << 23u),
        bitcast<f32>(((v0.w >> 16u) & 0xffu) << 23u),
    );
    let adj_inv = extent * inv_dir;
    let adj_orig = (p - origin) * inv_dir;
    let neg = inv_dir < vec3<f32>(0.0);
    var hit_mask = 0u;
    for (var half = 0u; half < 2u; half++) {
        let meta4 = v1[2u + half];
        let is_inner4 = (meta4 & (meta4 << 1u)) & 0x10101010u;
        let inner_mask4 = (is_inner4 >> 4u) * 0xffu;
        let bit_index4 = unpack4xU8((meta4 ^ (oct_inv4 & inner_mask4)) & 0x1f1f1f1fu);
        let child_bits4 = unpack4xU8((meta4 >> 5u) & 0x07070707u);
        let lo_x = vec4<f32>(unpack4xU8(v2[half]));
        let hi_x = vec4<f32>(unpack4xU8(v2[2u + half]));
        let lo_y = vec4<f32>(unpack4xU8(v3[half]));
        let hi_y = vec4<f32>(unpack4xU8(v3[2u + half]));
        let lo_z = vec4<f32>(unpack4xU8(v4[half]));
        let hi_z = vec4<f32>(unpack4xU8(v4[2u + half]));
        let t0x = select(lo_x, hi_x, neg.x) * adj_inv.x + adj_orig.x;
        let t1x = select(hi_x, lo_x, neg.x) * adj_inv.x + adj_orig.x;
        let t0y = select(lo_y, hi_y, neg.y) * adj_inv.y + adj_orig.y;
        let t1y = select(hi_y, lo_y, neg.y) * adj_inv.y + adj_orig.y;
        let t0z = select(lo_z, hi_z, neg.z) * adj_inv.z + adj_orig.z;
        let t1z = select(hi_z, lo_z, neg.z) * adj_inv.z + adj_orig.z;
        let tn = max(max(t0x, t0y), max(t0z, vec4<f32>(tmin)));
        let tf = min(min(t1x, t1y), min(t1z, vec4<f32>(tmax)));
        let bits = select(vec4<u32>(0u), child_bits4 << bit_index4, tn <= tf);
        hit_mask |= bits.x | bits.y | bits.z | bits.w;
    }
    return NodeHit(hit_mask, v1.x, v1.y, v0.w >> 24u);
}

// Möller–Trumbore in the exact formulation of obvhs' `Triangle::intersect`, so that the CPU
// reference and the shader agree bit for bit on which triangles are hit.
fn intersect_triangle(slot: u32, origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32) -> vec3<f32> {
    let v0 = tri_record(slot * 3u).xyz;
    let v1 = tri_record(slot * 3u + 1u).xyz;
    let v2 = tri_record(slot * 3u + 2u).xyz;
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

// Material index of a triangle slot (a3.w of its attributes).
fn triangle_material(slot: u32) -> u32 {
    return bitcast<u32>(tri_attr[slot * TRI_ATTR_VEC4S + 3u].w);
}

fn hit_is_curve(h: Hit) -> bool {
    return (instances[h.instance].flags & INST_CURVES) != 0u;
}

// Material of any hit: its triangle's, or its curve instance's.
fn hit_material(h: Hit) -> u32 {
    if (hit_is_curve(h)) {
        return instances[h.instance].material;
    }
    return triangle_material(h.tri);
}

// Entering root of the sphere (c, r) along o + t d, relative to o; -3.4e38 when the line
// misses. The origin is first moved to the line's closest approach to c, so that r² - |o - c|²
// keeps its digits.
fn sphere_entry(o: vec3<f32>, d: vec3<f32>, dd: f32, c: vec3<f32>, r: f32) -> f32 {
    let ts = dot(c - o, d) / dd;
    let q = o + ts * d - c;
    let disc = (r * r - dot(q, q)) / dd;
    if (disc < 0.0) {
        return -3.4e38;
    }
    return ts - sqrt(disc);
}

// Octahedral unit vector from pack2x16snorm (crates/render/src/gpu_curves.rs `oct_encode`).
fn oct_decode(w: u32) -> vec3<f32> {
    let e = unpack2x16snorm(w);
    var n = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-n.z, 0.0);
    n.x += select(t, -t, n.x >= 0.0);
    n.y += select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// vec4s per fibre segment in tri_pos: (p0, ±r0), (p1, ±r1), (m0, octahedral m1); a negative
// radius marks a strand end (gpu_curves.rs `Segment`).
const SEGMENT_VEC4S: u32 = 3u;

// A fibre segment: the round cone from (p0, r0) to (p1, r1) between the planes through p0 and
// p1 with normals m0, m1 (the bisectors of the strand's bends, so consecutive segments join
// into one closed tube), and at a strand end the outer half of the sphere of the end radius
// (Cycles' thick linear curves, mitred). Only entering crossings count, so a ray that starts inside a fibre
// (every ray leaving one: shading.wgsl spawns them just inside) never sees its walls.
// Returns (t, fraction along the segment, 1) or t = -1. The ray origin is moved next to the
// segment before solving: hair is ~1e-4 of the distance to the camera.
fn intersect_segment(base: u32, origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32) -> vec3<f32> {
    let a = tri_record(base);
    let b = tri_record(base + 1u);
    let c = tri_record(base + 2u);
    let p0 = a.xyz;
    let p1 = b.xyz;
    let r0 = abs(a.w);
    let r1 = abs(b.w);
    let dd = dot(dir, dir);
    let shift = dot(0.5 * (p0 + p1) - origin, dir) / dd;
    let o = origin + shift * dir;
    let axis = p1 - p0;
    let len = length(axis);
    var best = 3.4e38;
    var frac = 0.0;
    if (len > 0.0) {
        let ax = axis / len;
        let m0 = c.xyz;
        let m1 = oct_decode(bitcast<u32>(c.w));
        let k = (r1 - r0) / len;
        let oc = o - p0;
        let oz = dot(oc, ax);
        let dz = dot(dir, ax);
        let op = oc - oz * ax;
        let dp = dir - dz * ax;
        let rr = r0 + k * oz;
        let qa = dot(dp, dp) - k * k * dz * dz;
        let qb = dot(op, dp) - k * dz * rr;
        let qc = dot(op, op) - rr * rr;
        let disc = qb * qb - qa * qc;
        if (disc >= 0.0 && abs(qa) > 1e-30) {
            let sd = sqrt(disc);
            // Numerically stable roots of qa t² + 2 qb t + qc.
            let q = -(qb + select(-sd, sd, qb >= 0.0));
            let r_a = q / qa;
            let r_b = select(qc / q, r_a, q == 0.0);
            for (var i = 0u; i < 2u; i++) {
                let tr = select(r_b, r_a, i == 0u);
                let z = oz + tr * dz;
                let rz = r0 + k * z;
                let x = oc + tr * dir;
                let xp = op + tr * dp;
                let entering = dot(dir, xp - rz * k * ax) < 0.0;
                let inside_cuts = dot(x, m0) >= 0.0 && dot(x - axis, m1) <= 0.0;
                let t = tr + shift;
                if (entering && inside_cuts && rz > 0.0 && t >= tmin && t <= tmax && t < best) {
                    best = t;
                    frac = clamp(z / len, 0.0, 1.0);
                }
            }
        }
    }
    // A cap is the half of its sphere beyond the end (the other half lies inside the cone).
    if (a.w < 0.0) {
        let e0 = sphere_entry(o, dir, dd, p0, r0);
        let t0 = e0 + shift;
        if (t0 >= tmin && t0 <= tmax && t0 < best && dot(o + e0 * dir - p0, axis) <= 0.0) {
            best = t0;
            frac = 0.0;
        }
    }
    if (b.w < 0.0) {
        let e1 = sphere_entry(o, dir, dd, p1, r1);
        let t1 = e1 + shift;
        if (t1 >= tmin && t1 <= tmax && t1 < best && dot(o + e1 * dir - p1, axis) >= 0.0) {
            best = t1;
            frac = 1.0;
        }
    }
    if (best < 3.0e38) {
        return vec3<f32>(best, frac, 1.0);
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
// `only_mat` != NO_MATERIAL restricts the hits to triangles of that material (the SSS walk).
fn traverse_blas(inst_id: u32, origin: vec3<f32>, dir: vec3<f32>, tmin: f32, best: ptr<function, Hit>, any_hit: bool, only_mat: u32) -> bool {
    let inst = instances[inst_id];
    let curves = (inst.flags & INST_CURVES) != 0u;
    let inv_dir = vec3<f32>(safe_inverse(dir.x), safe_inverse(dir.y), safe_inverse(dir.z));
    let oct = octant_inv4(dir);
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    var found = false;
    if (TRAVERSAL_COUNTERS) {
        tc_blas += 1u;
    }
    loop {
        if (TRAVERSAL_COUNTERS) {
            tc_turns += 1u;
            if (simd_leader()) {
                tc_simd_turns += 1u;
            }
        }
        while (prims.y != 0u) {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            if (TRAVERSAL_COUNTERS) {
                tc_prims += 1u;
                if (simd_leader()) {
                    tc_simd_prims += 1u;
                }
            }
            let tmax = select((*best).t, 3.4e38, (*best).t < 0.0);
            var slot: u32;
            var h: vec3<f32>;
            if (curves) {
                slot = inst.tri_offset + SEGMENT_VEC4S * (prims.x + local);
                h = intersect_segment(slot, origin, dir, tmin, tmax);
            } else {
                slot = inst.tri_offset + prims.x + local;
                h = intersect_triangle(slot, origin, dir, tmin, tmax);
            }
            // The material is read only for a hit, and only where it matters: most tests miss,
            // and on lavapipe every read is a gather (BENCHMARKS.md, "The kernel").
            if (h.x >= 0.0 && ((*best).t < 0.0 || h.x < (*best).t)) {
                var accept = true;
                if (any_hit || only_mat != NO_MATERIAL) {
                    var mat = inst.material;
                    if (!curves) {
                        mat = triangle_material(slot);
                    }
                    // Shadow rays (any hit) see through mostly transparent surfaces (opacity
                    // < 0.5); the SSS walk sees only its own material.
                    if (any_hit) {
                        accept = !(materials[mat].extra.y < 0.5);
                    }
                    if (only_mat != NO_MATERIAL && mat != only_mat) {
                        accept = false;
                    }
                }
                if (accept) {
                    *best = Hit(h.x, inst_id, slot, h.y, select(h.z, 0.0, curves));
                    found = true;
                    if (any_hit) {
                        return true;
                    }
                }
            }
        }
        if ((current.y & 0xff000000u) != 0u) {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            if ((current.y & 0xff000000u) != 0u) {
                blas_stack[stack_slot(sp)] = current;
                tc_push(sp, BLAS_STACK);
                sp = min(sp + 1u, BLAS_STACK - 1u);
            }
            let slot_index = (offset - 24u) ^ (oct & 0xffu);
            let relative = countOneBits(hits_imask & ~(0xffffffffu << slot_index));
            if (TRAVERSAL_COUNTERS) {
                tc_nodes += 1u;
            }
            let tmax = select((*best).t, 3.4e38, (*best).t < 0.0);
            let nh = intersect_node(inst.node_offset + current.x + relative, origin, inv_dir, tmin, tmax, oct);
            current.x = nh.child_base;
            prims.x = nh.prim_base;
            current.y = (nh.hit_mask & 0xff000000u) | nh.imask;
            prims.y = nh.hit_mask & 0x00ffffffu;
        } else {
            current = vec2<u32>(0u, 0u);
        }
        if (prims.y == 0u && (current.y & 0xff000000u) == 0u) {
            if (sp == 0u) {
                break;
            }
            sp -= 1u;
            current = blas_stack[stack_slot(sp)];
        }
    }
    return found;
}

// Walks the TLAS; each leaf is an instance (TLAS primitive i = instance i after the host's
// reordering), whose BLAS is traversed with the ray moved into object space.
fn trace_impl(ray: Ray, any_hit: bool, skip_flags: u32) -> Hit {
    // A ray with a NaN or infinite origin or direction hits nothing. Without this its box tests
    // compare NaNs, and where min/max return the other operand for a NaN (IEEE maxNum: NVIDIA,
    // llvmpipe with LLVM 19) every box is entered: one such ray walks the whole BVH.
    let lim = vec3<f32>(3.4e38);
    if (!(all(abs(ray.origin) < lim) && all(abs(ray.dir) < lim))) {
        if (TRAVERSAL_COUNTERS) {
            tc_nonfinite += 1u;
        }
        return no_hit();
    }
    var best = no_hit();
    if (params.tlas_node_offset == NO_NODE) {
        return best;
    }
    if (ray.tmax < 3.0e38) {
        best.t = ray.tmax;
    }
    let inv_dir = vec3<f32>(safe_inverse(ray.dir.x), safe_inverse(ray.dir.y), safe_inverse(ray.dir.z));
    let oct = octant_inv4(ray.dir);
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    // One instance: the walk starts at its leaf, as if the TLAS root had been tested. Its BLAS
    // root tests the ray against tighter boxes anyway, so this saves a node test per ray and
    // keeps a single traverse_blas call site.
    if ((params.scene_flags & SCENE_ONE_INSTANCE) != 0u) {
        current = vec2<u32>(0u, 0u);
        prims = vec2<u32>(0u, 1u);
    }
    loop {
        while (prims.y != 0u) {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            let inst_id = prims.x + local;
            let inst = instances[inst_id];
            if ((inst.flags & skip_flags) == 0u) {
                let o = transform_point(inst.world_to_obj, ray.origin);
                let d = transform_dir(inst.world_to_obj, ray.dir);
                if (traverse_blas(inst_id, o, d, ray.tmin, &best, any_hit, NO_MATERIAL) && any_hit) {
                    return best;
                }
            }
        }
        if ((current.y & 0xff000000u) != 0u) {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            if ((current.y & 0xff000000u) != 0u) {
                tlas_stack[stack_slot(sp)] = current;
                tc_push(sp, TLAS_STACK);
                sp = min(sp + 1u, TLAS_STACK - 1u);
            }
            let slot_index = (offset - 24u) ^ (oct & 0xffu);
            let relative = countOneBits(hits_imask & ~(0xffffffffu << slot_index));
            if (TRAVERSAL_COUNTERS) {
                tc_nodes += 1u;
            }
            let tmax = select(best.t, 3.4e38, best.t < 0.0);
            let nh = intersect_node(params.tlas_node_offset + current.x + relative, ray.origin, inv_dir, ray.tmin, tmax, oct);
            current.x = nh.child_base;
            prims.x = nh.prim_base;
            current.y = (nh.hit_mask & 0xff000000u) | nh.imask;
            prims.y = nh.hit_mask & 0x00ffffffu;
        } else {
            current = vec2<u32>(0u, 0u);
        }
        if (prims.y == 0u && (current.y & 0xff000000u) == 0u) {
            if (sp == 0u) {
                break;
            }
            sp -= 1u;
            current = tlas_stack[stack_slot(sp)];
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
