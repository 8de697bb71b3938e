//! The Python client (clients/python) against an in-process coordinator and render worker:
//! `clients/python/tests/farm_check.py` submits a spec from Python, watches it to completion,
//! streams every sample once (stopped after two and resumed from its cursor), follows a stream
//! through a coordinator restart that this test performs, runs the torch IterableDataset with
//! 2 workers x 2 ranks, trains on the job through an in-process trainer service and relights a
//! sample with the result, and records three errors. This test then checks what it wrote: every
//! array equal bit for bit to the Rust trainer's decoding of the same EXR, every sample's
//! metadata equal to `spec expand` for its index, the folder and WebDataset readers giving the
//! stream's arrays, and the errors worded as the CLI words them.
//!
//! The Python environment comes from ./scripts/setup-python-client.sh
//! ($LIGHTFARM_CACHE/venv-client, or LIGHTFARM_PYTHON); without it the test skips, except
//! under CI, where it fails.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use lightfarm_integration::{Farm, TOKEN};

const SPEC: &str = "name = \"python\"\nseed = 11\ncount = 4\nwidth = 16\nheight = 16\nspp = 1\n";

fn python() -> Option<PathBuf> {
    let venv = std::env::var_os("LIGHTFARM_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let cache = std::env::var_os("LIGHTFARM_CACHE")
                .map(PathBuf::from)
                .unwrap_or_else(|| {
                    PathBuf::from(std::env::var_os("HOME").unwrap_or_default())
                        .join(".cache/lightfarm")
                });
            cache.join("venv-client/bin/python")
        });
    let ok = Command::new(&venv)
        .args(["-c", "import lightfarm.v1.jobs_pb2"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(venv);
    }
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false");
    assert!(
        !ci,
        "{} has no lightfarm package: run ./scripts/setup-python-client.sh",
        venv.display()
    );
    eprintln!(
        "skipping: no Python client ({}); run ./scripts/setup-python-client.sh",
        venv.display()
    );
    None
}

fn npy(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let file = npyz::NpyFile::new(&bytes[..]).expect("npy");
    let shape = file.shape().to_vec();
    (shape, file.into_vec::<f32>().expect("f32 data"))
}

fn flat3(v: &[[f32; 3]]) -> Vec<f32> {
    v.iter().flatten().copied().collect()
}

fn cli(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_lightfarm-under-test"))
        .args(args)
        .output()
        .expect("run lightfarm");
    assert!(!out.status.success(), "{args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn the_python_client_submits_watches_and_streams_samples() {
    let Some(python) = python() else {
        return;
    };
    let script_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../clients/python/tests");
    let offline = Command::new(&python)
        .args(["-m", "unittest", "discover", "-s"])
        .arg(&script_dir)
        .args(["-p", "test_*.py"])
        .output()
        .expect("python -m unittest");
    assert!(
        offline.status.success(),
        "the client's offline tests: {}",
        String::from_utf8_lossy(&offline.stderr)
    );
    let mut farm = Farm::start();
    // A trainer service in process, for the client's train and relight calls.
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let trainer = rt.block_on(async {
        let svc = lightfarm_trainer::service::TrainerService::open(
            lightfarm_trainer::service::ServiceConfig {
                data: farm.dir.path().join("trainer"),
                datasets: farm.dir.path().to_owned(),
                catalog: lightfarm_scene::Catalog::builtin().expect("catalog"),
                device: "cpu".into(),
                coordinator_token: Some(TOKEN.into()),
            },
        )
        .expect("trainer");
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let url = format!("http://{}", listener.local_addr().expect("addr"));
        tokio::spawn(svc.serve(listener, TOKEN, std::future::pending()));
        url
    });
    let spec = farm.dir.path().join("python.toml");
    std::fs::write(&spec, SPEC).expect("spec");
    let out = farm.dir.path().join("python-out");
    let worker = farm.spawn_worker("py-worker", 4);
    let script = script_dir.join("farm_check.py");
    let mut child = Command::new(&python)
        .arg(&script)
        .args([&farm.url(), TOKEN])
        .arg(&spec)
        .arg(&out)
        .arg(&trainer)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("run python");
    let mut stdin = child.stdin.take().expect("stdin");
    let lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let mut said = Vec::new();
    for line in lines {
        let line = line.expect("a line from python");
        eprintln!("python: {line}");
        if line == "RESTART ME" {
            farm.stop_coordinator();
            writeln!(stdin, "go").expect("write");
            stdin.flush().expect("flush");
            std::thread::sleep(Duration::from_secs(2));
            farm.start_coordinator();
        }
        said.push(line);
    }
    let status = child.wait().expect("python");
    assert!(status.success(), "the Python checks failed: {said:?}");
    assert_eq!(said.last().map(String::as_str), Some("done"), "{said:?}");
    farm.join(worker);

    // The README's example: submit a spec and train a toy model on the stream as it renders.
    let toy_spec = farm.dir.path().join("toy.toml");
    std::fs::write(
        &toy_spec,
        SPEC.replace("count = 4", "count = 2")
            .replace("seed = 11", "seed = 12"),
    )
    .expect("spec");
    let worker = farm.spawn_worker("toy-worker", 2);
    let toy = Command::new(&python)
        .arg(script_dir.join("../examples/train_toy.py"))
        .args([&farm.url(), TOKEN])
        .arg(&toy_spec)
        .output()
        .expect("train_toy.py");
    let toy_said = String::from_utf8_lossy(&toy.stdout);
    assert!(
        toy.status.success() && toy_said.matches(": loss ").count() >= 1,
        "{toy_said}{}",
        String::from_utf8_lossy(&toy.stderr)
    );
    farm.join(worker);

    // The same EXRs decoded by the Rust trainer: equal bit for bit; metadata = spec expand.
    let job = said
        .first()
        .and_then(|l| l.split_whitespace().nth(1))
        .expect("the job id")
        .to_owned();
    let export = farm.export_folder(&job, &farm.dir.path().join("export"));
    let shards = farm.export(
        &job,
        &farm.dir.path().join("shards"),
        &lightfarm_store::ExportFormat::WebDataset {
            samples_per_shard: 3,
        },
    );
    // The export readers give what the stream gave.
    let read = Command::new(&python)
        .arg(script_dir.join("export_check.py"))
        .arg(&export)
        .arg(&shards)
        .arg(out.join("exports"))
        .output()
        .expect("export_check.py");
    assert!(
        read.status.success(),
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    for reader in ["folder", "webdataset"] {
        for index in 0..4u64 {
            for pass in ["lit0", "lit1", "albedo", "normal", "normal_lens", "mask"] {
                let streamed = npy(&out.join(format!("{index}/{pass}.npy")));
                let exported = npy(&out.join(format!("exports/{reader}/{index}/{pass}.npy")));
                assert!(
                    streamed.0 == exported.0
                        && streamed
                            .1
                            .iter()
                            .zip(&exported.1)
                            .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{reader}: {pass} of sample {index} differs from the stream's"
                );
            }
        }
    }
    let resolved = lightfarm_scene::spec::DatasetSpec::from_toml_str(SPEC, "python.toml")
        .and_then(|s| s.validate(&lightfarm_scene::Catalog::builtin().expect("catalog")))
        .expect("spec");
    for index in 0..4u64 {
        let exr = export.join(format!("{index:08}.exr"));
        let bytes = std::fs::read(&exr).expect("exported EXR");
        let rust = lightfarm_trainer::sample::decode_sample(&bytes, "exported").expect("decode");
        let dir = out.join(index.to_string());
        let (w, h) = (rust.width as u64, rust.height as u64);
        for (name, want) in [
            ("lit0", flat3(&rust.lit[0])),
            ("lit1", flat3(&rust.lit[1])),
            ("albedo", flat3(&rust.albedo)),
            ("normal", flat3(&rust.normal)),
            ("normal_lens", flat3(&rust.normal_lens)),
        ] {
            let (shape, got) = npy(&dir.join(format!("{name}.npy")));
            assert_eq!(shape, [h, w, 3], "{name} of sample {index}");
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(
                same && got.len() == want.len(),
                "{name} of sample {index} differs"
            );
        }
        let (shape, mask) = npy(&dir.join("mask.npy"));
        assert_eq!(shape, [h, w]);
        assert!(mask
            .iter()
            .zip(&rust.mask)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).expect("meta"))
                .expect("json");
        let expanded = lightfarm_scene::expand::expand(&resolved, index).expect("expand");
        assert_eq!(
            meta["metadata"]["sample"],
            serde_json::to_value(&expanded).expect("json"),
            "sample {index}'s metadata is `spec expand`'s"
        );
    }

    // The errors say what the CLI says.
    let errors: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("errors.json")).expect("errors.json"),
    )
    .expect("json");
    let url = farm.url();
    let said_by_cli = [
        (
            "wrong_token",
            cli(&["jobs", "--coordinator", &url, "--token", "not-the-token"]),
        ),
        (
            "unknown_job",
            cli(&[
                "watch",
                "no-such-job",
                "--coordinator",
                &url,
                "--token",
                TOKEN,
            ]),
        ),
        (
            "bad_spec",
            cli(&[
                "submit",
                out.join("bad.toml").to_str().expect("utf8"),
                "--coordinator",
                &url,
                "--token",
                TOKEN,
            ]),
        ),
    ];
    for (key, cli_said) in said_by_cli {
        let py = errors[key]
            .as_str()
            .unwrap_or_else(|| panic!("no {key} error: {errors}"));
        assert!(
            !py.is_empty() && cli_said.contains(py),
            "{key}: Python said {py:?}, the CLI {cli_said:?}"
        );
    }
    assert_eq!(errors["stream_unknown_job"], errors["unknown_job"]);
}

/// The client's protocol version is the servers'.
#[test]
fn the_python_client_speaks_the_servers_protocol_version() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../clients/python/lightfarm/_protocol.py");
    let text = std::fs::read_to_string(&path).expect("_protocol.py");
    assert!(
        text.contains(&format!(
            "PROTOCOL_VERSION = {}\n",
            lightfarm_proto::PROTOCOL_VERSION
        )),
        "{} and lightfarm_proto::PROTOCOL_VERSION disagree",
        path.display()
    );
}
