//! The gradients of one optimiser step, from a batch cut into micro-batches.
//!
//! The paper trains on batches of 64 at 512²; the four networks, the critic and VGG16 hold about
//! 2 GB of activations per 512² example, more than one GPU has for 64. A step therefore runs the
//! batch `micro_batch` examples at a time and adds the gradients up before the optimiser moves.
//! Each micro-batch's loss is its own mean and weighs `1 / micro-batches` (what gradient
//! accumulation does in PyTorch), so a step is the full batch's when the micro-batches' masks
//! cover equal areas and differs slightly otherwise. The critic is fixed during the step, as it
//! is without micro-batches: its gradients add up the same way and it moves after the generator.

use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::prelude::*;
use lightfarm_nets::{
    critic_loss, generator_loss, in_precision, LossWeights, PatchGan, Precision, RelightNet, Vgg16,
};

use crate::data::{to_device, Example};
use crate::loss_scale::LossScale;
use crate::TrainError;

/// What a step needs besides the networks.
pub(crate) struct StepSpec<'a> {
    /// Examples per forward/backward pass; the batch is cut into chunks of this many.
    pub micro_batch: usize,
    pub weights: &'a LossWeights,
    /// The generator's loss includes the critic's verdict (after `adversarial_from`).
    pub adversarial: bool,
    /// The critic trains (adversarial weight > 0).
    pub train_critic: bool,
    pub vgg: Option<&'a Vgg16>,
    /// The precision the convolutions run in (`nets::precision`); the weights stay f32.
    pub precision: Precision,
    /// The losses are multiplied by its scale before the backward pass and the gradients
    /// divided by it after (`loss_scale.rs`); 1 and fixed outside f16.
    pub loss_scale: LossScale,
}

/// The step's losses, each the mean over its micro-batches (what `losses.jsonl` records).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct StepLosses {
    pub total: f32,
    pub normal: f32,
    pub normal_lens: f32,
    pub albedo: f32,
    pub relit: f32,
    pub residual: Option<f32>,
    pub adversarial: Option<f32>,
    pub critic: Option<f32>,
    pub perceptual: Option<f32>,
}

impl StepLosses {
    /// Each term's mean over `parts` (summed in f64).
    fn mean(parts: &[StepLosses]) -> StepLosses {
        let n = parts.len().max(1) as f64;
        let mean = |term: fn(&StepLosses) -> f32| {
            (parts.iter().map(|p| f64::from(term(p))).sum::<f64>() / n) as f32
        };
        let optional = |term: fn(&StepLosses) -> Option<f32>| {
            let values: Vec<f64> = parts.iter().filter_map(term).map(f64::from).collect();
            (!values.is_empty()).then(|| (values.iter().sum::<f64>() / values.len() as f64) as f32)
        };
        StepLosses {
            total: mean(|p| p.total),
            normal: mean(|p| p.normal),
            normal_lens: mean(|p| p.normal_lens),
            albedo: mean(|p| p.albedo),
            relit: mean(|p| p.relit),
            residual: optional(|p| p.residual),
            adversarial: optional(|p| p.adversarial),
            critic: optional(|p| p.critic),
            perceptual: optional(|p| p.perceptual),
        }
    }
}

pub(crate) struct StepGrads {
    pub model: GradientsParams,
    /// `None` when the critic does not train.
    pub critic: Option<GradientsParams>,
    pub losses: StepLosses,
    /// Every gradient is finite. False only where a half-precision pass overflowed under the
    /// loss scale: the step is then skipped and the scale lowered.
    pub finite: bool,
}

/// The generator's and the critic's gradients over `examples`, `spec.micro_batch` at a time.
pub(crate) fn gradients(
    model: &RelightNet,
    critic: &PatchGan,
    examples: &[Example],
    device: &Device,
    spec: &StepSpec<'_>,
) -> Result<StepGrads, TrainError> {
    if examples.is_empty() || spec.micro_batch == 0 {
        return Err(TrainError::Input(
            "a step needs at least one example".into(),
        ));
    }
    // The passes run on copies in the step's precision (`in_precision`, cast afresh for each
    // backward pass); the gradients land on the f32 originals.
    let vgg_run = spec.vgg.map(|v| {
        if spec.precision.is_half() {
            v.cast(spec.precision.dtype())
        } else {
            v.clone()
        }
    });

    let chunks: Vec<&[Example]> = examples.chunks(spec.micro_batch).collect();
    let share = f64::from(spec.loss_scale.scale) / chunks.len() as f64;
    let mut model_grads = GradientsAccumulator::<RelightNet>::new();
    let mut critic_grads = GradientsAccumulator::<PatchGan>::new();
    let mut parts = Vec::with_capacity(chunks.len());
    for chunk in &chunks {
        let batch = to_device(chunk, device)?;
        let out = in_precision(model, spec.precision).forward(
            batch.input,
            batch.targets.mask.clone(),
            &batch.light,
        );
        let judge = spec
            .adversarial
            .then(|| in_precision(critic, spec.precision));
        let loss = generator_loss(
            &out,
            &batch.targets,
            spec.weights,
            judge.as_ref(),
            vgg_run.as_ref(),
        );
        let optional = |t: &Option<Tensor<1>>| t.as_ref().map(scalar);
        let mut part = StepLosses {
            total: scalar(&loss.total),
            normal: scalar(&loss.normal),
            normal_lens: scalar(&loss.normal_lens),
            albedo: scalar(&loss.albedo),
            relit: scalar(&loss.relit),
            residual: optional(&loss.residual),
            adversarial: optional(&loss.adversarial),
            critic: None,
            perceptual: optional(&loss.perceptual),
        };
        let grads = loss.total.mul_scalar(share).backward();
        model_grads.accumulate(model, GradientsParams::from_grads(grads, model));
        if spec.train_critic {
            let c = critic_loss(
                &in_precision(critic, spec.precision),
                batch.targets.relit,
                out.relit.detach(),
                batch.targets.mask,
            );
            part.critic = Some(scalar(&c));
            let grads = c.mul_scalar(share).backward();
            critic_grads.accumulate(critic, GradientsParams::from_grads(grads, critic));
        }
        parts.push(part);
    }
    let mut model_grads = model_grads.grads();
    let mut critic_grads = spec.train_critic.then(|| critic_grads.grads());
    let mut finite = spec.loss_scale.unscale(&mut model_grads, model);
    if let Some(g) = critic_grads.as_mut() {
        finite &= spec.loss_scale.unscale(g, critic);
    }
    Ok(StepGrads {
        model: model_grads,
        critic: critic_grads,
        losses: StepLosses::mean(&parts),
        finite,
    })
}

pub(crate) fn scalar(t: &Tensor<1>) -> f32 {
    t.clone().into_scalar::<f32>()
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use lightfarm_light::Hdri;
    use lightfarm_nets::{PatchGanConfig, RelightConfig};

    use burn::module::{Module, ModuleVisitor, Param};

    use super::*;
    use crate::lights::Lighting;

    /// Every float parameter's gradient in `grads`, flattened in the module's parameter order
    /// (a missing gradient reads as an empty slice).
    fn flat_gradients<M: Module>(module: &M, grads: &GradientsParams) -> Vec<Vec<f32>> {
        struct Collect<'a> {
            grads: &'a GradientsParams,
            out: Vec<Vec<f32>>,
        }
        impl ModuleVisitor for Collect<'_> {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                let values = self
                    .grads
                    .get::<D>(param.id)
                    .and_then(|g| g.into_data().try_into_vec::<f32>().ok())
                    .unwrap_or_default();
                self.out.push(values);
            }
        }
        let mut c = Collect {
            grads,
            out: Vec::new(),
        };
        module.visit(&mut c);
        c.out
    }

    fn example(size: usize, seed: u32) -> Example {
        let n = size * size;
        // A smooth, deterministic pattern per channel; the mask covers a disc.
        let field = |c: usize, k: usize| -> Vec<f32> {
            (0..k * n)
                .map(|i| {
                    let x = (i % size) as f32 / size as f32;
                    let y = ((i / size) % size) as f32 / size as f32;
                    ((x * 5.0 + y * 3.0 + c as f32 + seed as f32).sin() * 0.5 + 0.5) * 0.8
                })
                .collect()
        };
        let mask = (0..n)
            .map(|i| {
                let x = (i % size) as f32 + 0.5 - size as f32 / 2.0;
                let y = (i / size) as f32 + 0.5 - size as f32 / 2.0;
                f32::from(x * x + y * y < (size * size) as f32 / 5.0)
            })
            .collect();
        let texels = (0..32 * 16)
            .map(|i| {
                let up = (i / 32) < 6;
                if up {
                    [2.0, 1.8, 1.5]
                } else {
                    [0.2, 0.25, 0.3]
                }
            })
            .collect();
        let hdri = Hdri::from_texels(32, 16, texels).expect("hdri");
        Example {
            size,
            input: field(0, 3),
            mask,
            normal: field(1, 3),
            normal_lens: field(2, 3),
            albedo: field(3, 3),
            target: field(4, 3),
            lighting: Arc::new(Lighting::new(&hdri)),
            camera_to_env: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    fn spec(micro_batch: usize, weights: &LossWeights) -> StepSpec<'_> {
        StepSpec {
            micro_batch,
            weights,
            adversarial: true,
            train_critic: true,
            vgg: None,
            precision: Precision::F32,
            loss_scale: LossScale::new(Precision::F32),
        }
    }

    /// `precision`'s loss scale set to `scale`.
    fn scaled(precision: Precision, scale: f32) -> LossScale {
        LossScale {
            scale,
            ..LossScale::new(precision)
        }
    }

    /// A tiny generator and critic on an autodiff CPU device.
    fn networks() -> (Device, RelightNet, PatchGan) {
        let device = Device::flex().autodiff();
        let model = RelightConfig::tiny().init(&device).expect("model");
        let critic = PatchGanConfig::new().with_width(4).init(&device);
        (device, model, critic)
    }

    /// ‖a − b‖ / ‖a‖ over all parameters.
    fn relative_error(a: &[Vec<f32>], b: &[Vec<f32>]) -> f64 {
        let (mut diff, mut norm) = (0.0f64, 0.0f64);
        for (pa, pb) in a.iter().zip(b) {
            assert_eq!(pa.len(), pb.len());
            for (x, y) in pa.iter().zip(pb) {
                diff += f64::from(x - y).powi(2);
                norm += f64::from(*x).powi(2);
            }
        }
        (diff / norm).sqrt()
    }

    fn max_abs(v: &[Vec<f32>]) -> f32 {
        v.iter().flatten().fold(0.0f32, |m, x| m.max(x.abs()))
    }

    /// Two copies of one example: each micro-batch's loss is the batch's, so the accumulated
    /// gradients must equal the batch's. Forgetting the 1/n share doubles them; dropping a
    /// micro-batch halves them.
    #[test]
    fn micro_batches_add_up_to_the_batch_gradient() {
        let (device, model, critic) = networks();
        let weights = LossWeights::default();
        let examples = vec![example(16, 0), example(16, 0)];
        let whole =
            gradients(&model, &critic, &examples, &device, &spec(2, &weights)).expect("batch");
        let split =
            gradients(&model, &critic, &examples, &device, &spec(1, &weights)).expect("micro");
        assert!((whole.losses.total - split.losses.total).abs() <= 1e-5 * whole.losses.total.abs());
        assert!(whole.losses.critic.is_some() && whole.losses.adversarial.is_some());

        for (module, a, b) in [
            (
                "generator",
                flat_gradients(&model, &whole.model),
                flat_gradients(&model, &split.model),
            ),
            (
                "critic",
                flat_gradients(&critic, whole.critic.as_ref().expect("critic")),
                flat_gradients(&critic, split.critic.as_ref().expect("critic")),
            ),
        ] {
            let scale = max_abs(&a);
            assert!(scale > 0.0, "{module}: no gradient at all");
            assert_eq!(a.len(), b.len());
            for (i, (ga, gb)) in a.iter().zip(&b).enumerate() {
                assert_eq!(ga.len(), gb.len(), "{module} parameter {i}");
                for (x, y) in ga.iter().zip(gb) {
                    assert!(
                        (x - y).abs() <= 1e-4 * scale,
                        "{module} parameter {i}: {x} vs {y}"
                    );
                }
            }
        }
    }

    /// Different examples: the micro-batches' gradients still add up to one step's worth
    /// (their mean), not to one micro-batch's.
    #[test]
    fn a_micro_batch_step_averages_its_parts() {
        let (device, model, critic) = networks();
        let weights = LossWeights::default();
        let (a, b) = (example(16, 0), example(16, 7));
        let s = spec(1, &weights);
        let ga = gradients(&model, &critic, std::slice::from_ref(&a), &device, &s).expect("a");
        let gb = gradients(&model, &critic, std::slice::from_ref(&b), &device, &s).expect("b");
        let both = gradients(&model, &critic, &[a, b], &device, &s).expect("both");
        let (fa, fb, fboth) = (
            flat_gradients(&model, &ga.model),
            flat_gradients(&model, &gb.model),
            flat_gradients(&model, &both.model),
        );
        let scale = max_abs(&fboth);
        for ((pa, pb), pboth) in fa.iter().zip(&fb).zip(&fboth) {
            for ((x, y), z) in pa.iter().zip(pb).zip(pboth) {
                assert!((0.5 * (x + y) - z).abs() <= 1e-4 * scale, "{x} {y} {z}");
            }
        }
        let mean = 0.5 * (ga.losses.total + gb.losses.total);
        assert!((both.losses.total - mean).abs() <= 1e-5 * mean.abs());
    }

    /// The half-precision passes land their gradients on the f32 weights, close to the f32
    /// step's: f16 under a loss scale (unscaled afterwards), bf16 without one.
    #[test]
    fn half_precision_gradients_match_f32() {
        let (device, model, critic) = networks();
        let weights = LossWeights::default();
        let examples = vec![example(16, 0)];
        let full = gradients(&model, &critic, &examples, &device, &spec(1, &weights)).expect("f32");
        let reference = flat_gradients(&model, &full.model);
        // Measured over unseeded inits: f16 ~1e-3, bf16 2e-3..2e-2 (8 mantissa bits). A missed
        // unscale is off by the scale (1023x), a half pass that did not run is exactly 0.
        for (precision, scale, bound) in
            [(Precision::F16, 1024.0, 1e-2), (Precision::Bf16, 1.0, 0.1)]
        {
            let s = StepSpec {
                precision,
                loss_scale: scaled(precision, scale),
                ..spec(1, &weights)
            };
            let half = gradients(&model, &critic, &examples, &device, &s).expect("half");
            assert!(half.finite, "{precision}");
            let err = relative_error(&reference, &flat_gradients(&model, &half.model));
            eprintln!("{precision}: relative gradient error {err:.2e}");
            assert!(err <= bound, "{precision}: relative gradient error {err}");
            assert!(
                err > 0.0,
                "{precision}: the passes did not run in half precision"
            );
            let critic_err = relative_error(
                &flat_gradients(&critic, full.critic.as_ref().expect("critic")),
                &flat_gradients(&critic, half.critic.as_ref().expect("critic")),
            );
            assert!(
                critic_err <= bound,
                "{precision}: critic gradient error {critic_err}"
            );
            assert!((half.losses.total - full.losses.total).abs() <= 0.05 * full.losses.total);
        }
    }

    /// A loss scale f16 cannot hold makes the gradients overflow, and the step says so.
    #[test]
    fn an_overflowing_loss_scale_is_reported() {
        let (device, model, critic) = networks();
        let weights = LossWeights::default();
        let s = StepSpec {
            precision: Precision::F16,
            loss_scale: scaled(Precision::F16, 1e30),
            ..spec(1, &weights)
        };
        let g = gradients(&model, &critic, &[example(16, 0)], &device, &s).expect("step");
        assert!(!g.finite);
        let s = StepSpec {
            precision: Precision::F16,
            loss_scale: scaled(Precision::F16, 2.0),
            ..spec(1, &weights)
        };
        let g = gradients(&model, &critic, &[example(16, 0)], &device, &s).expect("step");
        assert!(g.finite);
    }
}
