//! Eyebrows: short fine strands lying on the brow ridges.

use glam::Vec3;
use rayon::prelude::*;

use crate::landmarks::{HeadSurface, Landmarks};

use super::polyline::{smoothstep, taper};
use super::rng::{mix, Rng};
use super::scalp::{sample_roots, HeadFrame, LocalSkin, Root, Skin};
use super::strands::Strands;
use super::{STREAM_BROW_ROOTS, STREAM_BROW_STRAND};

/// Grows both eyebrows: ~320 short fine strands per brow on the brow ridge, lying almost flat
/// on the skin and pointing away from the midline and slightly up. Returns an empty set (and
/// logs why) when the surface or landmarks are unusable.
///
/// The brow band was measured on the MakeHuman and ICT heads, whose brow ridge (the most
/// forward skin above the eye) lies 1.6-2.4 cm above the eyeball centre: per side, from 1.6 cm
/// inside to 2.4 cm outside the eye centre (scaled by the eye distance / 5.9 cm), with its
/// lower edge 1.2 cm above the eye centre at the inner end, 1.8 cm under the arch (60 % of the
/// way out) and 1.4 cm at the tail, and 1.1 cm thick at the inner end thinning to 4 mm.
pub fn grow_eyebrows(surface: &HeadSurface, lm: &Landmarks, seed: u64) -> Strands {
    match grow_eyebrows_checked(surface, lm, seed) {
        Ok(s) => s,
        Err(reason) => {
            tracing::warn!("no eyebrows grown: {reason}");
            Strands::new()
        }
    }
}

/// Per-brow strand count.
const BROW_STRANDS: usize = 320;
const BROW_ROOT_WIDTH: f32 = 0.00018;

/// Shape of one brow in (u, v): u runs 0 (inner end) .. 1 (tail), v is the height above the
/// eye centre; see [`grow_eyebrows`].
#[derive(Clone, Copy)]
struct Brow {
    eye: Vec3,
    /// +1 for the subject's left brow (+X), -1 for the right.
    side: f32,
    mid_x: f32,
    scale: f32,
}

impl Brow {
    const INNER: f32 = 0.016;
    const SPAN: f32 = 0.040;

    fn u(&self, p: Vec3) -> f32 {
        (self.side * (p.x - self.eye.x) + Self::INNER * self.scale) / (Self::SPAN * self.scale)
    }

    fn arch(u: f32) -> f32 {
        if u < 0.6 {
            smoothstep(0.0, 0.6, u)
        } else {
            1.0 - 0.7 * smoothstep(0.6, 1.0, u)
        }
    }

    /// (lower, upper) height of the band above the eye centre at `u`.
    fn band(&self, u: f32) -> (f32, f32) {
        let lower = self.scale * (0.012 + 0.006 * Self::arch(u));
        let thick = self.scale * (0.011 - 0.007 * smoothstep(0.3, 1.0, u));
        (lower, lower + thick)
    }

    fn contains(&self, p: Vec3) -> bool {
        let u = self.u(p);
        if !(0.0..=1.0).contains(&u) || (p.x - self.mid_x) * self.side <= 0.0 {
            return false;
        }
        let (lo, hi) = self.band(u);
        let v = p.y - self.eye.y;
        v >= lo && v <= hi && p.z > self.eye.z - 0.02
    }

    /// Direction of a hair in the face plane at `u`: up at the inner end, outwards along the
    /// brow, slightly down at the tail.
    fn direction(&self, u: f32) -> Vec3 {
        let angle_deg = if u < 0.3 {
            70.0 - 50.0 * (u / 0.3)
        } else {
            20.0 - 35.0 * ((u - 0.3) / 0.7)
        };
        let (s, c) = libm::sincos((angle_deg as f64).to_radians());
        Vec3::new(self.side * c as f32, s as f32, 0.0)
    }
}

fn grow_eyebrows_checked(
    surface: &HeadSurface,
    lm: &Landmarks,
    seed: u64,
) -> Result<Strands, String> {
    let frame = HeadFrame::new(lm)?;
    let skin = Skin::new(surface)?;
    let scale = (lm.eye_distance() / 0.059).clamp(0.85, 1.15);
    let mut out = Strands::new();
    for (b, (eye, side)) in [(lm.eye_left, 1.0f32), (lm.eye_right, -1.0)]
        .into_iter()
        .enumerate()
    {
        let brow = Brow {
            eye,
            side,
            mid_x: frame.mid_x,
            scale,
        };
        let mut rng = Rng::new(seed, STREAM_BROW_ROOTS, b as u64);
        let roots = sample_roots(
            surface,
            &skin,
            BROW_STRANDS,
            &mut rng,
            |p| brow.contains(p),
            |p, n| {
                // Fewer hairs towards the tail; only skin that faces forwards (the brow ridge,
                // not the underside of the orbit rim).
                let keep = 1.0 - 0.6 * smoothstep(0.6, 1.0, brow.u(p));
                brow.contains(p) && n.z > 0.2 && rng_keep(p, keep)
            },
        );
        let centre = eye + Vec3::new(side * 0.004, 0.019, 0.0) * scale;
        let local = LocalSkin::new(surface, &skin, centre, 0.045 * scale);
        // Each hair has its own stream: grown on every core, collected in order.
        let hairs: Vec<(Vec<Vec3>, Vec<f32>)> = roots
            .par_iter()
            .enumerate()
            .filter_map(|(i, root)| {
                let mut rng = Rng::new(seed, STREAM_BROW_STRAND, (b * BROW_STRANDS + i) as u64);
                let pts = grow_brow_hair(&local, &brow, root, &mut rng)?;
                let w = BROW_ROOT_WIDTH * rng.range(0.85, 1.15);
                let widths = taper(&pts, w);
                Some((pts, widths))
            })
            .collect();
        for (pts, widths) in &hairs {
            out.push(pts, widths);
        }
    }
    Ok(out)
}

/// Deterministic thinning keyed by position, so the root sampler's stream stays independent of
/// how many candidates are thinned out.
fn rng_keep(p: Vec3, keep: f32) -> bool {
    let h =
        mix(p.x.to_bits() as u64 ^ ((p.y.to_bits() as u64) << 21) ^ ((p.z.to_bits() as u64) << 42));
    ((h >> 40) as f32 / 16_777_216.0) < keep
}

fn grow_brow_hair(local: &LocalSkin, brow: &Brow, root: &Root, rng: &mut Rng) -> Option<Vec<Vec3>> {
    const SEGMENTS: usize = 3;
    // A brow hair leaves the skin at a shallow angle and then lies on it.
    let height = |j: usize| 0.00035 + 0.00035 * (j as f32 / SEGMENTS as f32);
    let onto_skin = |p: Vec3, h: f32| local.closest(p).map(|(c, n)| (c + n * h, n));
    let u = brow.u(root.pos).clamp(0.0, 1.0);
    // Shorter hairs at the inner end and the tail, the longest over the arch.
    let len = brow.scale * (0.006 + 0.004 * (1.0 - (2.0 * u - 1.0).abs())) * rng.range(0.85, 1.2);
    let jitter = Vec3::new(0.0, rng.range(-0.2, 0.2), 0.0);
    let dir = (brow.direction(u) + jitter).normalize_or(Vec3::new(brow.side, 0.0, 0.0));
    let ds = len / SEGMENTS as f32;
    let (mut p, mut n) = onto_skin(root.pos, height(0))?;
    let mut pts = Vec::with_capacity(SEGMENTS + 1);
    pts.push(p);
    for j in 1..=SEGMENTS {
        // Outwards means around the head where the brow turns to the side, so the direction
        // is built from the surface's own horizontal and vertical tangents.
        let mut around = Vec3::Y.cross(n).normalize_or(Vec3::X);
        if around.dot(Vec3::new(brow.side, 0.0, -0.5)) < 0.0 {
            around = -around;
        }
        let up = (Vec3::Y - n * n.y).normalize_or(Vec3::Y);
        let along = (around * dir.x.abs() + up * dir.y).normalize_or(around);
        let mut q = p + along * ds;
        for _ in 0..2 {
            (q, n) = onto_skin(q, height(j))?;
        }
        if (q.x - brow.mid_x) * brow.side <= 0.0 {
            break;
        }
        pts.push(q);
        p = q;
    }
    (pts.len() >= 2).then_some(pts)
}
