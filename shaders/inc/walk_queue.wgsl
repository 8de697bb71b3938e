// The walk-dispatch schedule (the renderer's WalkSchedule::Dispatch), against the megakernel
// that walks where a path picks the subsurface lobe. Three dispatches per round of samples:
//   STAGE_PATHS   paths from the camera; one that picks a subsurface lobe is parked in its job
//                 slot and queued instead of walking (the rest of its radiance is its job's);
//   STAGE_WALKS   one invocation per queued job, side by side: the walk, then the rest of the
//                 path (later walks of it inline);
//   STAGE_GATHER  per pixel, adds its jobs' radiance and passes (one writer per pixel).
// The random stream goes with the job, so a path is the megakernel's path, bounce for bounce.
// Jobs live in `probe_in` (the integrator has no probe input): JOB_VEC4S per slot, slot
// i * pixels + p for sample i of the round at pixel p, then the queue, one slot index per vec4.

const STAGE_MEGAKERNEL: u32 = 0u;
const STAGE_PATHS: u32 = 1u;
const STAGE_WALKS: u32 = 2u;
const STAGE_GATHER: u32 = 3u;
// Not a stage of the schedule: the renderer's start-up test of the driver (report_cut_loops).
const STAGE_LOOP_PROBE: u32 = 4u;

const NO_SLOT: u32 = 0xffffffffu;
const JOB_VEC4S: u32 = 11u;
const JOB_ACTIVE: u32 = 1u;
const JOB_SPLIT_SET: u32 = 2u;

// Parked: 0 ray origin, dir.x; 1 dir.yz, hit t, instance; 2 triangle, u, v, flags (depth << 8);
// 3 throughput, rng state; 4 the subsurface lobe's weight; 5..9 the split (integrator.wgsl).
// Done (STAGE_WALKS): 0 radiance; 5..10 the passes (Passes, in PASS_VEC4S order).

fn job_base(slot: u32) -> u32 {
    return slot * JOB_VEC4S;
}

fn queue_entry(k: u32) -> u32 {
    return pc.sample_count * params.width * params.height * JOB_VEC4S + k;
}

fn job_flags(slot: u32) -> u32 {
    return bitcast<u32>(probe_in[job_base(slot) + 2u].w);
}

fn job_clear(slot: u32) {
    probe_in[job_base(slot) + 2u].w = bitcast<f32>(0u);
}

fn job_park(slot: u32, ray: Ray, hit: Hit, throughput: vec3<f32>, lobe_weight: vec3<f32>, depth: u32, split: Split, split_set: bool, rng: Rng) {
    let b = job_base(slot);
    var flags = JOB_ACTIVE | (depth << 8u);
    if (split_set) {
        flags |= JOB_SPLIT_SET;
    }
    probe_in[b] = vec4<f32>(ray.origin, ray.dir.x);
    probe_in[b + 1u] = vec4<f32>(ray.dir.yz, hit.t, bitcast<f32>(hit.instance));
    probe_in[b + 2u] = vec4<f32>(bitcast<f32>(hit.tri), hit.u, hit.v, bitcast<f32>(flags));
    probe_in[b + 3u] = vec4<f32>(throughput, bitcast<f32>(rng.state));
    probe_in[b + 4u] = vec4<f32>(lobe_weight, 0.0);
    probe_in[b + 5u] = vec4<f32>(split.diffuse, 0.0);
    probe_in[b + 6u] = vec4<f32>(split.specular, 0.0);
    probe_in[b + 7u] = vec4<f32>(split.sss, 0.0);
    probe_in[b + 8u] = vec4<f32>(split.coat, 0.0);
    probe_in[b + 9u] = vec4<f32>(split.sheen, 0.0);
    let k = atomicAdd(&counters[1], 1u);
    probe_in[queue_entry(k)] = vec4<f32>(bitcast<f32>(slot), 0.0, 0.0, 0.0);
}

// The parked job's walk and what the megakernel does after it (weight, split, roulette); false
// when the path ends there, else `start` continues it from the exit point.
fn job_resume(slot: u32, rng: ptr<function, Rng>, rays: ptr<function, u32>, start: ptr<function, PathStart>) -> bool {
    let b = job_base(slot);
    let j0 = probe_in[b];
    let j1 = probe_in[b + 1u];
    let j2 = probe_in[b + 2u];
    let j3 = probe_in[b + 3u];
    let ray = Ray(j0.xyz, vec3<f32>(j0.w, j1.x, j1.y), 0.0, 3.4e38);
    let hit = Hit(j1.z, bitcast<u32>(j1.w), bitcast<u32>(j2.x), j2.y, j2.z);
    let flags = bitcast<u32>(j2.w);
    *rng = Rng(bitcast<u32>(j3.w));
    let sp = shade_hit(ray, hit);
    let walk = random_walk(sp, hit.instance, to_local(sp.frame, -ray.dir), rng, rays);
    if (!walk.ok) {
        return false;
    }
    var throughput = j3.xyz * (probe_in[b + 4u].xyz * walk.weight);
    var split = Split(probe_in[b + 5u].xyz, probe_in[b + 6u].xyz, probe_in[b + 7u].xyz, probe_in[b + 8u].xyz, probe_in[b + 9u].xyz);
    if ((flags & JOB_SPLIT_SET) == 0u) {
        split = Split(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(1.0), vec3<f32>(0.0), vec3<f32>(0.0));
    }
    let depth = flags >> 8u;
    if (!roulette(&throughput, depth, rng)) {
        return false;
    }
    (*start).ray = Ray(walk.sp.p, -walk.sp.frame.n, 0.0, 3.4e38);
    (*start).throughput = throughput;
    (*start).depth = depth + 1u;
    (*start).exit = true;
    (*start).exit_sp = walk.sp;
    (*start).split = split;
    (*start).split_set = true;
    return true;
}

fn job_finish(slot: u32, radiance: vec3<f32>, ps: Passes) {
    let b = job_base(slot);
    probe_in[b] = vec4<f32>(radiance, 0.0);
    probe_in[b + 5u] = vec4<f32>(ps.diffuse, 0.0);
    probe_in[b + 6u] = vec4<f32>(ps.specular, 0.0);
    probe_in[b + 7u] = vec4<f32>(ps.sss, 0.0);
    probe_in[b + 8u] = vec4<f32>(ps.coat, 0.0);
    probe_in[b + 9u] = vec4<f32>(ps.sheen, 0.0);
    probe_in[b + 10u] = vec4<f32>(ps.direct, ps.unshadowed, 0.0, 0.0);
}

// STAGE_GATHER at pixel p: its finished jobs into the accumulators.
fn job_gather(p: u32) {
    let pixels = params.width * params.height;
    var sum = vec3<f32>(0.0);
    var passes = passes_zero();
    for (var i = 0u; i < pc.sample_count; i++) {
        let slot = i * pixels + p;
        if ((job_flags(slot) & JOB_ACTIVE) == 0u) {
            continue;
        }
        let b = job_base(slot);
        let l = probe_in[b].xyz;
        if (all(l == l) && max3(l) < 3.0e38) {
            sum += l;
            let d = probe_in[b + 10u];
            passes_add(&passes, Passes(probe_in[b + 5u].xyz, probe_in[b + 6u].xyz, probe_in[b + 7u].xyz,
                probe_in[b + 8u].xyz, probe_in[b + 9u].xyz, d.x, d.y));
        }
    }
    accumulate(p, sum, passes);
}
