//! Fibre segments for the GPU: every segment of a [`Curves`] set is cut into [`BVH_PIECES`]
//! collinear pieces, each one BLAS primitive (obvhs builds over its bounding box), stored in
//! leaf order in `tri_pos` as [`SEGMENT_VEC4S`] vec4s ([`Segment::gpu_words`]).
//! `shaders/inc/traverse.wgsl` intersects them as round cones, mitred at the joints and capped by
//! spheres at the strand ends.

use std::time::{Duration, Instant};

use glam::{Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::BvhBuildParams;

use crate::scene::Curves;
use crate::RenderError;

/// vec4s per segment in `tri_pos` (SEGMENT_VEC4S in shaders/inc/traverse.wgsl).
pub const SEGMENT_VEC4S: usize = 3;

/// One fibre segment in object (= world) space: the round cone from (p0, r0) to (p1, r1), cut
/// at each end by the plane through the end point with normal `m0` / `m1` (pointing along the
/// strand). Inside a strand that plane bisects the bend (a mitre joint), so consecutive cones
/// meet without overlapping or leaving a gap and the strand is one closed tube; at a strand's
/// ends (`cap0` / `cap1`) the plane is square to the axis and a sphere of the end radius closes
/// the tube.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub p0: Vec3,
    pub r0: f32,
    pub p1: Vec3,
    pub r1: f32,
    pub m0: Vec3,
    pub m1: Vec3,
    pub cap0: bool,
    pub cap1: bool,
}

/// Pieces per segment in the BVH. A hair segment of the dataset's samples is 45-315 radii long
/// (10th-90th percentile) and mostly diagonal, so its box is mostly empty and rays near the
/// hair enter many boxes whose fibre they miss. Two collinear pieces form the same tube (the
/// cut between them is square to the axis, at the interpolated radius) in boxes of about half
/// the area: 20-40% fewer fibre tests per ray, long-hair samples 9-19% faster on lavapipe,
/// for twice the segment memory and BVH build time (BENCHMARKS.md, "Two pieces per segment in
/// the BVH"). Four pieces cut the tests further but not the time.
pub const BVH_PIECES: usize = 2;

/// A curve set with more segments than this keeps one piece per segment, so that its pieces stay
/// well inside the 128 MiB that lavapipe allows a buffer (750 000 × 2 × 48 bytes = 69 MiB).
pub const MAX_SPLIT_SEGMENTS: usize = 750_000;

/// Bends sharper than this (the angle between consecutive segments) are not mitred: both
/// segments end square with a sphere there, as at a strand end.
pub const MAX_MITRE_BEND_DEG: f32 = 120.0;

impl Segment {
    /// Bounds of the segment: the mitre cut at each end is an ellipse of semi-major axis
    /// r / cos(half the bend) around the end point, inside the sphere of that radius.
    pub fn aabb(&self) -> Aabb {
        let ax = (self.p1 - self.p0).normalize_or_zero();
        let reach = |r: f32, m: Vec3| Vec3::splat(r / m.dot(ax).abs().max(0.5));
        let (e0, e1) = (reach(self.r0, self.m0), reach(self.r1, self.m1));
        Aabb::new(
            Vec3A::from((self.p0 - e0).min(self.p1 - e1)),
            Vec3A::from((self.p0 + e0).max(self.p1 + e1)),
        )
    }

    /// The three vec4s the shader reads: (p0, ±r0), (p1, ±r1) with a negative radius marking a
    /// capped end, and (m0, m1 as 2 × 16-bit octahedral).
    pub fn gpu_words(&self) -> [[f32; 4]; 3] {
        let signed = |r: f32, cap: bool| if cap { -r } else { r };
        [
            [self.p0.x, self.p0.y, self.p0.z, signed(self.r0, self.cap0)],
            [self.p1.x, self.p1.y, self.p1.z, signed(self.r1, self.cap1)],
            [
                self.m0.x,
                self.m0.y,
                self.m0.z,
                f32::from_bits(oct_encode(self.m1)),
            ],
        ]
    }
}

/// Unit vector → octahedral coordinates in [-1, 1]², packed as WGSL's pack2x16snorm does.
pub fn oct_encode(n: Vec3) -> u32 {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    let (mut x, mut y) = (n.x / l1, n.y / l1);
    if n.z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * ox.signum();
        y = (1.0 - ox.abs()) * oy.signum();
    }
    let q = |v: f32| ((v.clamp(-1.0, 1.0) * 32767.0).round() as i16) as u16 as u32;
    q(x) | (q(y) << 16)
}

/// The inverse of [`oct_encode`] (WGSL's unpack2x16snorm and the octahedral unfold).
pub fn oct_decode(w: u32) -> Vec3 {
    let f = |b: u32| ((b as u16 as i16) as f32 / 32767.0).max(-1.0);
    let (x, y) = (f(w & 0xffff), f(w >> 16));
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    let x = x + if x >= 0.0 { -t } else { t };
    let y = y + if y >= 0.0 { -t } else { t };
    Vec3::new(x, y, z).normalize()
}

/// The BLAS of one curve set.
pub struct CurveBlas {
    /// Index into [`crate::scene::Scene::curves`].
    pub set: u32,
    pub bvh: CwBvh,
    /// The BVH's primitives in the set's order (strand by strand): the pieces of its segments
    /// ([`split_pieces`]); the CPU reference intersects these.
    pub segments: Vec<Segment>,
    /// For each piece: (strand, index of its segment's first point within the strand).
    pub segment_strand: Vec<(u32, u32)>,
    /// Segments of the set's strands, before the split into pieces.
    pub strand_segments: usize,
    pub node_offset: u32,
    /// First vec4 of this BLAS's segments in `tri_pos`.
    pub seg_offset: u32,
    /// Wall-clock time of the BVH build.
    pub build_time: Duration,
}

/// The segments of `c`, strand by strand, with their joints; zero-length segments (repeated
/// points) are dropped.
pub fn segments_of(c: &Curves) -> (Vec<Segment>, Vec<(u32, u32)>) {
    let mut segs = Vec::with_capacity(c.segment_count());
    let mut owner = Vec::with_capacity(c.segment_count());
    let cos_max = MAX_MITRE_BEND_DEG.to_radians().cos();
    for (s, w) in c.offsets.windows(2).enumerate() {
        let first = segs.len();
        for k in w[0] as usize..(w[1] as usize).saturating_sub(1) {
            let (p0, p1) = (Vec3::from(c.points[k]), Vec3::from(c.points[k + 1]));
            if p0 == p1 {
                continue;
            }
            let ax = (p1 - p0).normalize();
            segs.push(Segment {
                p0,
                r0: c.radii[k],
                p1,
                r1: c.radii[k + 1],
                m0: ax,
                m1: ax,
                cap0: true,
                cap1: true,
            });
            owner.push((s as u32, k as u32 - w[0]));
        }
        for i in first + 1..segs.len() {
            let a = (segs[i - 1].p1 - segs[i - 1].p0).normalize();
            let b = (segs[i].p1 - segs[i].p0).normalize();
            if a.dot(b) < cos_max {
                continue;
            }
            let m = (a + b).normalize();
            segs[i - 1].m1 = m;
            segs[i - 1].cap1 = false;
            segs[i].m0 = m;
            segs[i].cap0 = false;
        }
    }
    (segs, owner)
}

/// How far consecutive pieces of a segment reach past their cut, as a fraction of the segment.
/// Each piece's cut plane is tested with its own f32 arithmetic, so pieces that only met there
/// would leave a crack that a ray could slip through; overlapping by far more than the rounding
/// (0.2 µm on a 2 mm segment) closes it without adding surface: both pieces are the same cone.
pub const PIECE_OVERLAP: f32 = 1e-4;

/// Cuts every segment into `k` collinear pieces of equal length that form the same tube: on the
/// same cone (the radius interpolated along the axis), reaching [`PIECE_OVERLAP`] past each
/// cut, the cut planes square to the axis and uncapped; the first and last piece keep the
/// segment's end points, mitres and caps bit for bit. `owner` is repeated for each piece.
pub fn split_pieces(
    segments: &[Segment],
    owner: &[(u32, u32)],
    k: usize,
) -> (Vec<Segment>, Vec<(u32, u32)>) {
    let k = k.max(1);
    let mut pieces = Vec::with_capacity(segments.len() * k);
    let mut piece_owner = Vec::with_capacity(segments.len() * k);
    for (s, &own) in segments.iter().zip(owner) {
        let ax = (s.p1 - s.p0).normalize();
        // The point and radius at cut i, moved `reach` along the axis.
        let at = |i: usize, reach: f32| {
            if i == 0 {
                (s.p0, s.r0)
            } else if i == k {
                (s.p1, s.r1)
            } else {
                let f = i as f32 / k as f32 + reach;
                (s.p0.lerp(s.p1, f), s.r0 + (s.r1 - s.r0) * f)
            }
        };
        for i in 0..k {
            let ((p0, r0), (p1, r1)) = (at(i, -PIECE_OVERLAP), at(i + 1, PIECE_OVERLAP));
            pieces.push(Segment {
                p0,
                r0,
                p1,
                r1,
                m0: if i == 0 { s.m0 } else { ax },
                m1: if i + 1 == k { s.m1 } else { ax },
                cap0: i == 0 && s.cap0,
                cap1: i + 1 == k && s.cap1,
            });
            piece_owner.push(own);
        }
    }
    (pieces, piece_owner)
}

/// A curve set's segments as the pieces its BLAS is built over: [`BVH_PIECES`] a segment, or one
/// for a set of more than [`MAX_SPLIT_SEGMENTS`] segments.
pub fn bvh_pieces(segments: &[Segment], owner: &[(u32, u32)]) -> (Vec<Segment>, Vec<(u32, u32)>) {
    let k = if segments.len() > MAX_SPLIT_SEGMENTS {
        1
    } else {
        BVH_PIECES
    };
    split_pieces(segments, owner, k)
}

/// The curve BLAS build parameters: obvhs' medium build (PLOC and reinsertion), no pre-split
/// (pieces are already short), at most three pieces a leaf. Public so that the worker's
/// `hair_bvh_cost` example times the same build stage by stage.
pub fn build_params() -> BvhBuildParams {
    let mut p = BvhBuildParams::medium_build();
    p.pre_split = false;
    p.max_prims_per_leaf = 3;
    p
}

/// Builds the BLAS of curve set `set` and appends its nodes and segments; `Ok(None)` for a set
/// without segments.
pub(crate) fn pack_curve_set(
    set: u32,
    c: &Curves,
    nodes: &mut Vec<obvhs::cwbvh::node::CwBvhNode>,
    tri_pos: &mut Vec<[f32; 4]>,
) -> Result<Option<CurveBlas>, RenderError> {
    c.validate()
        .map_err(|reason| RenderError::InvalidScene(format!("curves '{}': {reason}", c.name)))?;
    let (whole, owner) = segments_of(c);
    if whole.is_empty() {
        return Ok(None);
    }
    let (segments, segment_strand) = bvh_pieces(&whole, &owner);
    let boxes: Vec<Aabb> = segments.iter().map(Segment::aabb).collect();
    let start = Instant::now();
    let bvh = build_cwbvh(&boxes, build_params(), &mut Duration::default());
    let build_time = start.elapsed();
    let node_offset = nodes.len() as u32;
    nodes.extend_from_slice(&bvh.nodes);
    let seg_offset = u32::try_from(tri_pos.len()).map_err(|_| {
        RenderError::InvalidScene(format!("curves '{}': the scene is too large", c.name))
    })?;
    tri_pos.reserve(SEGMENT_VEC4S * segments.len());
    for &prim in &bvh.primitive_indices {
        tri_pos.extend(segments[prim as usize].gpu_words());
    }
    Ok(Some(CurveBlas {
        set,
        bvh,
        segments,
        segment_strand,
        strand_segments: whole.len(),
        node_offset,
        seg_offset,
        build_time,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octahedral_round_trip_is_within_1e4() {
        for (i, n) in [
            Vec3::X,
            -Vec3::Y,
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.5, -0.8),
        ]
        .iter()
        .enumerate()
        {
            let n = n.normalize();
            let back = oct_decode(oct_encode(n));
            assert!(back.angle_between(n) < 1e-4, "{i}: {n} -> {back}");
        }
    }

    #[test]
    fn pieces_tile_their_segment() {
        let c = Curves {
            name: "t".into(),
            points: vec![[0.0, 0.0, 0.0], [0.3, -1.0, 0.2], [1.0, -2.0, 0.0]],
            radii: vec![0.1, 0.08, 0.05],
            offsets: vec![0, 3],
            material: 0,
        };
        let (whole, owner) = segments_of(&c);
        for k in [1, 2, 3] {
            let (p, own) = split_pieces(&whole, &owner, k);
            assert_eq!((p.len(), own.len()), (2 * k, 2 * k));
            for (s, seg) in whole.iter().enumerate() {
                let pc = &p[s * k..(s + 1) * k];
                assert!(own[s * k..(s + 1) * k].iter().all(|&o| o == owner[s]));
                // The ends are the segment's own, bit for bit, with its mitres and caps.
                assert_eq!(
                    (pc[0].p0, pc[0].r0, pc[0].m0, pc[0].cap0),
                    (seg.p0, seg.r0, seg.m0, seg.cap0)
                );
                let last = pc[k - 1];
                assert_eq!(
                    (last.p1, last.r1, last.m1, last.cap1),
                    (seg.p1, seg.r1, seg.m1, seg.cap1)
                );
                let ax = (seg.p1 - seg.p0).normalize();
                let len = (seg.p1 - seg.p0).length();
                let along = |p: Vec3| (p - seg.p0).dot(ax) / len;
                for (i, w) in pc.windows(2).enumerate() {
                    // Consecutive pieces overlap by PIECE_OVERLAP on each side of the cut, cut
                    // square there, uncapped.
                    let cut = (i + 1) as f32 / k as f32;
                    assert!((along(w[0].p1) - (cut + PIECE_OVERLAP)).abs() < 1e-6);
                    assert!((along(w[1].p0) - (cut - PIECE_OVERLAP)).abs() < 1e-6);
                    assert!(!w[0].cap1 && !w[1].cap0 && w[0].m1 == ax && w[1].m0 == ax);
                }
                for q in pc {
                    // On the axis, with the radius of the cone there.
                    for (p, r) in [(q.p0, q.r0), (q.p1, q.r1)] {
                        let f = along(p);
                        assert!((p - seg.p0.lerp(seg.p1, f)).length() < 1e-6);
                        assert!((r - (seg.r0 + (seg.r1 - seg.r0) * f)).abs() < 1e-6);
                    }
                }
            }
        }
    }

    #[test]
    fn joints_are_mitred_and_strand_ends_capped() {
        let c = Curves {
            name: "t".into(),
            points: vec![
                [0.0, 0.0, 0.0],
                [0.0, -1.0, 0.0],
                [1.0, -2.0, 0.0],
                [1.0, -2.0, 0.0],
                [1.0, -3.0, 0.0],
            ],
            radii: vec![0.1; 5],
            offsets: vec![0, 5],
            material: 0,
        };
        let (s, owner) = segments_of(&c);
        assert_eq!(s.len(), 3, "the repeated point is dropped");
        assert_eq!(owner, vec![(0, 0), (0, 1), (0, 3)]);
        assert!(s[0].cap0 && !s[0].cap1 && !s[1].cap0 && !s[1].cap1 && !s[2].cap0 && s[2].cap1);
        let bisector = (Vec3::NEG_Y + Vec3::new(1.0, -1.0, 0.0).normalize()).normalize();
        assert!(s[0].m1.abs_diff_eq(bisector, 1e-6) && s[1].m0 == s[0].m1);
    }
}
