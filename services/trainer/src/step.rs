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
use lightfarm_nets::{critic_loss, generator_loss, LossWeights, PatchGan, RelightNet, Vgg16};

use crate::data::{to_device, Example};
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

pub(crate) struct StepGrads {
    pub model: GradientsParams,
    /// `None` when the critic does not train.
    pub critic: Option<GradientsParams>,
    pub losses: StepLosses,
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
    let chunks: Vec<&[Example]> = examples.chunks(spec.micro_batch).collect();
    let share = 1.0 / chunks.len() as f32;
    let mut model_grads = GradientsAccumulator::<RelightNet>::new();
    let mut critic_grads = GradientsAccumulator::<PatchGan>::new();
    let mut sums = Sums::default();
    for chunk in &chunks {
        let batch = to_device(chunk, device)?;
        let out = model.forward(batch.input, batch.targets.mask.clone(), &batch.light);
        let loss = generator_loss(
            &out,
            &batch.targets,
            spec.weights,
            spec.adversarial.then_some(critic),
            spec.vgg,
        );
        sums.total += f64::from(scalar(&loss.total));
        sums.normal += f64::from(scalar(&loss.normal));
        sums.normal_lens += f64::from(scalar(&loss.normal_lens));
        sums.albedo += f64::from(scalar(&loss.albedo));
        sums.relit += f64::from(scalar(&loss.relit));
        add(&mut sums.residual, loss.residual.as_ref());
        add(&mut sums.adversarial, loss.adversarial.as_ref());
        add(&mut sums.perceptual, loss.perceptual.as_ref());
        let grads = loss.total.mul_scalar(share).backward();
        model_grads.accumulate(model, GradientsParams::from_grads(grads, model));
        if spec.train_critic {
            let c = critic_loss(
                critic,
                batch.targets.relit,
                out.relit.detach(),
                batch.targets.mask,
            );
            add(&mut sums.critic, Some(&c));
            let grads = c.mul_scalar(share).backward();
            critic_grads.accumulate(critic, GradientsParams::from_grads(grads, critic));
        }
    }
    let n = chunks.len() as f64;
    let mean = |s: f64| (s / n) as f32;
    Ok(StepGrads {
        model: model_grads.grads(),
        critic: spec.train_critic.then(|| critic_grads.grads()),
        losses: StepLosses {
            total: mean(sums.total),
            normal: mean(sums.normal),
            normal_lens: mean(sums.normal_lens),
            albedo: mean(sums.albedo),
            relit: mean(sums.relit),
            residual: sums.residual.map(mean),
            adversarial: sums.adversarial.map(mean),
            critic: sums.critic.map(mean),
            perceptual: sums.perceptual.map(mean),
        },
    })
}

#[derive(Default)]
struct Sums {
    total: f64,
    normal: f64,
    normal_lens: f64,
    albedo: f64,
    relit: f64,
    residual: Option<f64>,
    adversarial: Option<f64>,
    critic: Option<f64>,
    perceptual: Option<f64>,
}

fn add(sum: &mut Option<f64>, term: Option<&Tensor<1>>) {
    if let Some(t) = term {
        *sum = Some(sum.unwrap_or(0.0) + f64::from(scalar(t)));
    }
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
        }
    }

    fn max_abs(v: &[Vec<f32>]) -> f32 {
        v.iter().flatten().fold(0.0f32, |m, x| m.max(x.abs()))
    }

    /// Two copies of one example: each micro-batch's loss is the batch's, so the accumulated
    /// gradients must equal the batch's. Forgetting the 1/n share doubles them; dropping a
    /// micro-batch halves them.
    #[test]
    fn micro_batches_add_up_to_the_batch_gradient() {
        let device = Device::flex().autodiff();
        let model = RelightConfig::tiny().init(&device).expect("model");
        let critic = PatchGanConfig::new().with_width(4).init(&device);
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
        let device = Device::flex().autodiff();
        let model = RelightConfig::tiny().init(&device).expect("model");
        let critic = PatchGanConfig::new().with_width(4).init(&device);
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
}
