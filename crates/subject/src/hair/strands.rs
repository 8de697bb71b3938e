//! [`Strands`]: the polylines with per-vertex width that hair and eyebrows are grown into.

use glam::Vec3;

/// Polylines with per-vertex width; strand i owns `points[offsets[i]..offsets[i+1]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Strands {
    pub points: Vec<Vec3>,
    /// Full fibre (ribbon) width at each point, metres.
    pub widths: Vec<f32>,
    /// `strand_count() + 1` entries, from 0 to `points.len()`.
    pub offsets: Vec<u32>,
}

impl Default for Strands {
    fn default() -> Self {
        Strands {
            points: Vec::new(),
            widths: Vec::new(),
            offsets: vec![0],
        }
    }
}

impl Strands {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    pub fn strand_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Points and widths of strand `i`; empty slices when `i` is out of range or the offsets
    /// are malformed (see [`Strands::validate`]).
    pub fn strand(&self, i: usize) -> (&[Vec3], &[f32]) {
        let (Some(&a), Some(&b)) = (self.offsets.get(i), self.offsets.get(i + 1)) else {
            return (&[], &[]);
        };
        let range = a as usize..b as usize;
        match (self.points.get(range.clone()), self.widths.get(range)) {
            (Some(p), Some(w)) => (p, w),
            _ => (&[], &[]),
        }
    }

    /// Number of polyline segments over all strands.
    pub fn segment_count(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1].saturating_sub(w[0]) as usize).saturating_sub(1))
            .sum()
    }

    /// Checks the invariants: offsets start at 0, never decrease and end at `points.len()`,
    /// every strand has at least 2 points, widths match the points, all points are finite and
    /// all widths finite and positive.
    pub fn validate(&self) -> Result<(), String> {
        if self.offsets.first() != Some(&0) {
            return Err(format!(
                "offsets must start with 0 (got {:?})",
                self.offsets.first()
            ));
        }
        if self.widths.len() != self.points.len() {
            return Err(format!(
                "{} widths for {} points; there must be one width per point",
                self.widths.len(),
                self.points.len()
            ));
        }
        for (i, w) in self.offsets.windows(2).enumerate() {
            if w[1] < w[0] {
                return Err(format!(
                    "offsets decrease at strand {i}: {} then {}",
                    w[0], w[1]
                ));
            }
            if w[1] - w[0] < 2 {
                return Err(format!(
                    "strand {i} has {} point(s); every strand needs at least 2",
                    w[1] - w[0]
                ));
            }
        }
        let last = self.offsets.last().copied().unwrap_or(0) as usize;
        if last != self.points.len() {
            return Err(format!(
                "the last offset is {last} but there are {} points",
                self.points.len()
            ));
        }
        if let Some(i) = self.points.iter().position(|p| !p.is_finite()) {
            return Err(format!("point {i} is not finite: {}", self.points[i]));
        }
        if let Some(i) = self
            .widths
            .iter()
            .position(|w| !(w.is_finite() && *w > 0.0))
        {
            return Err(format!(
                "width {i} is {}; widths must be finite and positive",
                self.widths[i]
            ));
        }
        Ok(())
    }

    /// Appends all strands of `other` (hair + eyebrows into one set).
    pub fn extend(&mut self, other: &Strands) {
        if self.offsets.is_empty() {
            self.offsets.push(self.points.len() as u32);
        }
        let base = self.points.len() as u32;
        let first = other.offsets.first().copied().unwrap_or(0);
        self.points.extend_from_slice(&other.points);
        self.widths.extend_from_slice(&other.widths);
        self.offsets.extend(
            other
                .offsets
                .iter()
                .skip(1)
                .map(|&o| base + o.saturating_sub(first)),
        );
    }

    pub(super) fn push(&mut self, points: &[Vec3], widths: &[f32]) {
        self.points.extend_from_slice(points);
        self.widths.extend_from_slice(widths);
        self.offsets.push(self.points.len() as u32);
    }
}
