//! Integer-hashed value noise: the same texels on every machine (no transcendental functions).

/// A 32-bit avalanche hash of a lattice point and a seed (the "lowbias32" mixer).
pub fn hash3(x: i32, y: i32, seed: u64) -> u32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ (seed as u32)
        ^ ((seed >> 32) as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    h
}

/// Uniform in [0, 1) from a lattice point.
pub fn lattice(x: i32, y: i32, seed: u64) -> f32 {
    (hash3(x, y, seed) >> 8) as f32 / (1u32 << 24) as f32
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// Value noise in [0, 1) at (x, y) in lattice units.
pub fn value(x: f32, y: f32, seed: u64) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i32, fy as i32);
    let (tx, ty) = (smooth(x - fx), smooth(y - fy));
    let a = lattice(ix, iy, seed);
    let b = lattice(ix + 1, iy, seed);
    let c = lattice(ix, iy + 1, seed);
    let d = lattice(ix + 1, iy + 1, seed);
    let top = a + (b - a) * tx;
    let bottom = c + (d - c) * tx;
    top + (bottom - top) * ty
}

/// Three octaves of value noise, centred on 0, roughly in [-0.5, 0.5].
pub fn fbm(x: f32, y: f32, seed: u64) -> f32 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut f = 1.0;
    for o in 0..3u64 {
        sum += amp * (value(x * f, y * f, seed.wrapping_add(o * 0x9E37)) - 0.5);
        amp *= 0.5;
        f *= 2.03;
    }
    sum / 0.875
}
