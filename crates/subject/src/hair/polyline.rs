//! Polyline helpers: arc length, resampling, width taper, small vector utilities.

use glam::Vec3;

use super::TIP_WIDTH;

pub(super) fn cumulative_arc(pts: &[Vec3]) -> Vec<f32> {
    let mut acc = 0.0;
    let mut out = Vec::with_capacity(pts.len());
    for (j, p) in pts.iter().enumerate() {
        if j > 0 {
            acc += p.distance(pts[j - 1]);
        }
        out.push(acc);
    }
    out
}

/// Point at fraction `t` of a polyline's arc length.
pub(super) fn point_at_fraction(pts: &[Vec3], t: f32) -> Vec3 {
    let total: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
    point_at_arc(pts, t.clamp(0.0, 1.0) * total)
}

fn point_at_arc(pts: &[Vec3], arc: f32) -> Vec3 {
    let mut left = arc;
    for w in pts.windows(2) {
        let l = w[0].distance(w[1]);
        if left <= l {
            return if l > 0.0 {
                w[0].lerp(w[1], left / l)
            } else {
                w[0]
            };
        }
        left -= l;
    }
    pts.last().copied().unwrap_or(Vec3::ZERO)
}

/// The first `arc` metres of a polyline as `segments` equal pieces.
pub(super) fn resample(pts: &[Vec3], arc: f32, segments: usize) -> Vec<Vec3> {
    (0..=segments)
        .map(|j| point_at_arc(pts, arc * j as f32 / segments as f32))
        .collect()
}

/// Arc length at which a polyline first goes below height `y`: 0 when it starts below, its
/// whole length when it never does.
pub(super) fn arc_to_height(pts: &[Vec3], y: f32) -> f32 {
    let Some(first) = pts.first() else {
        return 0.0;
    };
    if first.y < y {
        return 0.0;
    }
    let mut arc = 0.0;
    for w in pts.windows(2) {
        let l = w[0].distance(w[1]);
        if w[1].y < y {
            let f = (w[0].y - y) / (w[0].y - w[1].y);
            return arc + l * f;
        }
        arc += l;
    }
    arc
}

/// Linear taper from `root_width` at the root to [`TIP_WIDTH`] of it at the tip, by arc length.
pub(super) fn taper(pts: &[Vec3], root_width: f32) -> Vec<f32> {
    let total: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
    let mut arc = 0.0;
    let mut out = Vec::with_capacity(pts.len());
    for (j, p) in pts.iter().enumerate() {
        if j > 0 {
            arc += p.distance(pts[j - 1]);
        }
        let t = if total > 0.0 {
            (arc / total).min(1.0)
        } else {
            0.0
        };
        out.push(root_width * (1.0 - (1.0 - TIP_WIDTH) * t));
    }
    out
}

pub(super) fn any_perpendicular(n: Vec3) -> Vec3 {
    let r = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    (r - n * r.dot(n)).normalize_or(Vec3::Z)
}

pub(super) fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}
