//! Test scenes of fibres: wavy strands with tapering radii, and the hair material.
#![allow(dead_code)]

use glam::Vec3;
use lightfarm_render::scene::{Curves, Material, MaterialModel};

/// xorshift: reproducible without another dependency.
pub struct Rand(pub u64);

impl Rand {
    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn dir(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.next(), self.next(), self.next()) * 2.0 - Vec3::ONE;
            let l = v.length();
            if l > 0.05 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

/// `n` strands of `points` points hanging down (-Y) from roots spread over a `width`-wide
/// square in the XZ plane at y = 0, wavy, `length` long, radius `r_root` tapering to 40%.
pub fn hanging_strands(
    n: usize,
    points: usize,
    width: f32,
    length: f32,
    r_root: f32,
    seed: u64,
) -> Curves {
    let mut rng = Rand(seed | 1);
    let mut c = Curves {
        name: "test strands".into(),
        offsets: vec![0],
        ..Default::default()
    };
    for _ in 0..n {
        let root = Vec3::new((rng.next() - 0.5) * width, 0.0, (rng.next() - 0.5) * width);
        let phase = rng.next() * std::f32::consts::TAU;
        let amp = 0.002 + 0.004 * rng.next();
        let turns = 1.0 + 2.0 * rng.next();
        for k in 0..points {
            let s = k as f32 / (points - 1) as f32;
            let a = phase + s * turns * std::f32::consts::TAU;
            let p = root + Vec3::new(amp * a.cos(), -s * length, amp * a.sin());
            c.points.push(p.to_array());
            c.radii.push(r_root * (1.0 - 0.6 * s));
        }
        c.offsets.push(c.points.len() as u32);
    }
    c
}

pub fn hair_material(melanin: f32, redness: f32) -> Material {
    let mut m = Material {
        name: "hair".into(),
        melanin,
        melanin_redness: redness,
        ..Default::default()
    };
    m.apply_model(MaterialModel::Hair);
    m
}
