//! Training on a dataset the project rendered: the networks overfit four samples (both render
//! nets), the loss falls, and a resumed run continues the same loss curve.

mod common;

use std::sync::atomic::AtomicBool;

use lightfarm_nets::RenderNet;
use lightfarm_scene::Catalog;
use lightfarm_trainer::config::{NetConfig, TrainConfig};
use lightfarm_trainer::eval::{evaluate, table};
use lightfarm_trainer::train::read_losses;
use lightfarm_trainer::StepLog;

fn config(out: &std::path::Path, steps: u64, render_net: RenderNet) -> TrainConfig {
    let mut cfg: TrainConfig = toml::from_str(&format!(
        "dataset = {:?}\nout = {:?}\nsplit = \"all\"\nsteps = {steps}\nbatch = {}\nlr = 5e-3\ncheckpoint_every = 10\n\
         device = \"cpu\"\nloader_threads = 1\nvgg_weights = \"none\"\n[loss]\nadversarial = 0.0\n",
        common::dataset(),
        out,
        common::COUNT
    ))
    .expect("config");
    cfg.net = NetConfig {
        widths: vec![8, 16, 32],
        render_net,
        critic_width: 8,
        adversarial_from: 0,
    };
    cfg.validate().expect("valid");
    cfg
}

fn mean(v: &[StepLog], f: impl Fn(&StepLog) -> f32) -> f32 {
    v.iter().map(f).sum::<f32>() / v.len() as f32
}

/// The bar: trained on four samples, the relit error is far below the error between
/// the input and the target, and the loss falls in trend. Measured at 300 steps (all CI can
/// afford on flex, ~0.35 s/step): MAE 0.044 vs 0.079, MSE 0.008 vs 0.024; still falling.
#[test]
fn both_render_nets_overfit_four_samples() {
    let tmp = tempfile::tempdir().unwrap();
    let mut models = Vec::new();
    // The paper's render net is held to the bar; the ablation only has to train (its
    // row is there to be compared). It gets the same steps: at 150 its relit MAE swung from
    // 0.78x to 0.88x the input's between two renders of the dataset that differed only in the
    // noise of surfaces without UVs (2026-12-05); at 300 it is 0.64x and 0.66x on the same two.
    for (net, steps) in [(RenderNet::Decomposed, 300u64), (RenderNet::Blackbox, 300)] {
        let out = tmp.path().join(format!("{net:?}"));
        let cfg = config(&out, steps, net);
        let summary = lightfarm_trainer::train(
            &cfg,
            Catalog::builtin().unwrap(),
            &mut (),
            &AtomicBool::new(false),
        )
        .unwrap();
        assert_eq!(summary.end_step, steps);
        let losses = read_losses(&out).unwrap();
        assert_eq!(losses.len(), steps as usize);
        // Falling in trend: the mean over each fifth of the run is below the one before.
        let fifths: Vec<f32> = losses
            .chunks(steps as usize / 5)
            .map(|c| mean(c, |l| l.total))
            .collect();
        let speed = mean(&losses, |l| l.samples_per_second);
        println!("{net:?}: loss by fifths {fifths:?}, {speed:.1} samples/s");
        assert!(
            fifths.windows(2).all(|w| w[1] < w[0]),
            "{net:?}: loss by fifths {fifths:?}"
        );
        models.push(out);
    }
    let rows = evaluate(
        &models,
        common::dataset(),
        "all",
        Catalog::builtin().unwrap(),
        "cpu",
        None,
        |_, _| {},
    )
    .unwrap();
    println!("{}", table(&rows));
    assert_eq!(rows.len(), 3);
    let input = rows[0].mae;
    assert!(
        rows[1].mae < 0.6 * input,
        "decomposed: relit MAE {} vs input {input}",
        rows[1].mae
    );
    assert!(
        rows[1].mse < 0.4 * rows[0].mse,
        "decomposed: relit MSE {} vs input {}",
        rows[1].mse,
        rows[0].mse
    );
    // The ablation's bar is looser than the paper's net's, but not "any improvement": it
    // measured 0.052 vs 0.080 (0.66x) at 300 steps.
    assert!(
        rows[2].mae < 0.8 * input,
        "blackbox: relit MAE {} vs input {input}",
        rows[2].mae
    );
    // SSIM is the paper's net's bar only: the black-box ablation predicts the relit image
    // directly and can blur it at this size and step count (measured 0.654 vs the input's 0.668
    // at 150 steps after the garment push-out changed the renders; 0.711 vs 0.662 at 300),
    // which is the paper's reason for the decomposed net, not a training failure.
    assert!(
        rows[1].ssim > rows[0].ssim,
        "decomposed: SSIM {} vs input {}",
        rows[1].ssim,
        rows[0].ssim
    );
    for row in &rows[1..] {
        assert!(row.sh_error.is_some_and(f64::is_finite));
    }
}

/// Stopping after step 20 and resuming to 30 gives the losses of an uninterrupted 30-step run.
#[test]
fn a_resumed_run_continues_the_same_loss_curve() {
    let tmp = tempfile::tempdir().unwrap();
    let straight = tmp.path().join("straight");
    let resumed = tmp.path().join("resumed");
    let catalog = || Catalog::builtin().unwrap();
    let stop = AtomicBool::new(false);
    lightfarm_trainer::train(
        &config(&straight, 30, RenderNet::Decomposed),
        catalog(),
        &mut (),
        &stop,
    )
    .unwrap();
    lightfarm_trainer::train(
        &config(&resumed, 25, RenderNet::Decomposed),
        catalog(),
        &mut (),
        &stop,
    )
    .unwrap();
    // Steps 21..25 were logged after the step-20 checkpoint and are redone on resume; drop the
    // step-25 checkpoint to stand for a crash between checkpoints.
    let ck = resumed.join("checkpoints");
    std::fs::remove_dir_all(ck.join("step-000000025")).unwrap();
    std::fs::write(ck.join("latest"), "step-000000020").unwrap();
    let summary = lightfarm_trainer::train(
        &config(&resumed, 30, RenderNet::Decomposed),
        catalog(),
        &mut (),
        &stop,
    )
    .unwrap();
    assert_eq!((summary.start_step, summary.end_step), (20, 30));
    let (a, b) = (
        read_losses(&straight).unwrap(),
        read_losses(&resumed).unwrap(),
    );
    assert_eq!(
        b.len(),
        30,
        "losses.jsonl keeps one line per step after a resume"
    );
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.step, y.step);
        let tol = 1e-4 * x.total.abs().max(1e-3);
        assert!(
            (x.total - y.total).abs() <= tol,
            "step {}: {} vs {}",
            x.step,
            x.total,
            y.total
        );
    }
}

#[test]
fn bad_configs_are_refused_with_the_key() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("train.toml");
    for (text, needle) in [
        ("dataset = \"d\"\nout = \"o\"\nsteps = 0\n", "steps"),
        ("dataset = \"d\"\nout = \"o\"\nbatch = 0\n", "batch"),
        ("dataset = \"d\"\nout = \"o\"\ncrop = 30\n", "crop"),
        ("dataset = \"d\"\nout = \"o\"\nlr = -1.0\n", "lr"),
        ("dataset = \"d\"\nout = \"o\"\nbogus = 1\n", "bogus"),
        (
            "dataset = \"d\"\nout = \"o\"\n[net]\nwidths = []\n",
            "widths",
        ),
        (
            "dataset = \"d\"\nout = \"o\"\n[net]\nrender_net = \"magic\"\n",
            "render_net",
        ),
        ("dataset = [", "train.toml"),
        (
            "dataset = \"d\"\nout = \"o\"\nbatch = 8\nmicro_batch = 3\n",
            "micro_batch = 3",
        ),
        (
            "dataset = \"d\"\nout = \"o\"\nbatch = 8\nmicro_batch = 0\n",
            "micro_batch",
        ),
        (
            "dataset = \"d\"\nout = \"o\"\nbatch = 8\nmicro_batch = 16\n",
            "divide batch",
        ),
        (
            "dataset = \"d\"\nout = \"o\"\nprecision = \"f8\"\n",
            "precision",
        ),
    ] {
        std::fs::write(&path, text).unwrap();
        let err = TrainConfig::load(&path).expect_err(text).to_string();
        assert!(err.contains(needle), "{text:?}: {err}");
    }
}

#[test]
fn a_missing_or_webdataset_export_is_refused_with_the_fix() {
    let tmp = tempfile::tempdir().unwrap();
    let mut cfg = config(&tmp.path().join("run"), 5, RenderNet::Decomposed);
    cfg.dataset = tmp.path().join("nowhere");
    let err = lightfarm_trainer::train(
        &cfg,
        Catalog::builtin().unwrap(),
        &mut (),
        &AtomicBool::new(false),
    )
    .expect_err("no dataset")
    .to_string();
    assert!(
        err.contains("lightfarm export") && err.contains("nowhere"),
        "{err}"
    );
}

#[test]
fn truncated_or_foreign_exrs_are_errors_naming_the_sample() {
    let exr_path = std::fs::read_dir(common::dataset())
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|e| e == "exr"))
        .unwrap();
    let bytes = std::fs::read(&exr_path).unwrap();
    let good = lightfarm_trainer::sample::decode_sample(&bytes, "s0").unwrap();
    assert_eq!((good.width, good.height), (common::SIZE, common::SIZE));
    // The id pass gives the skin the lighting metric fits to: inside the subject, not all of it.
    let skin = good
        .skin
        .as_ref()
        .expect("a rendered sample has the id pass and its table");
    let (on_skin, subject) = (skin.iter().sum::<f32>(), good.mask.iter().sum::<f32>());
    assert!(
        on_skin > 0.0 && on_skin < subject,
        "skin {on_skin} of {subject} subject pixels"
    );
    assert!(skin
        .iter()
        .zip(&good.mask)
        .all(|(&s, &m)| s == 0.0 || m > 0.0));
    for cut in [0, 8, bytes.len() / 2, bytes.len() - 1] {
        let err = lightfarm_trainer::sample::decode_sample(&bytes[..cut], "s0")
            .expect_err("truncated")
            .to_string();
        assert!(err.contains("s0"), "{err}");
    }
    let err = lightfarm_trainer::sample::decode_sample(b"not an exr at all", "junk")
        .expect_err("junk")
        .to_string();
    assert!(err.contains("junk") && err.contains("OpenEXR"), "{err}");
}

/// The paper's perceptual loss is on unless a config turns it off.
#[test]
fn the_perceptual_loss_uses_the_builtin_weights_by_default() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("train.toml");
    let load = |extra: &str| {
        std::fs::write(&path, format!("dataset = \"d\"\nout = \"o\"\n{extra}")).unwrap();
        TrainConfig::load(&path).unwrap().perceptual_weights()
    };
    let builtin = Some(lightfarm_nets::vgg::builtin_weights());
    assert_eq!(load(""), builtin);
    assert_eq!(load("vgg_weights = \"builtin\"\n"), builtin);
    assert_eq!(load("vgg_weights = \"none\"\n"), None);
    assert_eq!(load("[loss]\nperceptual = 0.0\n"), None);
    assert_eq!(
        load("vgg_weights = \"w.safetensors\"\n"),
        Some(tmp.path().join("w.safetensors"))
    );
}

#[test]
fn the_example_config_is_valid() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/train.toml");
    let cfg = TrainConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(cfg.net.render_net, RenderNet::Decomposed);
    assert!(cfg.dataset.ends_with("out/dataset"));
}

/// The paper's schedule (section 4): 512² crops, batch 64 in micro-batches of 8, lr 1e-4,
/// 50k iterations, the full-width networks and the perceptual loss.
#[test]
fn the_paper_preset_is_the_papers_schedule() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/train-paper.toml");
    let cfg = TrainConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((cfg.crop, cfg.batch, cfg.micro_batch()), (512, 64, 8));
    assert_eq!((cfg.lr, cfg.steps), (1e-4, 50_000));
    assert_eq!(cfg.net.widths, vec![32, 64, 128, 256, 512]);
    assert_eq!(cfg.net.render_net, RenderNet::Decomposed);
    assert_eq!(
        cfg.perceptual_weights(),
        Some(lightfarm_nets::vgg::builtin_weights())
    );
    assert_eq!(cfg.device, "auto");
}

/// A batch run in micro-batches trains and logs one line per step, whose loss is the mean
/// over the step's micro-batches (step.rs checks the gradients themselves).
#[test]
fn micro_batches_train_one_logged_step_each() {
    let tmp = tempfile::tempdir().unwrap();
    let mut cfg = config(&tmp.path().join("run"), 2, RenderNet::Decomposed);
    cfg.micro_batch = Some(1);
    let summary = lightfarm_trainer::train(
        &cfg,
        Catalog::builtin().unwrap(),
        &mut (),
        &AtomicBool::new(false),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.end_step, 2);
    let log = lightfarm_trainer::train::read_losses(&cfg.out).unwrap();
    assert_eq!(log.iter().map(|l| l.step).collect::<Vec<_>>(), vec![1, 2]);
    assert!(log.iter().all(|l| l.total.is_finite() && l.total > 0.0));
}

/// Training in f16 (with its loss scale) and bf16 follows the f32 run's loss curve, and an f16
/// checkpoint keeps the loss scale a resumed run continues from (step.rs checks the gradients).
#[test]
fn half_precision_runs_follow_the_f32_loss_curve() {
    let tmp = tempfile::tempdir().unwrap();
    let run = |precision: lightfarm_nets::Precision| {
        // Two steps: flex has no native half arithmetic (f16 ~3x slower than f32 here).
        let mut cfg = config(
            &tmp.path().join(precision.to_string()),
            2,
            RenderNet::Decomposed,
        );
        cfg.precision = precision;
        lightfarm_trainer::train(
            &cfg,
            Catalog::builtin().unwrap(),
            &mut (),
            &AtomicBool::new(false),
        )
        .unwrap_or_else(|e| panic!("{precision}: {e}"));
        (read_losses(&cfg.out).unwrap(), cfg.out)
    };
    let (full, _) = run(lightfarm_nets::Precision::F32);
    for precision in [
        lightfarm_nets::Precision::F16,
        lightfarm_nets::Precision::Bf16,
    ] {
        let (half, out) = run(precision);
        assert_eq!(half.len(), full.len(), "{precision}: one line per step");
        for (a, b) in full.iter().zip(&half) {
            assert!(
                (a.total - b.total).abs() <= 0.05 * a.total,
                "{precision} step {}: {} vs f32 {}",
                a.step,
                b.total,
                a.total
            );
        }
        let state =
            std::fs::read_to_string(out.join("checkpoints/step-000000002/state.json")).unwrap();
        assert_eq!(
            state.contains("\"loss_scale\""),
            precision == lightfarm_nets::Precision::F16,
            "{precision}: {state}"
        );
    }
}

/// Random VGG16 + LPIPS weights in torchvision's / lpips's layout (the code cannot tell them
/// from ImageNet's; crates/nets/tests/vgg.rs checks the maths).
fn write_random_vgg(path: &std::path::Path) {
    let mut state = 1u64;
    let mut rand = move |bound: f32| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * bound
    };
    let mut tensors: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
    let mut push = |name: String, shape: Vec<usize>, v: Vec<f32>| {
        tensors.push((
            name,
            shape,
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ));
    };
    for (i, cin, cout) in lightfarm_nets::vgg::VGG16_CONVS {
        let bound = (6.0 / (9.0 * cin as f32)).sqrt();
        push(
            format!("features.{i}.weight"),
            vec![cout, cin, 3, 3],
            (0..cout * cin * 9).map(|_| rand(bound)).collect(),
        );
        push(format!("features.{i}.bias"), vec![cout], vec![0.0; cout]);
    }
    for (k, c) in lightfarm_nets::vgg::TAP_CHANNELS.into_iter().enumerate() {
        push(
            format!("lin{k}.model.1.weight"),
            vec![1, c, 1, 1],
            vec![0.1; c],
        );
    }
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = tensors
        .iter()
        .map(|(n, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                    .unwrap(),
            )
        })
        .collect();
    safetensors::serialize_to_file(views, None, path).unwrap();
}

/// With user-supplied VGG weights the perceptual term is in the loss curve, and `eval` with
/// LPIPS weights adds an LPIPS column; a missing weights file is an error naming the key.
#[test]
fn user_vgg_weights_add_the_perceptual_loss_and_lpips() {
    let dir = tempfile::tempdir().unwrap();
    let weights = dir.path().join("vgg16_lpips.safetensors");
    write_random_vgg(&weights);
    let out = dir.path().join("run");
    let mut cfg = config(&out, 3, RenderNet::Decomposed);
    cfg.vgg_weights = Some(weights.clone());
    let cancel = AtomicBool::new(false);
    lightfarm_trainer::train(&cfg, Catalog::builtin().unwrap(), &mut (), &cancel).expect("train");
    let losses = read_losses(&out).unwrap();
    assert_eq!(losses.len(), 3);
    for l in &losses {
        let p = l.perceptual.expect("a perceptual term in every step");
        assert!(p.is_finite() && p > 0.0, "perceptual loss {p}");
    }
    let rows = evaluate(
        std::slice::from_ref(&out),
        common::dataset(),
        "all",
        Catalog::builtin().unwrap(),
        "cpu",
        Some(&weights),
        |_, _| {},
    )
    .unwrap();
    println!("{}", table(&rows));
    assert!(table(&rows).contains("LPIPS"));
    for r in &rows {
        let l = r.lpips.expect("an LPIPS value per row");
        assert!(l.is_finite() && l > 0.0, "{}: LPIPS {l}", r.model);
    }

    let mut cfg = config(&dir.path().join("run2"), 3, RenderNet::Decomposed);
    cfg.vgg_weights = Some(dir.path().join("no-such.safetensors"));
    let err = lightfarm_trainer::train(&cfg, Catalog::builtin().unwrap(), &mut (), &cancel)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("vgg_weights") && err.contains("no-such.safetensors"),
        "{err}"
    );
}
