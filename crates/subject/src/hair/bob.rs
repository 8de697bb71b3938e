//! The bob: grown long, then cut at one height.

use glam::Vec3;
use rayon::prelude::*;

use super::growth::{Grower, Steer, StrandPlan};
use super::polyline::{arc_to_height, resample};
use super::rng::Rng;
use super::STREAM_STRAND;

impl Grower<'_> {
    /// Grows every strand long, then cuts them all at one height (with a few mm of jitter)
    /// chosen so the mean centreline length is `mean_length`, and resamples them.
    pub(super) fn grow_bob(&self, plans: &[StrandPlan], mean_length: f32) -> Vec<(Vec<Vec3>, f32)> {
        const GROW_STEP: f32 = 0.012;
        const MIN_LEN: f32 = 0.015;
        let grow_len = (2.2 * mean_length).min(0.6);
        let steps = (grow_len / GROW_STEP).ceil() as usize;
        // Most of a long-grown strand is cut off; a subset tells roughly where the cut will be,
        // so the full set only grows a little past it.
        let stride = (plans.len() / 500).max(1);
        let subset: Vec<Vec<Vec3>> = plans
            .par_iter()
            .step_by(stride)
            .map(|p| self.grow_path(p, steps, GROW_STEP, |_, _| Steer::Comb))
            .collect();
        let rough_cut = cut_height(&subset, &vec![0.0; subset.len()], mean_length, MIN_LEN);
        let stop_below = rough_cut - 0.03;
        let long: Vec<Vec<Vec3>> = plans
            .par_iter()
            .map(|p| {
                self.grow_path(p, steps, GROW_STEP, |q, _| {
                    if q.y < stop_below {
                        Steer::Stop
                    } else {
                        Steer::Comb
                    }
                })
            })
            .collect();
        let jitter: Vec<f32> = (0..plans.len())
            .map(|i| {
                let mut rng = Rng::new(self.seed, STREAM_STRAND, (i as u64) | (1 << 40));
                rng.range(-0.004, 0.004)
            })
            .collect();
        let cut = cut_height(&long, &jitter, mean_length, MIN_LEN);
        long.par_iter()
            .zip(&jitter)
            .zip(plans)
            .map(|((pts, j), plan)| {
                let arc = arc_to_height(pts, cut + j).max(MIN_LEN);
                let segments = ((arc * self.curl.stretch() / self.style.segment).ceil() as usize)
                    .clamp(2, self.style.max_segments)
                    .min(plan.segments.max(2));
                (resample(pts, arc, segments), 0.0)
            })
            .collect()
    }
}

/// Height at which cutting every strand (each `jitter` higher) leaves a mean length of
/// `mean_length`, strands shorter than `min_len` kept at that length.
fn cut_height(lines: &[Vec<Vec3>], jitter: &[f32], mean_length: f32, min_len: f32) -> f32 {
    let mean_at = |y: f32| -> f32 {
        let sum: f64 = lines
            .iter()
            .zip(jitter)
            .map(|(pts, j)| arc_to_height(pts, y + j).max(min_len) as f64)
            .sum();
        (sum / lines.len().max(1) as f64) as f32
    };
    let (lowest, highest) = lines
        .iter()
        .flatten()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.y), hi.max(p.y))
        });
    if !(lowest.is_finite() && highest.is_finite()) {
        return 0.0;
    }
    let (mut lo, mut hi) = (lowest - 0.01, highest + 0.01);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if mean_at(mid) > mean_length {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}
