//! Curl: the helix wound around a grown centreline.

use glam::Vec3;

use super::polyline::{any_perpendicular, cumulative_arc, smoothstep};
use super::DOWN;

/// Curl parameters from `HairSample::curl`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Curl {
    /// Helix radius, metres.
    pub(super) amplitude: f32,
    /// Helix pitch along the centreline, metres.
    pub(super) period: f32,
}

impl Curl {
    pub(super) fn new(curl: f32) -> Curl {
        Curl {
            amplitude: 0.008 * curl,
            period: 0.09 - 0.07 * curl,
        }
    }

    /// Arc length of the helix per unit centreline length.
    pub(super) fn stretch(&self) -> f32 {
        let r = std::f32::consts::TAU * self.amplitude / self.period;
        (1.0 + r * r).sqrt()
    }
}

/// Helix around a centreline: radius `amplitude` ramping in over 1.5 cm after arc length
/// `start`, one turn per `period` of centreline. The frame is parallel-transported from
/// `reference` so neighbouring strands with the same reference curl alike.
pub(super) fn add_curl(
    line: &[Vec3],
    start: f32,
    amplitude: f32,
    period: f32,
    phase: f32,
    reference: Vec3,
) -> Vec<Vec3> {
    let n = line.len();
    let arcs = cumulative_arc(line);
    let tangent =
        |j: usize| (line[(j + 1).min(n - 1)] - line[j.saturating_sub(1)]).normalize_or(DOWN);
    let t0 = tangent(0);
    let mut b1 = (reference - t0 * reference.dot(t0))
        .try_normalize()
        .unwrap_or_else(|| any_perpendicular(t0));
    let mut out = Vec::with_capacity(n);
    for j in 0..n {
        let t = tangent(j);
        b1 = (b1 - t * b1.dot(t))
            .try_normalize()
            .unwrap_or_else(|| any_perpendicular(t));
        let b2 = t.cross(b1);
        let s = arcs[j];
        let a = amplitude * smoothstep(start, start + 0.015, s);
        let theta = phase as f64 + std::f64::consts::TAU * ((s - start).max(0.0) / period) as f64;
        let (sin, cos) = libm::sincos(theta);
        out.push(line[j] + (b1 * cos as f32 + b2 * sin as f32) * a);
    }
    out
}
