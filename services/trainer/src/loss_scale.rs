//! The dynamic loss scale of f16 training (what PyTorch's `GradScaler` does, with its defaults).
//!
//! f16 cannot hold magnitudes below ~6e-8, and a UNet's gradients at 512² are often smaller:
//! they would flush to zero in the backward pass. The loss is therefore multiplied by a large
//! scale before the backward pass and the f32 gradients divided by it after. Too large a
//! scale overflows instead; such a step is skipped and the scale halved. After
//! [`GROWTH_INTERVAL`] steps without overflow it doubles again, so it tracks the largest scale
//! the gradients allow. bf16 has f32's exponent range and f32 needs nothing: their scale stays 1.

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;
use lightfarm_nets::Precision;
use serde::{Deserialize, Serialize};

/// PyTorch's `GradScaler` defaults.
pub const INITIAL_SCALE: f32 = 65536.0;
pub const GROWTH_INTERVAL: u32 = 2000;
const MIN_SCALE: f32 = 1.0;
const MAX_SCALE: f32 = 16_777_216.0;

/// The scale and its history; part of a checkpoint so a resumed run scales as the first would.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossScale {
    pub scale: f32,
    /// Steps since the last overflow or growth.
    pub good_steps: u32,
    /// The scale moves (f16); fixed at 1 otherwise.
    pub dynamic: bool,
}

impl LossScale {
    pub fn new(precision: Precision) -> LossScale {
        let dynamic = precision.needs_loss_scale();
        LossScale {
            scale: if dynamic { INITIAL_SCALE } else { 1.0 },
            good_steps: 0,
            dynamic,
        }
    }

    /// Records whether a step's gradients were finite; returns whether the optimiser may use them.
    pub fn update(&mut self, finite: bool) -> bool {
        if !self.dynamic {
            return finite;
        }
        if finite {
            self.good_steps += 1;
            if self.good_steps >= GROWTH_INTERVAL {
                self.scale = (self.scale * 2.0).min(MAX_SCALE);
                self.good_steps = 0;
            }
        } else {
            self.scale = (self.scale * 0.5).max(MIN_SCALE);
            self.good_steps = 0;
        }
        finite
    }

    /// Divides `module`'s gradients in `grads` by the scale where it is dynamic; returns whether
    /// they are all finite (always true where it is not: nothing was scaled to overflow).
    pub fn unscale<M: Module>(&self, grads: &mut GradientsParams, module: &M) -> bool {
        !self.dynamic || unscale(grads, module, 1.0 / f64::from(self.scale))
    }
}

/// Divides every gradient of `module` in `grads` by the loss scale (`inverse` = 1 / scale);
/// returns whether all of them are finite. One read-back: the sum of every gradient is
/// non-finite exactly when one of them is (NaN and ±∞ survive a sum).
pub fn unscale<M: Module>(grads: &mut GradientsParams, module: &M, inverse: f64) -> bool {
    struct Unscale<'a> {
        grads: &'a mut GradientsParams,
        inverse: f64,
        total: Option<Tensor<1>>,
    }
    impl ModuleVisitor for Unscale<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if let Some(g) = self.grads.remove::<D>(param.id) {
                let g = g.mul_scalar(self.inverse);
                let sum = g.clone().sum();
                self.total = Some(match self.total.take() {
                    Some(t) => t + sum,
                    None => sum,
                });
                self.grads.register(param.id, g);
            }
        }
    }
    let mut v = Unscale {
        grads,
        inverse,
        total: None,
    };
    module.visit(&mut v);
    v.total.is_none_or(|t| t.into_scalar::<f32>().is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_overflow_halves_the_scale_and_skips_the_step() {
        let mut s = LossScale::new(Precision::F16);
        assert_eq!(s.scale, INITIAL_SCALE);
        assert!(!s.update(false));
        assert_eq!(s.scale, INITIAL_SCALE / 2.0);
        assert!(s.update(true));
        assert_eq!(s.good_steps, 1);
    }

    #[test]
    fn the_scale_doubles_after_the_growth_interval() {
        let mut s = LossScale::new(Precision::F16);
        for _ in 0..GROWTH_INTERVAL - 1 {
            assert!(s.update(true));
        }
        assert_eq!(s.scale, INITIAL_SCALE);
        assert!(s.update(true));
        assert_eq!(s.scale, INITIAL_SCALE * 2.0);
        assert_eq!(s.good_steps, 0);
    }

    #[test]
    fn the_scale_stays_within_its_bounds() {
        let mut s = LossScale::new(Precision::F16);
        for _ in 0..100 {
            s.update(false);
        }
        assert_eq!(s.scale, MIN_SCALE);
        let mut s = LossScale {
            scale: MAX_SCALE,
            good_steps: GROWTH_INTERVAL - 1,
            dynamic: true,
        };
        s.update(true);
        assert_eq!(s.scale, MAX_SCALE);
    }

    #[test]
    fn f32_and_bf16_are_not_scaled() {
        for p in [Precision::F32, Precision::Bf16] {
            let mut s = LossScale::new(p);
            assert_eq!(s.scale, 1.0);
            for _ in 0..3 * GROWTH_INTERVAL {
                assert!(s.update(true));
            }
            assert_eq!(s.scale, 1.0, "{p}");
        }
    }
}
