//! Eyelashes: curved fibres along the lid margins of [`crate::eyelids`].

use glam::Vec3;
use rayon::prelude::*;

use crate::eyelids::EyeLids;
use crate::landmarks::HeadSurface;

use super::polyline::{cumulative_arc, point_at_fraction, smoothstep, taper};
use super::rng::Rng;
use super::scalp::{LocalSkin, Skin};
use super::strands::Strands;
use super::STREAM_LASH;

/// One lid's lashes. Counts are per eye and within the range anatomy reports (90–160 upper,
/// 75–80 lower lashes; the lower row is sparser and shorter here because its lashes are the
/// finest); lengths from the middle of the lid outwards, where lashes are longest.
struct LidLashes {
    count: usize,
    /// Part of the margin (by arc length, medial 0 → lateral 1) that carries lashes.
    span: (f32, f32),
    /// Length at the corners and the extra at the longest point, metres.
    base_length: f32,
    extra_length: f32,
    root_width: f32,
    /// +1 for the upper lid (its lashes curl up), −1 for the lower.
    up: f32,
    /// How far a lash leans away from the opening at its root and at its tip (relative to
    /// the forward axis): the lower lashes stay straighter so that they clear the lower lid.
    lean: (f32, f32),
}

const UPPER: LidLashes = LidLashes {
    count: 110,
    span: (0.06, 0.97),
    base_length: 0.0055,
    extra_length: 0.0045,
    root_width: 0.00012,
    up: 1.0,
    lean: (0.35, 1.0),
};
const LOWER: LidLashes = LidLashes {
    count: 50,
    span: (0.18, 0.95),
    base_length: 0.003,
    extra_length: 0.0025,
    root_width: 0.00008,
    up: -1.0,
    lean: (0.1, 0.6),
};
const SEGMENTS: usize = 6;
/// How far above the lid skin a lash starts and how close to it a lash may come, metres.
const ROOT_LIFT: f32 = 0.0002;
const CLEARANCE: f32 = 0.0001;

/// Grows the lashes of every eye in `lids` on the (posed) skin `surface`. Each lash leaves
/// the margin along the lid's outward normal, tipped away from the eye opening, and curls
/// away from it (up on the upper lid, down on the lower); at the outer corner lashes splay
/// outwards, at the inner corner slightly inwards. A lash that would cross the skin or come
/// within 0.1 mm of it ends there, and one that ends before half its length is left out. Returns an empty set (and logs why) when the skin is unusable.
pub fn grow_eyelashes(surface: &HeadSurface, lids: &[EyeLids], seed: u64) -> Strands {
    let mut out = Strands::new();
    if lids.is_empty() {
        return out;
    }
    let skin = match Skin::new(surface) {
        Ok(s) => s,
        Err(reason) => {
            tracing::warn!("no eyelashes grown: {reason}");
            return out;
        }
    };
    for (e, eye) in lids.iter().enumerate() {
        let all = eye.upper.iter().chain(&eye.lower);
        let opening = all.clone().sum::<Vec3>() / all.count().max(1) as f32;
        let lateral = Vec3::X * eye.side.signum();
        for (l, (margin, lid)) in [(&eye.upper, &UPPER), (&eye.lower, &LOWER)]
            .into_iter()
            .enumerate()
        {
            if margin.len() < 2 {
                continue;
            }
            let centre = margin.iter().sum::<Vec3>() / margin.len() as f32;
            let local = LocalSkin::new(surface, &skin, centre, 0.03);
            let total = cumulative_arc(margin).last().copied().unwrap_or(0.0);
            if total <= 0.0 {
                continue;
            }
            let place = Margin {
                skin: &local,
                points: margin,
                length: total,
                opening,
                lateral,
            };
            // Each lash has its own stream: grown on every core, collected in order.
            let lashes: Vec<(Vec<Vec3>, Vec<f32>)> = (0..lid.count)
                .into_par_iter()
                .filter_map(|i| {
                    let index = ((e * 2 + l) * 1000 + i) as u64;
                    let mut rng = Rng::new(seed, STREAM_LASH, index);
                    let pts = grow_lash(&place, lid, i, &mut rng)?;
                    let widths = taper(&pts, lid.root_width * rng.range(0.85, 1.15));
                    Some((pts, widths))
                })
                .collect();
            for (pts, widths) in &lashes {
                out.push(pts, widths);
            }
        }
    }
    out
}

/// One lid margin and what its lashes are placed against.
struct Margin<'a> {
    skin: &'a LocalSkin,
    /// Medial to lateral.
    points: &'a [Vec3],
    /// Arc length of `points`, metres.
    length: f32,
    /// Centre of the eye opening (the mean of both margins).
    opening: Vec3,
    /// The face's horizontal direction towards the outer corner.
    lateral: Vec3,
}

fn grow_lash(m: &Margin, lid: &LidLashes, i: usize, rng: &mut Rng) -> Option<Vec<Vec3>> {
    let Margin {
        skin: local,
        points: margin,
        length: total,
        opening,
        lateral,
    } = *m;
    // Stratified along the lid so the lashes are evenly spaced but not regular.
    let (a, b) = lid.span;
    let s = a + (b - a) * (i as f32 + rng.f32()) / lid.count as f32;
    let eps = 0.5 * STEP_ALONG / total;
    let on_margin = point_at_fraction(margin, s);
    let tangent = (point_at_fraction(margin, (s + eps).min(1.0))
        - point_at_fraction(margin, (s - eps).max(0.0)))
    .try_normalize()?;
    let (c, skin_normal) = local.closest(on_margin)?;
    // Lashes grow forwards, with the eye's axis (canonical +Z). At the margin the skin's own
    // normal is unreliable: the nearest triangle may be the lid's rim facing into the opening
    // or its inner side folding back into the socket, so it only tilts the axis a little.
    let n = (Vec3::Z + skin_normal * 0.3).normalize_or(Vec3::Z);
    // Away from the opening's centre, across the lid: up on the upper lid, outwards at the
    // corners. The bias up (upper lid) or down (lower) decides where the lids meet, as on a
    // closed eye. (The margin's own tangent is too jagged on the coarse meshes to build this
    // from.)
    let from_centre = c - opening + Vec3::Y * (0.003 * lid.up);
    let away = (from_centre - n * from_centre.dot(n)).try_normalize()?;
    let splay = 0.5 * smoothstep(0.55, 1.0, s) - 0.25 * (1.0 - smoothstep(0.0, 0.3, s));
    let curl = rng.range(0.8, 1.2);
    // Splay in the face's horizontal: at the corners the margin itself turns down.
    let sideways = lateral * splay + tangent * rng.range(-0.12, 0.12);
    let start = (n + away * lid.lean.0 + sideways * 0.5).normalize();
    let end = (n * 0.35 + away * (lid.lean.1 * curl) + sideways).normalize();
    let bump = (1.0 - ((s - 0.6) / 0.6).powi(2)).max(0.0);
    let length = (lid.base_length + lid.extra_length * bump) * rng.range(0.85, 1.15);

    let mut p = c + n * ROOT_LIFT;
    let mut pts = Vec::with_capacity(SEGMENTS + 1);
    pts.push(p);
    for j in 1..=SEGMENTS {
        let f = (j as f32 - 0.5) / SEGMENTS as f32;
        let d = start.lerp(end, f.powf(1.5)).normalize_or(start);
        let q = p + d * (length / SEGMENTS as f32);
        let (sc, sn) = local.closest(q)?;
        if (q - sc).dot(sn) < CLEARANCE || local.crossed_by(p, q) {
            break;
        }
        pts.push(q);
        p = q;
    }
    // A stub of a lash looks like dirt on the lid; keep lashes that reach half their length.
    (pts.len() > SEGMENTS / 2).then_some(pts)
}

/// Arc length used for the margin's tangent, metres.
const STEP_ALONG: f32 = 0.001;
