//! `lightfarm demo`: the one-machine case. A coordinator and a render worker run in this
//! process; a small light-stage dataset is rendered from the built-in assets, exported as a
//! folder of EXR + JSON, and shown as a contact sheet; then the relighting network trains on it
//! briefly, relights a held-out sample and is scored on the test split.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_proto::v1 as pb;
use lightfarm_render::{RenderOutput, RenderStats};
use lightfarm_scene::Catalog;

use crate::sheet::{tiles, Sheet};

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output directory: farm data, the exported dataset, the contact sheet.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Samples to render.
    #[arg(long, default_value_t = 8)]
    count: u64,
    /// Image size (square).
    #[arg(long, default_value_t = 128)]
    size: u32,
    #[arg(long, default_value_t = 32)]
    spp: u32,
    /// Also render each sample under this many OLAT lights of the virtual light stage (0: no;
    /// the paper's is 168), for `lightfarm relight-olat`.
    #[arg(long, default_value_t = 0)]
    olat: u32,
    #[arg(long, env = "LIGHTFARM_DEVICE", default_value = "auto")]
    device: String,
    /// Training steps after rendering (0 skips training and relighting).
    #[arg(long, default_value_t = 300)]
    train_steps: u64,
    /// Where the networks train: auto, cpu or gpu.
    #[arg(long, env = "LIGHTFARM_TRAIN_DEVICE", default_value = "auto")]
    train_device: String,
    /// Serve the farm's web dashboard here while the demo renders ("off": do not).
    #[arg(long, default_value = "127.0.0.1:0")]
    dashboard: String,
    /// Keep the dashboard up this many seconds after the render (to look around).
    #[arg(long, default_value_t = 0)]
    dashboard_linger: u64,
    /// The dashboard's login token (default: a new one per run, printed).
    #[arg(long, env = "LIGHTFARM_DEMO_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

fn spec(a: &DemoArgs) -> String {
    // The paper's defaults, with accessories more frequent so a short demo shows them.
    format!(
        "name = \"demo\"\nseed = 2022\ncount = {}\nwidth = {}\nheight = {}\nspp = {}\n\
         [subject]\nglasses_probability = 0.5\nheadset_probability = 0.15\n\
         [split]\ntest_identities = [\"lee_perry_smith\"]\n[lighting]\nolat = {}\n",
        a.count, a.size, a.size, a.spp, a.olat
    )
}

/// The passes of a sample EXR written by a worker, as the contact sheet draws them.
fn output_from_exr(bytes: &[u8]) -> Result<RenderOutput> {
    let s = lightfarm_trainer::sample::decode_sample(bytes, "demo sample")?;
    let (w, h) = (s.width, s.height);
    Ok(RenderOutput {
        width: w as u32,
        height: h as u32,
        lit: Vec::from(s.lit),
        albedo: s.albedo,
        normal: s.normal,
        normal_lens: s.normal_lens,
        mask: s.mask,
        // The contact sheet draws the contract's passes only.
        pass_set: Vec::new(),
        passes: Vec::new(),
        id: Vec::new(),
        stats: RenderStats {
            seconds: 0.0,
            samples: 0,
            samples_per_second: 0.0,
            rays: 0,
            rays_per_second: 0.0,
            device: String::new(),
            device_kind: String::new(),
            width: w as u32,
            height: h as u32,
            spp: 0,
            lightings: 2,
            lightings_per_path: 0,
            triangles: 0,
            curve_segments: 0,
            geometry_bytes: 0,
            olat_lights: 0,
            olat_seconds: 0.0,
        },
        traversal: None,
        olat: Vec::new(),
    })
}

pub fn run(a: DemoArgs) -> Result<()> {
    if a.count == 0 || a.count > 1000 {
        bail!("--count {} must be in 1..=1000", a.count);
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("--out {}", a.out.display()))?;
    let rt = crate::farm_cmd::runtime()?;
    rt.block_on(demo(&a))?;
    if a.train_steps > 0 {
        train_and_relight(&a)?;
    }
    Ok(())
}

async fn demo(a: &DemoArgs) -> Result<()> {
    let data = a.out.join("farm");
    // A fresh farm each run: the demo's job ids and samples start from zero.
    if data.exists() {
        std::fs::remove_dir_all(&data).with_context(|| format!("clearing {}", data.display()))?;
    }
    let token = a
        .token
        .clone()
        .unwrap_or_else(|| format!("demo-{}", std::process::id()));
    let config = lightfarm_coordinator::CoordinatorConfig::new(
        data.clone(),
        token.clone(),
        Catalog::builtin()?,
    );
    let coordinator =
        tokio::task::spawn_blocking(move || lightfarm_coordinator::Coordinator::open(config))
            .await??;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = format!("http://{}", listener.local_addr()?);
    let (server_stop_tx, mut server_stop) = tokio::sync::watch::channel(false);
    let dashboard = if a.dashboard == "off" {
        None
    } else {
        let web = tokio::net::TcpListener::bind(&a.dashboard)
            .await
            .with_context(|| format!("--dashboard {}: cannot bind", a.dashboard))?;
        eprintln!(
            "demo: dashboard on http://{} (log in with the token {token})",
            web.local_addr()?
        );
        let board = coordinator.dashboard(&lightfarm_coordinator::dashboard::DashboardConfig {
            token: token.clone(),
            secure_cookies: false,
            trainer: None,
        })?;
        let mut stop = server_stop.clone();
        Some(tokio::spawn(lightfarm_coordinator::metrics::serve_metrics(
            web,
            coordinator.metrics().clone(),
            coordinator.scheduler().clone(),
            Some(board),
            None,
            async move {
                let _ = stop.wait_for(|s| *s).await;
            },
        )))
    };
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let server = tokio::spawn(coordinator.serve(listener, async move {
        let _ = server_stop.wait_for(|s| *s).await;
    }));

    let (ch, auth) = lightfarm_worker::client::channel(&addr, &token, None)?;
    let mut jobs = pb::jobs_client::JobsClient::with_interceptor(ch.clone(), auth.clone());
    let job = jobs
        .submit_dataset(pb::SubmitDatasetRequest {
            spec: Some(pb::submit_dataset_request::Spec::Toml(spec(a))),
            priority: 0,
        })
        .await?
        .into_inner();
    eprintln!("demo: rendering {} samples ({}², {} spp, two lightings each) with an in-process coordinator and worker", job.count, a.size, a.spp);

    let mut worker_stop = stop_rx.clone();
    let worker = tokio::spawn(lightfarm_worker::run(
        lightfarm_worker::WorkerConfig {
            coordinator: addr.clone(),
            token: token.clone(),
            name: "demo-worker".into(),
            cache_dir: a.out.join("worker-cache"),
            device: a.device.clone(),
            tls_ca: None,
            max_samples: None,
        },
        async move {
            let _ = worker_stop.wait_for(|s| *s).await;
        },
    ));

    let bar = ProgressBar::new(job.count);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} samples  {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    let mut watch = jobs
        .watch_job(pb::JobRef {
            job_id: job.id.clone(),
        })
        .await?
        .into_inner();
    let mut last = None;
    let mut worker = worker;
    let mut worker_result = None;
    // A worker that fails (no usable device, say) ends before the job does: stop waiting for
    // progress then, and report why.
    loop {
        tokio::select! {
            msg = watch.message() => match msg? {
                Some(j) => {
                    let c = j.counts.unwrap_or_default();
                    bar.set_position(c.done + c.failed);
                    bar.set_message(format!("{:.2} samples/s", j.samples_per_second));
                    last = Some(j);
                }
                None => break,
            },
            r = &mut worker => {
                worker_result = Some(r);
                break;
            }
        }
    }
    bar.finish_and_clear();
    let _ = stop_tx.send(true);
    let worker_result = match worker_result {
        Some(r) => r,
        None => worker.await,
    };
    worker_result
        .context("worker task")?
        .context("the demo's render worker stopped")?;
    let last = last.context("no progress from the coordinator")?;
    if last.state != pb::JobState::Completed as i32 {
        for f in &last.failures {
            eprintln!("sample {}: {}", f.index, f.reason);
        }
        bail!("the demo job did not complete: {last:?}");
    }

    // Export the committed samples as a folder and draw a contact sheet from them.
    let mut samples = pb::samples_client::SamplesClient::with_interceptor(ch, auth)
        .max_decoding_message_size(64 << 20);
    let mut stream = samples
        .stream_samples(pb::StreamSamplesRequest {
            job_id: job.id.clone(),
            split: String::new(),
            cursor: 0,
            follow: false,
            metadata_only: false,
        })
        .await?
        .into_inner();
    let dataset = a.out.join("dataset");
    let mut writer = lightfarm_store::ExportWriter::create(
        &dataset,
        &job.id,
        &lightfarm_store::ExportFormat::Folder,
    )?;
    let mut assembler = lightfarm_coordinator::service::SampleAssembler::default();
    let mut received = Vec::new();
    while let Some(chunk) = stream.message().await? {
        received.extend(assembler.push(chunk).map_err(anyhow::Error::msg)?);
    }
    received.extend(assembler.finish());
    received.sort_by_key(|(r, _)| r.index);
    let mut sheet = Sheet::new(received.len() as u32, a.size, a.size);
    for (row, (info, bytes)) in received.iter().enumerate() {
        writer.add(info, bytes)?;
        let meta: serde_json::Value = serde_json::from_str(&info.metadata_json).unwrap_or_default();
        let s = &meta["sample"];
        let caption = format!(
            "#{} {} {} hair {} {}{}",
            info.index,
            s["head"]["id"].as_str().unwrap_or("?"),
            info.split,
            s["hair"]["style"].as_str().unwrap_or("?"),
            s["glasses"]["id"].as_str().unwrap_or(""),
            if s["headset"].is_object() {
                " headset"
            } else {
                ""
            }
        );
        sheet.row(row as u32, &caption, &tiles(&output_from_exr(bytes)?));
    }
    let report = writer.finish()?;
    if dashboard.is_some() && a.dashboard_linger > 0 {
        eprintln!(
            "demo: the dashboard stays up {} s more (Ctrl-C ends it)",
            a.dashboard_linger
        );
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_secs(a.dashboard_linger)) => {}
            _ = crate::farm_cmd::shutdown_signal() => {}
        }
    }
    let _ = server_stop_tx.send(true);
    let _ = server.await;
    if let Some(d) = dashboard {
        let _ = d.await;
    }
    let sheet_path = a.out.join("sheet.png");
    image::RgbImage::from_raw(sheet.width, sheet.height, sheet.pixels)
        .context("sheet size")?
        .save_with_format(&sheet_path, image::ImageFormat::Png)
        .with_context(|| sheet_path.display().to_string())?;
    eprintln!(
        "demo: {} samples in {} ({} files, {:.1} MB), contact sheet {}",
        report.samples,
        dataset.display(),
        report.files.len(),
        report.bytes as f64 / 1e6,
        sheet_path.display()
    );
    Ok(())
}

/// Trains the tiny network on the exported dataset, relights a held-out sample under another
/// HDRI and scores the test split: the whole pipeline in a couple of minutes on a CPU.
fn train_and_relight(a: &DemoArgs) -> Result<()> {
    use lightfarm_trainer::config::{NetConfig, TrainConfig};
    let dataset = a.out.join("dataset");
    let run = a.out.join("train");
    if run.exists() {
        std::fs::remove_dir_all(&run).with_context(|| format!("clearing {}", run.display()))?;
    }
    let crop = (a.size as usize).min(64) / 4 * 4;
    let entries = lightfarm_store::list_export_folder(&dataset)?;
    let has = |split: &str| entries.iter().any(|e| e.split == split);
    // A very small demo may draw no held-out identity, or nothing else; use what there is.
    let train_split = if has("train") { "train" } else { "all" };
    let eval_split = if has("test") { "test" } else { "all" };
    let mut cfg: TrainConfig = toml::from_str(&format!(
        "dataset = {:?}\nout = {:?}\nsplit = {train_split:?}\nsteps = {}\nbatch = 4\ncrop = {crop}\nlr = 2e-3\ncheckpoint_every = 50\ndevice = {:?}\n",
        dataset, run, a.train_steps, a.train_device
    ))?;
    cfg.net = NetConfig {
        widths: vec![8, 16, 32],
        critic_width: 8,
        ..NetConfig::default()
    };
    // The paper's perceptual loss when its pretrained weights are installed; the demo still
    // runs without them.
    if !lightfarm_nets::vgg::builtin_weights().is_file() {
        eprintln!(
            "demo: training without the perceptual loss: its weights are not installed ({})",
            lightfarm_nets::vgg::BUILTIN_WEIGHTS_FIX
        );
        cfg.vgg_weights = Some(lightfarm_trainer::config::VGG_NONE.into());
    }
    cfg.validate().map_err(anyhow::Error::msg)?;
    eprintln!("demo: training the relighting network ({} steps, widths {:?}, {crop}² crops) on the train split", cfg.steps, cfg.net.widths);
    let bar = ProgressBar::new(cfg.steps).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    struct Obs(ProgressBar);
    impl lightfarm_trainer::Observer for Obs {
        fn on_step(&mut self, l: &lightfarm_trainer::StepLog) {
            self.0.set_position(l.step);
            self.0.set_message(format!("loss {:.4}", l.total));
        }
    }
    let stop = std::sync::atomic::AtomicBool::new(false);
    let summary =
        lightfarm_trainer::train(&cfg, Catalog::builtin()?, &mut Obs(bar.clone()), &stop)?;
    bar.finish_and_clear();
    let losses = lightfarm_trainer::train::read_losses(&run)?;
    if let (Some(first), Some(last)) = (losses.first(), losses.last()) {
        eprintln!(
            "demo: loss {:.4} → {:.4}; checkpoint {}",
            first.total,
            last.total,
            summary.checkpoint.display()
        );
    }

    // Relight a held-out (test split) sample under an HDRI it was not rendered with.
    let entry = entries
        .iter()
        .find(|e| e.split == "test")
        .or(entries.first())
        .context("the demo dataset is empty")?;
    let bytes = std::fs::read(&entry.exr).with_context(|| entry.exr.display().to_string())?;
    let sample =
        lightfarm_trainer::sample::decode_sample(&bytes, &entry.exr.display().to_string())?;
    let used: Vec<&str> = sample
        .spec
        .lighting
        .iter()
        .map(|l| l.hdri.as_str())
        .collect();
    let catalog = Catalog::builtin()?;
    let hdri = catalog
        .of_kind(lightfarm_scene::AssetKind::Hdri)
        .into_iter()
        .find(|h| !used.contains(&h.id.as_str()))
        .context("the catalog needs a third HDRI")?
        .id
        .clone();
    let relit = a.out.join("relit.png");
    crate::train_cmd::relight(crate::train_cmd::RelightArgs {
        model: run.clone(),
        image: entry.exr.clone(),
        mask: None,
        no_matte: false,
        target: crate::olat_cmd::TargetHdri {
            hdri: hdri.clone(),
            rotation: 0.0,
            flip: false,
            assets: None,
        },
        out: relit.clone(),
        device: a.train_device.clone(),
    })?;
    eprintln!(
        "demo: relit sample {} ({}) under {hdri}: {}",
        entry.index,
        entry.split,
        relit.display()
    );
    // The demo runs without the pretrained weights too: LPIPS joins the table once installed.
    let lpips = if lightfarm_nets::vgg::builtin_weights().is_file() {
        "builtin"
    } else {
        eprintln!(
            "demo: evaluating without LPIPS: its weights are not installed ({})",
            lightfarm_nets::vgg::BUILTIN_WEIGHTS_FIX
        );
        "none"
    };
    crate::train_cmd::eval(crate::train_cmd::EvalArgs {
        model: vec![run],
        dataset: Some(dataset),
        split: eval_split.into(),
        json: Some(a.out.join("eval.json")),
        device: a.train_device.clone(),
        assets: None,
        lpips: lpips.into(),
        real: None,
        lightings: 4,
        size: 256,
        seed: 0,
    })
}
