//! [`grow_hair`]: roots on the scalp, per-strand plans and the step-by-step growth of a strand
//! over the scalp and into free space.

use glam::{Vec2, Vec3};
use lightfarm_scene::expand::HairSample;
use rayon::prelude::*;

use crate::landmarks::{HeadSurface, Landmarks};

use super::clump::{assign_guides, clump};
use super::curl::{add_curl, Curl};
use super::polyline::{any_perpendicular, smoothstep, taper};
use super::ponytail::Tail;
use super::rng::Rng;
use super::scalp::{sample_roots, HeadFrame, Probe, Root, Skin};
use super::strands::Strands;
use super::styles::{Kind, Style, HAIR_STYLES, STYLES};
use super::{
    CLEAR_TOLERANCE, DOWN, MARGIN, NEAR, STIFFNESS, STREAM_HEAD, STREAM_ROOTS, STREAM_STRAND,
};

/// Grows the strand hair of `hair` on the scalp of `surface`. `seed` picks the roots and every
/// per-strand variation; the same inputs give bit-identical strands on any machine.
///
/// Errors name the offending parameter: an unknown style (listing the known ones),
/// parameters outside their ranges, or a surface/landmark set that cannot carry hair.
pub fn grow_hair(
    surface: &HeadSurface,
    lm: &Landmarks,
    hair: &HairSample,
    seed: u64,
) -> Result<Strands, String> {
    let style = STYLES
        .iter()
        .find(|s| s.name == hair.style)
        .ok_or_else(|| {
            format!(
                "unknown hair style {:?}; known styles: {}",
                hair.style,
                HAIR_STYLES.join(", ")
            )
        })?;
    let check = |name: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(v as f32)
        } else {
            Err(format!(
                "hair.{name} = {v} is outside [{lo}, {hi}] (style {})",
                style.name
            ))
        }
    };
    let density = check("density", hair.density, 0.0, 1.0)?;
    let length = check("length_m", hair.length_m, 0.0, 1.0)?;
    let curl = check("curl", hair.curl, 0.0, 1.0)?;
    let clumping = check("clumping", hair.clumping, 0.0, 1.0)?;
    if length <= 0.0 {
        return Err(format!(
            "hair.length_m must be positive (style {})",
            style.name
        ));
    }
    let count = (density * style.strands as f32).round() as usize;
    if count == 0 {
        return Ok(Strands::new());
    }
    let frame = HeadFrame::new(lm)?;
    let skin = Skin::new(surface)?;
    let grower = Grower {
        skin: &skin,
        frame: &frame,
        style,
        curl: Curl::new(curl),
        clumping,
        seed,
    };
    let mut rng = Rng::new(seed, STREAM_ROOTS, 0);
    let roots = sample_roots(
        surface,
        &skin,
        count,
        &mut rng,
        |p| frame.in_scalp(p),
        |p, _| frame.in_scalp(p),
    );
    if roots.is_empty() {
        return Err(
            "no skin above the hairline: check that the landmarks belong to this head and that \
             the skin covers the scalp"
                .into(),
        );
    }
    Ok(grower.grow(&roots, length))
}

/// Everything one hair set's growth needs.
pub(super) struct Grower<'a> {
    pub(super) skin: &'a Skin,
    pub(super) frame: &'a HeadFrame,
    pub(super) style: &'a Style,
    pub(super) curl: Curl,
    pub(super) clumping: f32,
    pub(super) seed: u64,
}

/// Per-strand parameters drawn from the strand's own random stream.
#[derive(Clone, Copy, Debug)]
pub(super) struct StrandPlan {
    pub(super) root: Root,
    /// Target arc length of the centreline.
    pub(super) length: f32,
    pub(super) segments: usize,
    pub(super) lift: f32,
    pub(super) comb: Vec3,
    pub(super) width: f32,
    pub(super) amplitude: f32,
    pub(super) period: f32,
    pub(super) phase: f32,
    /// Ponytail: position in the tail's cross-section, unit disc.
    pub(super) slot: [f32; 2],
}

impl Grower<'_> {
    fn grow(&self, roots: &[Root], length: f32) -> Strands {
        let parting = self.parting();
        let stretch = self.curl.stretch();
        let mut plans: Vec<StrandPlan> = roots
            .iter()
            .enumerate()
            .map(|(i, root)| self.plan(i, *root, length, stretch, parting))
            .collect();
        let guides = assign_guides(roots);
        let tie = (self.style.kind == Kind::Ponytail).then(|| Tail::new(self.skin, self.frame));
        if let Some(tail) = &tie {
            // Hair keeps its side through the tie, so neighbours on the scalp stay neighbours
            // in the tail.
            for plan in plans.iter_mut() {
                plan.slot = tail.slot(plan.root.pos, Vec2::from(plan.slot).length());
            }
        }

        // Centrelines, and where each strand's curl starts.
        // Each strand is a pure function of its plan and the read-only skin, so growing them on
        // every core and collecting in index order gives the same strands for any thread count.
        let mut lines: Vec<(Vec<Vec3>, f32)> = match (self.style.kind, &tie) {
            (Kind::Buzz, _) => plans.par_iter().map(|p| (self.grow_buzz(p), 0.0)).collect(),
            (Kind::Ponytail, Some(tail)) => plans
                .par_iter()
                .enumerate()
                .map(|(i, p)| self.grow_ponytail(p, &plans[guides[i]], tail))
                .collect(),
            (Kind::Bob, _) => self.grow_bob(&plans, length / stretch),
            _ => plans.par_iter().map(|p| (self.grow_flow(p), 0.0)).collect(),
        };
        if matches!(self.style.kind, Kind::Flow | Kind::Bob) && self.clumping > 0.0 {
            lines = clump(&lines, &guides, self.clumping);
        }

        let settled: Vec<(Vec<Vec3>, Vec<f32>)> = lines
            .par_iter()
            .enumerate()
            .filter_map(|(i, (line, curl_start))| {
                let plan = &plans[i];
                let guide = &plans[guides[i]];
                let mut pts = if plan.amplitude > 0.0 && line.len() >= 2 {
                    // Clumped strands curl in step with their guide, as real curls do.
                    let phase = guide.phase + (plan.phase - guide.phase) * (1.0 - self.clumping);
                    add_curl(
                        line,
                        *curl_start,
                        plan.amplitude,
                        plan.period,
                        phase,
                        any_perpendicular(guide.root.normal),
                    )
                } else {
                    line.clone()
                };
                self.settle(&mut pts);
                (pts.len() >= 2).then(|| {
                    let widths = taper(&pts, plan.width);
                    (pts, widths)
                })
            })
            .collect();
        let mut out = Strands::new();
        for (pts, widths) in &settled {
            out.push(pts, widths);
        }
        out
    }

    /// Parting offset from the midline for parted styles: middle, or 2-3 cm to either side.
    fn parting(&self) -> f32 {
        let mut rng = Rng::new(self.seed, STREAM_HEAD, 0);
        let pick = rng.f32();
        let offset = 0.025 * self.frame.k * rng.range(0.8, 1.2);
        if pick < 0.4 {
            0.0
        } else if pick < 0.7 {
            offset
        } else {
            -offset
        }
    }

    fn plan(&self, i: usize, root: Root, length: f32, stretch: f32, parting: f32) -> StrandPlan {
        let style = self.style;
        let mut rng = Rng::new(self.seed, STREAM_STRAND, i as u64);
        let arc = length * (1.0 + style.length_jitter * rng.range(-1.0, 1.0));
        // Curly strands need about six segments per coil to read as coils.
        let segment = if self.curl.amplitude > 0.0 {
            style.segment.min(self.curl.period * stretch / 6.0)
        } else {
            style.segment
        };
        let segments = ((arc / segment).ceil() as usize).clamp(2, style.max_segments);
        let comb = self.comb(root, parting);
        let jitter = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let r = rng.f32().sqrt();
        let (s, c) = libm::sincos(rng.range(0.0, std::f32::consts::TAU) as f64);
        StrandPlan {
            root,
            length: arc / stretch,
            segments,
            lift: MARGIN + style.lift * rng.f32(),
            comb: (comb + jitter * 0.2).normalize_or(comb),
            width: style.root_width * rng.range(0.85, 1.15),
            amplitude: self.curl.amplitude * rng.range(0.85, 1.15),
            period: self.curl.period * rng.range(0.9, 1.1),
            phase: rng.range(0.0, std::f32::consts::TAU),
            slot: [r * c as f32, r * s as f32],
        }
    }

    /// Comb direction at a root (not yet made tangent to the scalp).
    fn comb(&self, root: Root, parting: f32) -> Vec3 {
        let f = self.frame;
        if self.style.parted {
            let side = if root.pos.x < f.mid_x + parting {
                -1.0
            } else {
                1.0
            };
            // The parting runs from the front hairline to the crown; behind it the hair falls
            // straight down. Front hair is swept back as well as sideways, around the face.
            let lateral = smoothstep(f.crown.z - 0.07 * f.k, f.crown.z - 0.01 * f.k, root.pos.z);
            let front = smoothstep(0.04, 0.09, root.pos.z - f.ear_mid_z);
            Vec3::new(side * lateral, -0.6, -(0.25 + 1.0 * front))
        } else {
            // Away from a point in front of the forehead below the hairline: up and back at
            // the front, back over the top, down at the back and the sides.
            let source = Vec3::new(f.mid_x, f.eye_y + 0.02 * f.k, f.eye_z + 0.1 * f.k);
            let front = smoothstep(0.03, 0.07, root.pos.z - f.ear_mid_z);
            let away = (root.pos - source).normalize_or(Vec3::NEG_Z);
            away + DOWN * (0.4 * (1.0 - front))
        }
    }

    fn grow_buzz(&self, plan: &StrandPlan) -> Vec<Vec3> {
        let n = plan.root.normal;
        let along = (plan.comb - n * plan.comb.dot(n)).normalize_or(any_perpendicular(n));
        let half = 0.5 * plan.length;
        let d1 = (n + along * 0.3).normalize_or(n);
        let d2 = (n + along * 0.6).normalize_or(n);
        let p1 = plan.root.pos + d1 * half;
        vec![plan.root.pos, p1, p1 + d2 * half]
    }

    /// Strand growth over the scalp and into free space (short, long, curly, and the bob
    /// before its cut).
    fn grow_flow(&self, plan: &StrandPlan) -> Vec<Vec3> {
        let ds = plan.length / plan.segments as f32;
        self.grow_path(plan, plan.segments, ds, |_, _| Steer::Comb)
    }

    /// Steps a strand from its root for at most `steps` segments of length `ds`; `steer(p, s)`
    /// picks the flow at arc length `s`.
    pub(super) fn grow_path(
        &self,
        plan: &StrandPlan,
        steps: usize,
        ds: f32,
        steer: impl Fn(Vec3, f32) -> Steer,
    ) -> Vec<Vec3> {
        let style = self.style;
        let mut pts = Vec::with_capacity(steps + 1);
        pts.push(plan.root.pos);
        let (mut p, mut d, mut s) = (plan.root.pos, plan.root.normal, 0.0f32);
        let mut probe = self.skin.probe(p);
        for _ in 0..steps {
            let layer = MARGIN + (plan.lift - MARGIN) * smoothstep(0.0, 0.03, s);
            let (mut flow, project) = match steer(p, s) {
                Steer::Stop => break,
                Steer::Towards(dir, project) => (dir, project),
                Steer::Comb => {
                    let gamma = style.gravity * smoothstep(0.0, 0.06, s);
                    let flow = (plan.comb * (1.0 - gamma) + DOWN * gamma).normalize_or(DOWN);
                    (flow, true)
                }
            };
            let mut up = plan.root.normal;
            if let Some((h, n)) = probe {
                up = n;
                let attached = h < layer + NEAR && (style.hug || n.y > -0.1);
                if attached && (project || flow.dot(n) < 0.0) {
                    let along = flow - n * flow.dot(n);
                    flow = along
                        .try_normalize()
                        .or_else(|| (d - n * d.dot(n)).try_normalize())
                        .unwrap_or(flow);
                    let lift = (0.5 * (layer - h) / ds).clamp(-0.3, 1.0);
                    flow = (flow + n * lift).normalize_or(flow);
                } else if h <= layer {
                    let into = flow.dot(n);
                    if into < 0.0 {
                        flow = (flow - n * into).normalize_or(n);
                    }
                }
            }
            let alpha = libm::exp((-s / style.rise) as f64) as f32;
            let target = (up * alpha + flow * (1.0 - alpha)).normalize_or(flow);
            d = (d * STIFFNESS + target * (1.0 - STIFFNESS)).normalize_or(target);
            let Some((q, q_probe)) = self.place(p, p + d * ds, ds) else {
                break;
            };
            d = (q - p).normalize_or(d);
            pts.push(q);
            p = q;
            probe = q_probe;
            s += ds;
        }
        pts
    }

    /// Moves a proposed next point out of the skin and the face while keeping it `ds` from
    /// `prev`; returns it with its skin probe, or `None` when no such spot is found.
    pub(super) fn place(&self, prev: Vec3, proposed: Vec3, ds: f32) -> Option<(Vec3, Probe)> {
        let mut q = proposed;
        for _ in 0..4 {
            let r = self.resolve(q);
            if r.clear && !r.moved {
                return Some((r.point, r.probe));
            }
            q = prev + (r.point - prev).try_normalize()? * ds;
        }
        None
    }

    /// Pushes `p` out of the skin (to [`MARGIN`], when it is more than [`CLEAR_TOLERANCE`]
    /// below it) and out of the face keep-out.
    fn resolve(&self, p: Vec3) -> Resolved {
        let mut q = p;
        let mut moved = false;
        for _ in 0..6 {
            let probe = self.skin.probe_vertex(q);
            let mut step = false;
            if let Some((h, n, open_edge)) = probe {
                if h < MARGIN - CLEAR_TOLERANCE {
                    if open_edge {
                        // Past the edge of the skin (a cut neck or arm) there is no telling
                        // where the body is; the strand ends here.
                        break;
                    }
                    q += n * (MARGIN - h);
                    step = true;
                }
            }
            if self.frame.in_face(q) {
                q = self.frame.out_of_face(q);
                step = true;
            }
            if !step {
                return Resolved {
                    point: q,
                    moved,
                    clear: true,
                    probe: probe.map(|(h, n, _)| (h, n)),
                };
            }
            moved = true;
        }
        Resolved {
            point: q,
            moved,
            clear: false,
            probe: None,
        }
    }

    /// Final collision pass after clumping and curl moved the points; the strand ends at the
    /// first point that cannot be placed.
    fn settle(&self, pts: &mut Vec<Vec3>) {
        for j in 1..pts.len() {
            let r = self.resolve(pts[j]);
            if !r.clear {
                pts.truncate(j);
                return;
            }
            pts[j] = r.point;
        }
    }
}

/// Outcome of [`Grower::resolve`].
struct Resolved {
    point: Vec3,
    /// The point had to be moved.
    moved: bool,
    /// The point is outside the skin and the face.
    clear: bool,
    /// Skin probe at `point` when `clear`.
    probe: Probe,
}

/// What drives a growth step.
#[derive(Clone, Copy, Debug)]
pub(super) enum Steer {
    /// The strand's comb direction blended with gravity, along the scalp.
    Comb,
    /// This direction; along the scalp when the flag is set.
    Towards(Vec3, bool),
    /// The strand ends here.
    Stop,
}
