//! Clumping: guide strands and the pull of every other strand towards its guide.

use glam::Vec3;
use rayon::prelude::*;

use super::grid::PointGrid;
use super::polyline::{cumulative_arc, point_at_fraction, smoothstep};
use super::scalp::Root;
use super::{GUIDE_EVERY, MAX_CLUMP_PULL};

/// Index of each strand's guide: the nearest of the first `len / GUIDE_EVERY` roots (the roots
/// are in random order, so those are a random subset); guides are their own guide.
pub(super) fn assign_guides(roots: &[Root]) -> Vec<usize> {
    let n_guides = roots.len().div_ceil(GUIDE_EVERY).max(1).min(roots.len());
    if n_guides == 0 {
        return Vec::new();
    }
    let positions: Vec<Vec3> = roots.iter().map(|r| r.pos).collect();
    let ids: Vec<u32> = (0..n_guides as u32).collect();
    let grid = PointGrid::new(&positions, &ids, 0.01, 0.0);
    (0..roots.len())
        .into_par_iter()
        .map(|i| {
            if i < n_guides {
                i
            } else {
                grid.nearest(positions[i], f32::INFINITY)
                    .map_or(0, |(g, _)| g as usize)
            }
        })
        .collect()
}

/// Pulls each strand towards its guide at the same fraction of its length, increasingly from
/// root (free) to tip (`0.9 × clumping` of the way).
pub(super) fn clump(
    lines: &[(Vec<Vec3>, f32)],
    guides: &[usize],
    clumping: f32,
) -> Vec<(Vec<Vec3>, f32)> {
    lines
        .par_iter()
        .enumerate()
        .map(|(i, (pts, start))| {
            let g = guides.get(i).copied().unwrap_or(i);
            if g == i || pts.len() < 2 {
                return (pts.clone(), *start);
            }
            let guide = &lines[g].0;
            let arcs = cumulative_arc(pts);
            let total = arcs.last().copied().unwrap_or(0.0).max(1e-9);
            let out = pts
                .iter()
                .zip(&arcs)
                .map(|(p, a)| {
                    let t = a / total;
                    let w = 0.9 * clumping * smoothstep(0.0, 1.0, t);
                    // A capped pull cannot carry a point through the head or neck to a guide
                    // on the other side of it (the collision pass only sees skin within
                    // PROBE_RANGE).
                    *p + ((point_at_fraction(guide, t) - *p) * w).clamp_length_max(MAX_CLUMP_PULL)
                })
                .collect();
            (out, *start)
        })
        .collect()
}
