//! [`PointGrid`]: nearest-point queries over the skin vertices and the clump guides.

use glam::Vec3;

/// Uniform grid over a subset of points for nearest-point queries. Each cell also knows how
/// many rings of cells around it are empty, so queries far from every point stay cheap.
pub(super) struct PointGrid {
    origin: Vec3,
    cell: f32,
    dims: [usize; 3],
    /// Prefix sums into `items`, one per cell plus one.
    starts: Vec<u32>,
    pub(super) items: Vec<u32>,
    /// The points of `items`, in the same (cell) order, so a query reads memory in sequence.
    item_points: Vec<Vec3>,
    /// Chebyshev distance, in cells, to the nearest non-empty cell (capped at 255).
    empty_rings: Vec<u8>,
}

impl PointGrid {
    /// Grid over `points[ids]` (all finite), padded by `pad` on every side.
    pub(super) fn new(points: &[Vec3], ids: &[u32], cell: f32, pad: f32) -> PointGrid {
        const MAX_DIM: f32 = 160.0;
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for &i in ids {
            lo = lo.min(points[i as usize]);
            hi = hi.max(points[i as usize]);
        }
        if ids.is_empty() {
            lo = Vec3::ZERO;
            hi = Vec3::ZERO;
        }
        let pad = if pad.is_finite() { pad } else { 0.0 };
        let lo = lo - Vec3::splat(pad);
        let extent = (hi + Vec3::splat(pad)) - lo;
        // Bounded memory for huge or degenerate inputs: the cell grows instead.
        let cell = cell.max(extent.max_element() / MAX_DIM).max(1e-6);
        let dims = [extent.x, extent.y, extent.z].map(|e| (e / cell).floor() as usize + 1);
        let n_cells = dims[0] * dims[1] * dims[2];
        let cell_of = |p: Vec3| -> usize {
            let c = ((p - lo) / cell).floor();
            let ix = (c.x.max(0.0) as usize).min(dims[0] - 1);
            let iy = (c.y.max(0.0) as usize).min(dims[1] - 1);
            let iz = (c.z.max(0.0) as usize).min(dims[2] - 1);
            (iz * dims[1] + iy) * dims[0] + ix
        };
        let mut counts = vec![0u32; n_cells + 1];
        for &i in ids {
            counts[cell_of(points[i as usize]) + 1] += 1;
        }
        for c in 0..n_cells {
            counts[c + 1] += counts[c];
        }
        let starts = counts.clone();
        let mut fill = counts;
        let mut items = vec![0u32; ids.len()];
        for &i in ids {
            let c = cell_of(points[i as usize]);
            items[fill[c] as usize] = i;
            fill[c] += 1;
        }
        // Multi-source breadth-first search over the 26-neighbourhood gives the Chebyshev
        // distance to the nearest occupied cell.
        let mut empty_rings = vec![u8::MAX; n_cells];
        let mut queue = std::collections::VecDeque::new();
        for c in 0..n_cells {
            if starts[c + 1] > starts[c] {
                empty_rings[c] = 0;
                queue.push_back(c);
            }
        }
        while let Some(c) = queue.pop_front() {
            let d = empty_rings[c];
            if d == u8::MAX - 1 {
                continue;
            }
            let (ix, iy, iz) = (
                c % dims[0],
                (c / dims[0]) % dims[1],
                c / (dims[0] * dims[1]),
            );
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (x, y, z) = (ix as i64 + dx, iy as i64 + dy, iz as i64 + dz);
                        if x < 0 || y < 0 || z < 0 {
                            continue;
                        }
                        let (x, y, z) = (x as usize, y as usize, z as usize);
                        if x >= dims[0] || y >= dims[1] || z >= dims[2] {
                            continue;
                        }
                        let nc = (z * dims[1] + y) * dims[0] + x;
                        if empty_rings[nc] > d + 1 {
                            empty_rings[nc] = d + 1;
                            queue.push_back(nc);
                        }
                    }
                }
            }
        }
        let item_points = items.iter().map(|&i| points[i as usize]).collect();
        PointGrid {
            origin: lo,
            cell,
            dims,
            starts,
            items,
            item_points,
            empty_rings,
        }
    }

    /// Nearest indexed point to `p` within `max_dist`, with its squared distance.
    pub(super) fn nearest(&self, p: Vec3, max_dist: f32) -> Option<(u32, f32)> {
        if self.items.is_empty() || !p.is_finite() {
            return None;
        }
        let c = (p - self.origin) / self.cell;
        let f = c - c.floor();
        let c = c.floor();
        let dims = self.dims.map(|d| d as i64);
        let (cx, cy, cz) = (c.x as i64, c.y as i64, c.z as i64);
        // Outside the grid: start from the nearest cell and skip the rings that are surely
        // empty or beyond `max_dist`.
        let clamp = |v: i64, d: i64| v.clamp(0, d - 1);
        let (qx, qy, qz) = (clamp(cx, dims[0]), clamp(cy, dims[1]), clamp(cz, dims[2]));
        let outside = (cx - qx).abs().max((cy - qy).abs()).max((cz - qz).abs());
        let q_cell = ((qz * dims[1] + qy) * dims[0] + qx) as usize;
        let first_ring = (self.empty_rings[q_cell] as i64).max(outside.saturating_sub(1));
        // Points in ring r are at least r - 1 cells plus p's distance to its own cell's
        // nearest face away.
        let inset = if outside == 0 {
            f.min(Vec3::ONE - f).min_element().max(0.0)
        } else {
            0.0
        };
        let mut best: Option<(u32, f32)> = None;
        let mut best_d2 = if max_dist.is_finite() {
            max_dist * max_dist
        } else {
            f32::INFINITY
        };
        let max_ring = dims[0].max(dims[1]).max(dims[2]) + outside + 1;
        let mut r = first_ring;
        while r <= max_ring {
            if r > 0 {
                let lower = ((r - 1) as f32 + inset) * self.cell;
                if lower * lower > best_d2 {
                    break;
                }
            }
            for dz in -r..=r {
                let z = cz + dz;
                if z < 0 || z >= dims[2] {
                    continue;
                }
                for dy in -r..=r {
                    let y = cy + dy;
                    if y < 0 || y >= dims[1] {
                        continue;
                    }
                    let on_face = dz.abs() == r || dy.abs() == r;
                    let step = if on_face { 1 } else { (2 * r).max(1) };
                    let mut dx = -r;
                    while dx <= r {
                        let x = cx + dx;
                        dx += step;
                        if x < 0 || x >= dims[0] {
                            continue;
                        }
                        let cell = ((z * dims[1] + y) * dims[0] + x) as usize;
                        let (a, b) = (self.starts[cell] as usize, self.starts[cell + 1] as usize);
                        if b == a || self.cell_distance_sq(p, x, y, z) > best_d2 {
                            continue;
                        }
                        for (k, q) in self.item_points[a..b].iter().enumerate() {
                            let d2 = q.distance_squared(p);
                            if d2 > best_d2 {
                                continue;
                            }
                            let i = self.items[a + k];
                            // Ties go to the lower index, whatever the scan order.
                            let better = match best {
                                None => true,
                                Some((bi, bd)) => d2 < bd || i < bi,
                            };
                            if better {
                                best = Some((i, d2));
                                best_d2 = d2;
                            }
                        }
                    }
                }
            }
            r += 1;
        }
        best
    }

    fn cell_distance_sq(&self, p: Vec3, x: i64, y: i64, z: i64) -> f32 {
        let lo = self.origin + Vec3::new(x as f32, y as f32, z as f32) * self.cell;
        let hi = lo + Vec3::splat(self.cell);
        let d = (lo - p).max(p - hi).max(Vec3::ZERO);
        d.length_squared()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hair::rng::Rng;

    /// The nearest point by brute force, ties to the lower index.
    fn brute(points: &[Vec3], ids: &[u32], p: Vec3, max_dist: f32) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        for &i in ids {
            let d2 = points[i as usize].distance_squared(p);
            if d2 > max_dist * max_dist {
                continue;
            }
            if best.is_none_or(|(bi, bd)| d2 < bd || (d2 == bd && i < bi)) {
                best = Some((i, d2));
            }
        }
        best
    }

    #[test]
    fn nearest_is_the_brute_force_answer_for_any_cell_size() {
        let mut rng = Rng::new(1, 2, 3);
        // A head-sized shell of points, some duplicated (exact ties).
        let mut points: Vec<Vec3> = (0..4000)
            .map(|_| {
                let z = rng.range(-1.0, 1.0);
                let phi = rng.range(0.0, std::f32::consts::TAU);
                let s = (1.0 - z * z).sqrt();
                Vec3::new(s * phi.cos(), z, s * phi.sin()) * 0.1
            })
            .collect();
        points.extend_from_within(..200);
        let ids: Vec<u32> = (0..points.len() as u32).filter(|i| i % 7 != 3).collect();
        let queries: Vec<Vec3> = (0..20_000)
            .map(|k| {
                let base = points[k % points.len()];
                let off = Vec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                );
                // Near the shell, a little off it, and far outside the grid.
                base + off * [0.002, 0.02, 0.3][k % 3]
            })
            .collect();
        let mut mismatches = Vec::new();
        for cell in [0.004, 0.008, 0.012, 0.016, 0.024] {
            let grid = PointGrid::new(&points, &ids, cell, 0.03);
            for (k, &q) in queries.iter().enumerate() {
                for max_dist in [0.03, f32::INFINITY] {
                    let got = grid.nearest(q, max_dist);
                    let want = brute(&points, &ids, q, max_dist);
                    if got != want {
                        mismatches.push((cell, k, max_dist, got, want));
                    }
                }
            }
        }
        assert!(
            mismatches.is_empty(),
            "{} mismatches, first {:?}",
            mismatches.len(),
            &mismatches[..mismatches.len().min(5)]
        );
    }
}
