//! The ponytail: the tie behind the head, the tail's axis, and strands grown into it.

use glam::{Vec2, Vec3};

use super::growth::{Grower, Steer, StrandPlan};
use super::polyline::smoothstep;
use super::scalp::{HeadFrame, Skin};
use super::DOWN;

/// The ponytail: a tie point behind and above the ears, and the axis the tail hangs along.
pub(super) struct Tail {
    /// Axis points every [`Tail::STEP`] from the tie.
    axis: Vec<Vec3>,
    radius: f32,
}

impl Tail {
    const STEP: f32 = 0.002;
    const MAX_LEN: f32 = 1.2;

    pub(super) fn new(skin: &Skin, frame: &HeadFrame) -> Tail {
        let k = frame.k;
        let tie_y = frame.ear_y + 0.035 * k;
        // The hindmost skin on the midline at tie height; the tie sits on the hair there.
        let back = skin
            .grid
            .items
            .iter()
            .map(|&i| (skin.positions[i as usize], skin.normals[i as usize]))
            .filter(|(p, _)| (p.x - frame.mid_x).abs() < 0.012 && (p.y - tie_y).abs() < 0.012)
            .min_by(|a, b| a.0.z.total_cmp(&b.0.z));
        let tie = match back {
            Some((p, n)) => p + (n * 0.6 + Vec3::NEG_Z * 0.4).normalize_or(Vec3::NEG_Z) * 0.014 * k,
            None => Vec3::new(frame.mid_x, tie_y, frame.crown.z - 0.1 * k),
        };
        let steps = (Self::MAX_LEN / Self::STEP) as usize;
        let mut axis = Vec::with_capacity(steps + 1);
        let mut p = tie;
        let mut d = Vec3::new(0.0, -0.45, -0.55).normalize_or(DOWN);
        axis.push(p);
        for _ in 0..steps {
            // Bends from back-and-down to straight down over the first ~8 cm.
            d = (d + DOWN * 0.05).normalize_or(DOWN);
            p += d * Self::STEP;
            axis.push(p);
        }
        Tail {
            axis,
            radius: 0.009 * k,
        }
    }

    /// Place in the tie's cross-section (unit disc) at radius `r` for a strand rooted at
    /// `root`: on the side of the tie the root lies.
    pub(super) fn slot(&self, root: Vec3, r: f32) -> [f32; 2] {
        let (b1, b2) = self.frame(0);
        let to_root = root - self.axis[0];
        let dir = Vec2::new(to_root.dot(b1), to_root.dot(b2)).normalize_or(Vec2::X);
        (dir * r).to_array()
    }

    /// Cross-section axes at axis sample `i`.
    fn frame(&self, i: usize) -> (Vec3, Vec3) {
        let i = i.min(self.axis.len() - 2);
        let tangent = (self.axis[i + 1] - self.axis[i]).normalize_or(DOWN);
        let b1 = Vec3::X;
        (b1, tangent.cross(b1).normalize_or(Vec3::Z))
    }

    /// Point at `sigma` along the tail for a strand at `slot` of the cross-section, pulled
    /// towards its guide's slot by `clumping` as `t` (0 at the tie, 1 at the tip) grows.
    pub(super) fn point(
        &self,
        sigma: f32,
        slot: [f32; 2],
        guide: [f32; 2],
        t: f32,
        clumping: f32,
    ) -> Vec3 {
        let x = (sigma / Self::STEP).max(0.0);
        let i = (x.floor() as usize).min(self.axis.len() - 2);
        let f = (x - i as f32).min(1.0);
        let c = self.axis[i].lerp(self.axis[i + 1], f);
        let (b1, b2) = self.frame(i);
        let pull = clumping * 0.9 * smoothstep(0.0, 1.0, t);
        let sx = slot[0] + (guide[0] - slot[0]) * pull;
        let sy = slot[1] + (guide[1] - slot[1]) * pull;
        let r = self.radius * (1.0 + 1.2 * smoothstep(0.0, 0.12, sigma));
        c + (b1 * sx + b2 * sy) * r
    }
}

impl Grower<'_> {
    /// A ponytail strand: over the scalp to its place in the tie, then down the tail.
    /// Returns the points and the arc length at the tie, where the tail (and its curl) starts.
    pub(super) fn grow_ponytail(
        &self,
        plan: &StrandPlan,
        guide: &StrandPlan,
        tail: &Tail,
    ) -> (Vec<Vec3>, f32) {
        let ds = plan.length / plan.segments as f32;
        let target = tail.point(0.0, plan.slot, guide.slot, 0.0, self.clumping);
        let mut pts = self.grow_path(plan, plan.segments, ds, |p, s| {
            let to = target - p;
            let dist = to.length();
            if dist <= ds || s > 0.85 * plan.length {
                Steer::Stop
            } else {
                // Along the scalp towards the tie; within 3 cm, straight at it (it stands off
                // the skin by the tie's thickness).
                Steer::Towards(to / dist, dist >= 0.03)
            }
        });
        let head_arc: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
        let Some(&last) = pts.last() else {
            return (pts, 0.0);
        };
        if last.distance(target) > 2.0 * ds {
            // Never reached the tie: the strand ends on the scalp, shortened.
            return (pts, head_arc);
        }
        let remaining = plan.length - head_arc;
        let steps = (remaining / ds).floor() as usize;
        let tail_len = remaining.max(ds);
        let mut prev = last;
        for j in 1..=steps {
            let sigma = j as f32 * ds;
            let q = tail.point(
                sigma,
                plan.slot,
                guide.slot,
                sigma / tail_len,
                self.clumping,
            );
            let step = q.distance(prev).max(0.25 * ds);
            let Some((q, _)) = self.place(prev, q, step) else {
                break;
            };
            pts.push(q);
            prev = q;
        }
        (pts, head_arc)
    }
}
