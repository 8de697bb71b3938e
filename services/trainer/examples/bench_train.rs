//! Training-speed benchmark: iterations/s of one generator + critic step of the relighting
//! network on fixed random inputs of the trainer's shapes (data loading not timed), the same
//! work `bench/train_torch.py` times in PyTorch. `bench/train-compare.sh` runs both.
//!
//! cargo run --release -p lightfarm-trainer --example bench_train -- \
//!     --batch 2 --size 256 --widths 32,64,128,256,512 --iters 3 --warmup 1 [--device cpu|gpu] \
//!     [--precision f32|f16|bf16]
//!
//! `--precision f16|bf16` runs the convolutions in half precision on cast copies of the weights,
//! with f16's loss scale, as the trainer does (`precision` in train.toml); its PyTorch
//! counterpart is `bench/train_torch.py --amp f16|bf16` (autocast and `GradScaler`).

use std::time::Instant;

mod common;
use common::arg;

use burn::optim::GradientsParams;
use burn::prelude::*;
use lightfarm_light::{
    default_resolution, PrefilteredEnv, PrefilteredMap, ShRadiance, PHONG_EXPONENTS,
};
use lightfarm_nets::{
    critic_loss, generator_loss, in_precision, LightBatch, LightInput, LossWeights, PatchGanConfig,
    Precision, RelightConfig, RenderNet, Targets,
};
use lightfarm_trainer::loss_scale::LossScale;

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let batch: usize = arg(&args, "--batch", 2);
    let size: usize = arg(&args, "--size", 256);
    let widths: Vec<usize> = arg(&args, "--widths", "32,64,128,256,512".to_string())
        .split(',')
        .filter_map(|w| w.trim().parse().ok())
        .collect();
    let gan_width: usize = arg(&args, "--gan-width", 32);
    let warmup: usize = arg(&args, "--warmup", 1);
    let iters: usize = arg(&args, "--iters", 3);
    let device_name: String = arg(&args, "--device", "cpu".to_string());
    let precision: Precision = arg(&args, "--precision", "f32".to_string())
        .parse()
        .unwrap_or_else(|e| panic!("--precision: {e}"));
    let render_net = match arg(&args, "--render-net", "decomposed".to_string()).as_str() {
        "blackbox" => RenderNet::Blackbox,
        _ => RenderNet::Decomposed,
    };

    let base = lightfarm_nets::device::select(&device_name).unwrap_or_else(|e| panic!("{e}"));
    precision.check(&base).unwrap_or_else(|e| panic!("{e}"));
    let device = base.autodiff();
    device.seed(0);
    let cfg = RelightConfig::new()
        .with_widths(widths.clone())
        .with_render_net(render_net);
    let mut model = cfg.init(&device).unwrap_or_else(|e| panic!("{e}"));
    let mut critic = PatchGanConfig::new().with_width(gan_width).init(&device);
    let mut optim = lightfarm_nets::optimizer();
    let mut critic_optim = lightfarm_nets::optimizer();
    let params = model.num_params();

    let mut rng = Rng(7);
    let mut tensor = |dims: [usize; 4], scale: f32, mask: Option<&[f32]>| {
        let n: usize = dims.iter().product();
        let plane = dims[2] * dims[3];
        let data: Vec<f32> = (0..n)
            .map(|i| rng.next() * scale * mask.map_or(1.0, |m| m[i % plane]))
            .collect();
        Tensor::<4>::from_data(TensorData::new(data, dims), &device)
    };
    let disc: Vec<f32> = (0..size * size)
        .map(|i| {
            let (x, y) = (
                (i % size) as f32 / size as f32 - 0.5,
                (i / size) as f32 / size as f32 - 0.5,
            );
            if x * x + y * y < 0.16 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let unit = |t: Tensor<4>| {
        let t = t.sub_scalar(0.5);
        let len = t.clone().powi_scalar(2).sum_dim(1).add_scalar(1e-8).sqrt();
        t / len
    };
    let input = tensor([batch, 3, size, size], 1.0, Some(&disc));
    let targets = Targets {
        normal: unit(tensor([batch, 3, size, size], 1.0, None)),
        normal_lens: unit(tensor([batch, 3, size, size], 1.0, None)),
        albedo: tensor([batch, 3, size, size], 1.0, None),
        relit: tensor([batch, 3, size, size], 2.0, Some(&disc)),
        mask: Tensor::<4>::from_data(
            TensorData::new(disc.repeat(batch), [batch, 1, size, size]),
            &device,
        ),
    };
    let mut r = Rng(11);
    let env = PrefilteredEnv {
        sh: ShRadiance {
            coeffs: [[0.0; 3]; 9].map(|c: [f32; 3]| c.map(|_| r.next())),
        },
        phong: PHONG_EXPONENTS
            .iter()
            .map(|&n| {
                let (w, _) = default_resolution(n);
                PrefilteredMap {
                    exponent: n,
                    width: w,
                    height: w / 2,
                    texels: (0..w * w / 2).map(|_| [r.next() * 4.0; 3]).collect(),
                }
            })
            .collect(),
    };
    let items: Vec<LightInput<'_>> = (0..batch)
        .map(|_| LightInput {
            env: &env,
            scale: 1.0,
            camera_to_env: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        })
        .collect();
    let light = LightBatch::new(&items, &device).unwrap_or_else(|e| panic!("{e}"));
    let weights = LossWeights::default();

    let mut scale = LossScale::new(precision);
    let mut skipped = 0u32;
    let mut times = Vec::new();
    for i in 0..warmup + iters {
        let t0 = Instant::now();
        // The trainer's step (step.rs) without micro-batches: copies in the precision run the
        // passes (cast afresh for each backward pass), the gradients land on the f32 weights.
        let run_model = in_precision(&model, precision);
        let out = run_model.forward(input.clone(), targets.mask.clone(), &light);
        let loss = generator_loss(
            &out,
            &targets,
            &weights,
            Some(&in_precision(&critic, precision)),
            None,
        );
        let _ = loss.total.clone().into_scalar::<f32>();
        let backward = loss.total.mul_scalar(scale.scale).backward();
        let mut grads = GradientsParams::from_grads(backward, &model);
        let c = critic_loss(
            &in_precision(&critic, precision),
            targets.relit.clone(),
            out.relit.detach(),
            targets.mask.clone(),
        );
        let _ = c.clone().into_scalar::<f32>();
        let mut critic_grads =
            GradientsParams::from_grads(c.mul_scalar(scale.scale).backward(), &critic);
        let finite = scale.unscale(&mut grads, &model) & scale.unscale(&mut critic_grads, &critic);
        if scale.update(finite) {
            model = optim.step(1e-4, model, grads);
            critic = critic_optim.step(1e-4, critic, critic_grads);
        } else {
            skipped += 1;
        }
        let dt = t0.elapsed().as_secs_f64();
        eprintln!(
            "iteration {i}: {dt:.3} s{}",
            if i < warmup { " (warm-up)" } else { "" }
        );
        if i >= warmup {
            times.push(dt);
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let total: f64 = times.iter().sum();
    println!(
        "{}",
        serde_json::json!({
            "framework": "burn",
            "burn": "0.22.1",
            "device": device_name,
            "batch": batch,
            "size": size,
            "widths": widths,
            "iters": iters,
            "seconds_per_iter_median": median,
            "seconds_per_iter_min": times[0],
            "iters_per_s": iters as f64 / total,
            "params": params,
            "precision": precision.to_string(),
            "skipped_steps": skipped,
        })
    );
}
