// Counter-based random numbers: every (pixel, sample, dimension) has its own stream, so a render
// is a pure function of the seed whatever the dispatch chunking, and the lightings of one pair
// reuse the same camera samples (correlated noise, which the trainer prefers to independent noise).

fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

struct Rng {
    state: u32,
};

fn rng_init(pixel: u32, sample: u32, seed: u32) -> Rng {
    return Rng(pcg_hash(pixel ^ pcg_hash(sample ^ pcg_hash(seed))));
}

fn rng_next_u32(rng: ptr<function, Rng>) -> u32 {
    (*rng).state = (*rng).state * 747796405u + 2891336453u;
    let s = (*rng).state;
    let word = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rng_next(rng: ptr<function, Rng>) -> f32 {
    // 24 high bits -> [0, 1) exactly representable
    return f32(rng_next_u32(rng) >> 8u) * (1.0 / 16777216.0);
}

// floor(r * n / 2^32) without 64-bit integers: an index uniform in [0, n) for any n, where
// floor(u * n) with a 24-bit float u would leave cells unreachable past 2^24 and quantise.
fn uniform_index(r: u32, n: u32) -> u32 {
    let rl = r & 0xffffu;
    let rh = r >> 16u;
    let nl = n & 0xffffu;
    let nh = n >> 16u;
    let lo_lo = rl * nl;
    let hi_lo = rh * nl;
    let lo_hi = rl * nh;
    let mid = (lo_lo >> 16u) + (hi_lo & 0xffffu) + (lo_hi & 0xffffu);
    return rh * nh + (hi_lo >> 16u) + (lo_hi >> 16u) + (mid >> 16u);
}

fn rng_next2(rng: ptr<function, Rng>) -> vec2<f32> {
    let a = rng_next(rng);
    let b = rng_next(rng);
    return vec2<f32>(a, b);
}
