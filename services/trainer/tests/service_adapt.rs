//! Adaptation jobs on the trainer service: a completed train job adapted to a folder of real
//! photos under the datasets root, watched to the end with the adaptation's losses, listed
//! with its base, relit by its adapted checkpoint, still there (with its curve) after the
//! service reopens; and the refusals, each naming the input.

mod common;

use std::path::Path;

use lightfarm_proto::v1 as pb;
use lightfarm_trainer::service::{ServiceConfig, TrainerService};
use tonic::Code;

type Client = pb::trainer_client::TrainerClient<lightfarm_proto::client::AuthedChannel>;

fn open(data: &Path, datasets: &Path) -> TrainerService {
    TrainerService::open(ServiceConfig {
        data: data.to_owned(),
        datasets: datasets.to_owned(),
        catalog: lightfarm_scene::Catalog::builtin().expect("catalog"),
        device: "cpu".into(),
        coordinator_token: None,
    })
    .expect("service")
}

async fn serve(svc: TrainerService) -> Client {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = format!("http://{}", listener.local_addr().expect("addr"));
    tokio::spawn(svc.serve(listener, "tok", std::future::pending()));
    let (ch, auth) = lightfarm_proto::client::channel(&addr, "tok", None).expect("channel");
    pb::trainer_client::TrainerClient::with_interceptor(ch, auth)
        .max_decoding_message_size(64 << 20)
}

/// Follows a job to its end; its last state and every loss point seen.
async fn watch(c: &mut Client, id: &str) -> (pb::TrainJob, Vec<pb::LossPoint>) {
    let mut stream = c
        .watch_train_job(pb::TrainJobRef { job_id: id.into() })
        .await
        .expect("watch")
        .into_inner();
    let (mut last, mut points) = (None, Vec::new());
    while let Some(p) = stream.message().await.expect("stream") {
        points.extend(p.losses);
        last = p.job;
    }
    (last.expect("a job"), points)
}

/// The three public-domain portraits at 96² in `dir`.
fn photos(dir: &Path) {
    std::fs::create_dir_all(dir).expect("mkdir");
    for name in ["astronaut.png", "camera.png", "grace_hopper.jpg"] {
        let src = lightfarm_scene::catalog::builtin_assets_dir()
            .join("photos")
            .join(name);
        image::open(&src)
            .unwrap_or_else(|e| panic!("{}: {e}; run ./scripts/fetch-models.sh", src.display()))
            .resize_exact(96, 96, image::imageops::FilterType::Triangle)
            .to_rgb8()
            .save(dir.join(name).with_extension("png"))
            .expect("save");
    }
}

const ADAPT: &str = "batch = 2\nsize = 32\ncheckpoint_every = 2\n\
    hdris = [\"studio_small_03\", \"venice_sunset\"]\ncritic_width = 8\nolat_lights = 8\n\
    vgg_weights = \"none\"\n[weights]\nsimilarity = 0\nidentity = 0\n[adapter]\nbase = 4\nblocks = 2\n";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_train_job_adapted_to_photos() {
    let datasets = tempfile::tempdir().expect("tmp");
    #[cfg(unix)]
    std::os::unix::fs::symlink(common::dataset(), datasets.path().join("export")).expect("link");
    photos(&datasets.path().join("portraits"));
    let data = tempfile::tempdir().expect("tmp");
    let mut c = serve(open(data.path(), datasets.path())).await;

    let train = c
        .submit_train_job(pb::SubmitTrainJobRequest {
            config_toml: "loader_threads = 1\nvgg_weights = \"none\"\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n".into(),
            dataset: "export".into(),
            split: "all".into(),
            steps: 3,
            batch: 2,
        })
        .await
        .expect("train job")
        .into_inner();
    let submit = |base: &str, photos: &str, config: &str| pb::SubmitAdaptJobRequest {
        config_toml: config.into(),
        base_job_id: base.into(),
        photos: photos.into(),
        steps: 4,
    };
    // While the train job has not ended its model is not final: refused.
    let early = c
        .submit_adapt_job(submit(&train.id, "portraits", ADAPT))
        .await;
    let (train_end, _) = watch(&mut c, &train.id).await;
    assert_eq!(
        train_end.state,
        pb::TrainJobState::Completed as i32,
        "{train_end:?}"
    );
    if let Err(e) = early {
        assert_eq!(e.code(), Code::FailedPrecondition, "{e}");
        assert!(e.message().contains("has not ended"), "{e}");
    }

    let job = c
        .submit_adapt_job(submit(&train.id, "portraits", ADAPT))
        .await
        .expect("adapt job")
        .into_inner();
    assert_eq!(job.kind, pb::TrainJobKind::Adapt as i32);
    assert!(job.id.starts_with("adapt-"), "{}", job.id);
    assert_eq!(job.base_job_id, train.id);
    assert!(
        Path::new(&job.base_checkpoint)
            .join("model.safetensors")
            .is_file(),
        "{job:?}"
    );
    let (end, points) = watch(&mut c, &job.id).await;
    assert_eq!(end.state, pb::TrainJobState::Completed as i32, "{end:?}");
    let mut steps: Vec<u64> = points.iter().map(|p| p.step).collect();
    steps.dedup();
    assert_eq!(steps, vec![1, 2, 3, 4]);
    for p in &points {
        assert!(
            p.total.is_finite() && p.olat > 0.0 && p.relative >= 0.0,
            "{p:?}"
        );
        assert_eq!(
            (p.similarity, p.identity, p.skipped_photos),
            (0.0, 0.0, 0),
            "{p:?}"
        );
    }
    // f_Ā starts at zero, so R̄ = R and the relative term is 0 until the first update.
    assert!(points.iter().any(|p| p.relative > 0.0), "{points:?}");

    // The adapted model relights through the same call as a trained one.
    let mut png = Vec::new();
    image::open(datasets.path().join("portraits/astronaut.png"))
        .expect("photo")
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("png");
    let relit = c
        .relight(pb::RelightRequest {
            job_id: job.id.clone(),
            image: png,
            mask: Vec::new(),
            lighting: Some(pb::relight_request::Lighting::HdriId(
                "studio_small_03".into(),
            )),
            rotation_deg: 0.0,
            flip: false,
            no_matte: true,
        })
        .await
        .expect("relight")
        .into_inner();
    assert_eq!((relit.width, relit.height), (96, 96));

    // Refusals, each naming what is wrong.
    let cases = [
        (
            submit("", "portraits", ADAPT),
            Code::InvalidArgument,
            "base_job_id",
        ),
        (
            submit("train-999999", "portraits", ADAPT),
            Code::NotFound,
            "train-999999",
        ),
        (
            submit(&job.id, "portraits", ADAPT),
            Code::InvalidArgument,
            "adaptation job",
        ),
        (
            submit(&train.id, "../portraits", ADAPT),
            Code::InvalidArgument,
            "../portraits",
        ),
        (
            submit(&train.id, "nowhere", ADAPT),
            Code::FailedPrecondition,
            "nowhere",
        ),
        (
            submit(&train.id, "portraits", "assets = \"/elsewhere\"\n"),
            Code::InvalidArgument,
            "assets",
        ),
        (
            submit(&train.id, "portraits", "size = 7\n"),
            Code::InvalidArgument,
            "size = 7",
        ),
    ];
    for (req, code, names) in cases {
        let e = c.submit_adapt_job(req).await.expect_err("refused");
        assert_eq!(e.code(), code, "{e}");
        assert!(e.message().contains(names), "{names}: {e}");
    }

    // A reopened service knows the job, its kind, base and curve.
    let mut again = serve(open(data.path(), datasets.path())).await;
    let listed = again
        .list_train_jobs(pb::ListTrainJobsRequest {})
        .await
        .expect("list")
        .into_inner()
        .jobs;
    let adapt = listed.iter().find(|j| j.id == job.id).expect("listed");
    assert_eq!(
        (adapt.kind, adapt.step),
        (pb::TrainJobKind::Adapt as i32, 4)
    );
    assert_eq!(adapt.base_job_id, train.id);
    let (_, curve) = watch(&mut again, &job.id).await;
    assert_eq!(curve.len(), 4);
    assert!(curve.iter().all(|p| p.olat > 0.0));
}
