//! `lightfarm demo`: the one-machine case. A coordinator and a render worker run in this
//! process; a small light-stage dataset is rendered from the built-in assets, exported as a
//! folder of EXR + JSON, and shown as a contact sheet.

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
    #[arg(long, env = "LIGHTFARM_DEVICE", default_value = "auto")]
    device: String,
}

fn spec(a: &DemoArgs) -> String {
    // The paper's defaults, with accessories more frequent so a short demo shows them.
    format!(
        "name = \"demo\"\nseed = 2022\ncount = {}\nwidth = {}\nheight = {}\nspp = {}\n\
         [subject]\nglasses_probability = 0.5\nheadset_probability = 0.15\n\
         [split]\ntest_identities = [\"lee_perry_smith\"]\n",
        a.count, a.size, a.size, a.spp
    )
}

/// The passes of a sample EXR written by a worker.
fn output_from_exr(bytes: &[u8]) -> Result<RenderOutput> {
    use exr::prelude::{ReadChannels, ReadLayers};
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .context("decoding a sample EXR")?;
    let layer = &img.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let channel = |name: &str| -> Result<Vec<f32>> {
        let c = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .with_context(|| format!("sample EXR has no channel {name}"))?;
        Ok(c.sample_data.values_as_f32().collect())
    };
    let rgb = |base: &str, names: [&str; 3]| -> Result<Vec<[f32; 3]>> {
        let [a, b, c] = names.map(|n| channel(&format!("{base}.{n}")));
        let (a, b, c) = (a?, b?, c?);
        Ok((0..w * h).map(|i| [a[i], b[i], c[i]]).collect())
    };
    Ok(RenderOutput {
        width: w as u32,
        height: h as u32,
        lit: vec![rgb("lit0", ["R", "G", "B"])?, rgb("lit1", ["R", "G", "B"])?],
        albedo: rgb("albedo", ["R", "G", "B"])?,
        normal: rgb("normal", ["X", "Y", "Z"])?,
        normal_lens: rgb("normal_lens", ["X", "Y", "Z"])?,
        mask: channel("mask.A")?,
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
            triangles: 0,
        },
    })
}

pub fn run(a: DemoArgs) -> Result<()> {
    if a.count == 0 || a.count > 1000 {
        bail!("--count {} must be in 1..=1000", a.count);
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("--out {}", a.out.display()))?;
    let rt = crate::farm_cmd::runtime()?;
    rt.block_on(demo(a))
}

async fn demo(a: DemoArgs) -> Result<()> {
    let data = a.out.join("farm");
    // A fresh farm each run: the demo's job ids and samples start from zero.
    if data.exists() {
        std::fs::remove_dir_all(&data).with_context(|| format!("clearing {}", data.display()))?;
    }
    let token = format!("demo-{}", std::process::id());
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
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let server = tokio::spawn(coordinator.serve(listener, async move {
        let _ = server_stop.wait_for(|s| *s).await;
    }));

    let (ch, auth) = lightfarm_worker::client::channel(&addr, &token, None)?;
    let mut jobs = pb::jobs_client::JobsClient::with_interceptor(ch.clone(), auth.clone());
    let job = jobs
        .submit_dataset(pb::SubmitDatasetRequest {
            spec: Some(pb::submit_dataset_request::Spec::Toml(spec(&a))),
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
    while let Some(j) = watch.message().await? {
        let c = j.counts.unwrap_or_default();
        bar.set_position(c.done + c.failed);
        bar.set_message(format!("{:.2} samples/s", j.samples_per_second));
        last = Some(j);
        if worker.is_finished() {
            break;
        }
    }
    bar.finish_and_clear();
    let _ = stop_tx.send(true);
    worker.await.context("worker task")??;
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
    let _ = server_stop_tx.send(true);
    let _ = server.await;
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
    eprintln!("demo: training and relighting are not implemented yet; the exported dataset is what the trainer will read");
    Ok(())
}
