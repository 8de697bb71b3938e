//! The trainer's gRPC surface in process: submit, watch to the end, checkpoints, relight, and
//! refusals (token, dataset path, unknown job).

mod common;

use lightfarm_proto::v1 as pb;
use lightfarm_trainer::service::{ServiceConfig, TrainerService};
use tonic::metadata::MetadataValue;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;
use tonic::{Code, Request, Status};

type Auth = Box<dyn Fn(Request<()>) -> Result<Request<()>, Status> + Send + Sync>;
type Client = pb::trainer_client::TrainerClient<InterceptedService<Channel, Auth>>;

async fn client(addr: &str, token: &str) -> Client {
    let ch = Channel::from_shared(addr.to_owned())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let value: MetadataValue<_> = format!("Bearer {token}").parse().unwrap();
    let auth: Auth = Box::new(move |mut r: Request<()>| {
        r.metadata_mut().insert("authorization", value.clone());
        Ok(r)
    });
    pb::trainer_client::TrainerClient::with_interceptor(ch, auth)
        .max_decoding_message_size(64 << 20)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn submit_watch_checkpoints_and_relight() {
    let dataset = common::dataset();
    let data = tempfile::tempdir().unwrap();
    let svc = TrainerService::open(ServiceConfig {
        data: data.path().to_owned(),
        datasets: dataset.parent().unwrap().to_owned(),
        catalog: lightfarm_scene::Catalog::builtin().unwrap(),
        device: "cpu".into(),
        coordinator_token: None,
    })
    .unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = format!("http://{}", listener.local_addr().unwrap());
    tokio::spawn(svc.serve(listener, "s3cret", std::future::pending()));

    let mut c = client(&addr, "s3cret").await;
    let submit = |dataset: &str, steps| {
        pb::SubmitTrainJobRequest {
        config_toml: "checkpoint_every = 3\nloader_threads = 1\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n".into(),
        dataset: dataset.into(),
        split: "all".into(),
        steps,
        batch: 2,
    }
    };
    let job = c
        .submit_train_job(submit("export", 7))
        .await
        .unwrap()
        .into_inner();
    let mut watch = c
        .watch_train_job(pb::TrainJobRef {
            job_id: job.id.clone(),
        })
        .await
        .unwrap()
        .into_inner();
    let mut steps = Vec::new();
    let mut last = None;
    while let Some(p) = watch.message().await.unwrap() {
        steps.extend(p.losses.iter().map(|l| l.step));
        last = p.job;
    }
    let last = last.unwrap();
    assert_eq!(last.state, pb::TrainJobState::Completed as i32, "{last:?}");
    steps.dedup();
    assert_eq!(steps, (1..=7).collect::<Vec<u64>>());

    let cks = c
        .list_checkpoints(pb::TrainJobRef {
            job_id: job.id.clone(),
        })
        .await
        .unwrap()
        .into_inner()
        .checkpoints;
    assert!(cks.iter().any(|c| c.latest && c.step == 7), "{cks:?}");

    let mut png = Vec::new();
    image::RgbaImage::from_fn(24, 16, |x, y| {
        image::Rgba([
            (x * 10) as u8,
            (y * 15) as u8,
            90,
            if x > 3 { 255 } else { 0 },
        ])
    })
    .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
    .unwrap();
    let relight = |hdri: &str| pb::RelightRequest {
        job_id: job.id.clone(),
        image: png.clone(),
        mask: Vec::new(),
        lighting: Some(pb::relight_request::Lighting::HdriId(hdri.into())),
        rotation_deg: 45.0,
        flip: false,
        no_matte: false,
    };
    let park = c
        .relight(relight("rooitou_park"))
        .await
        .unwrap()
        .into_inner();
    let studio = c
        .relight(relight("studio_small_03"))
        .await
        .unwrap()
        .into_inner();
    for r in [&park, &studio] {
        assert_eq!((r.width, r.height), (24, 16));
        for bytes in [
            &r.relit_png,
            &r.normal_png,
            &r.albedo_png,
            &r.diffuse_png,
            &r.specular_png,
            &r.mask_png,
        ] {
            let img = image::load_from_memory(bytes).expect("a PNG");
            assert_eq!((img.width(), img.height()), (24, 16));
        }
        // The image's alpha is the foreground, not a matte; the mask PNG is that alpha.
        assert!(!r.matted);
        let mask = image::load_from_memory(&r.mask_png)
            .expect("png")
            .to_luma8();
        assert_eq!(mask.get_pixel(3, 5)[0], 0);
        assert_eq!(mask.get_pixel(4, 5)[0], 255);
    }
    // Without a mask the request image's alpha is the mask (0 for x <= 3). The relit image is
    // the network's output times the mask, so those columns are black; the light-ball inset
    // (x >= 8, y >= 8 at 24×16) does not reach them.
    let in_inset =
        |x: u32, y: u32| lightfarm_trainer::infer::in_inset(24, 16, x as usize, y as usize);
    assert!(
        in_inset(8, 8) && !in_inset(7, 15) && !in_inset(23, 7),
        "the inset is x >= 8, y >= 8"
    );
    let decode = |bytes: &[u8]| image::load_from_memory(bytes).expect("relit PNG").to_rgb8();
    let (a, b) = (decode(&park.relit_png), decode(&studio.relit_png));
    let subject: Vec<(u32, u32)> = (0..16)
        .flat_map(|y| (4..24).map(move |x| (x, y)))
        .filter(|&(x, y)| !in_inset(x, y))
        .collect();
    for img in [&a, &b] {
        for y in 0..16 {
            for x in 0..4 {
                assert_eq!(
                    img.get_pixel(x, y).0,
                    [0, 0, 0],
                    "({x}, {y}) is off the mask"
                );
            }
        }
        assert!(
            subject
                .iter()
                .any(|&(x, y)| img.get_pixel(x, y).0 != [0, 0, 0]),
            "the relit subject is all black"
        );
    }
    assert!(
        subject
            .iter()
            .any(|&(x, y)| a.get_pixel(x, y) != b.get_pixel(x, y)),
        "two HDRIs relit the subject identically"
    );

    // Refusals.
    let err = c
        .submit_train_job(submit("../escape", 5))
        .await
        .unwrap_err();
    assert_eq!(err.code(), Code::InvalidArgument, "{err}");
    let err = c.submit_train_job(submit("nowhere", 5)).await.unwrap_err();
    assert_eq!(err.code(), Code::FailedPrecondition, "{err}");
    assert!(err.message().contains("lightfarm export"), "{err}");
    let err = c
        .watch_train_job(pb::TrainJobRef {
            job_id: "train-999".into(),
        })
        .await
        .unwrap_err();
    assert_eq!(err.code(), Code::NotFound);
    let err = c
        .relight(pb::RelightRequest {
            job_id: job.id.clone(),
            image: b"junk".to_vec(),
            mask: vec![],
            lighting: Some(pb::relight_request::Lighting::HdriId("rooitou_park".into())),
            rotation_deg: 0.0,
            flip: false,
            no_matte: false,
        })
        .await
        .unwrap_err();
    assert_eq!(err.code(), Code::InvalidArgument, "{err}");
    let mut wrong = client(&addr, "guess").await;
    let err = wrong
        .list_train_jobs(pb::ListTrainJobsRequest {})
        .await
        .unwrap_err();
    assert_eq!(err.code(), Code::Unauthenticated);
}
