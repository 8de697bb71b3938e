//! How the renderer orders its work: where subsurface walks run and whether the lightings of a
//! sample share their camera paths. Every choice renders the same image in expectation;
//! BENCHMARKS.md times them.

/// Where a subsurface random walk runs (shaders/inc/walk_queue.wgsl). Both give the same paths
/// from the same random streams; only the order of the work differs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WalkSchedule {
    /// In the path's own invocation, where it picks the subsurface lobe.
    #[default]
    Megakernel,
    /// Parked and queued by the path dispatch, run side by side by a dispatch of their own,
    /// then gathered per pixel (three dispatches per round of samples).
    Dispatch,
}

impl WalkSchedule {
    pub fn parse(name: &str) -> Option<WalkSchedule> {
        match name {
            "megakernel" => Some(WalkSchedule::Megakernel),
            "dispatch" => Some(WalkSchedule::Dispatch),
            _ => None,
        }
    }
}

/// How the lightings of one render are traced (shaders/kernels/integrator.wgsl).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightingSchedule {
    /// Each camera path serves every lighting: one NEE shadow ray per lighting at each vertex,
    /// each escaped ray weighted per lighting. The paths, passes and aux rays are traced once.
    #[default]
    Shared,
    /// One dispatch per lighting, each tracing its own paths (what the renderer did before
    /// shared paths; kept to measure them against and for the walk-dispatch schedule, whose
    /// job slots hold one lighting).
    Separate,
    /// Shared paths with one NEE shadow ray per vertex for all the lightings of a group: it aims
    /// at one lighting picked uniformly and is weighted for each by the mixture density
    /// (1/K) Σ p_k, which the escaped rays' MIS weights use too. Fewer shadow rays, more noise
    /// per lighting where the lightings' bright regions differ (BENCHMARKS.md measures both).
    Mixture,
}

impl LightingSchedule {
    pub fn parse(name: &str) -> Option<LightingSchedule> {
        match name {
            "shared" => Some(LightingSchedule::Shared),
            "separate" => Some(LightingSchedule::Separate),
            "mixture" => Some(LightingSchedule::Mixture),
            _ => None,
        }
    }
}
