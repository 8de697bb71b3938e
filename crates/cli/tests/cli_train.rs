//! `lightfarm train`, `relight` and `eval` through the real binary: a run killed with SIGKILL
//! resumes the same loss curve; relight writes the image, its inset and intermediates; eval
//! prints a row per model; bad input is an error naming it.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::{assert_relit_masked, inset, losses, positions, sample_mask};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lightfarm"));
    c.env("LIGHTFARM_TRAIN_DEVICE", "cpu");
    c
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("run lightfarm")
}

/// Four 16² samples rendered and exported by `lightfarm demo` (training skipped).
fn dataset() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("demo");
        let o = out.to_str().expect("utf8");
        let r = run(&[
            "demo",
            "--out",
            o,
            "--count",
            "4",
            "--size",
            "16",
            "--spp",
            "1",
            "--train-steps",
            "0",
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        (tmp, out.join("dataset"))
    })
    .1
}

fn write_config(dir: &Path, name: &str, steps: u64) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "dataset = {:?}\nout = {:?}\nsplit = \"all\"\nsteps = {steps}\nbatch = 2\ncrop = 16\nlr = 2e-3\n\
             checkpoint_every = 5\nloader_threads = 1\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n",
            dataset(),
            dir.join(name)
        ),
    )
    .expect("write config");
    path
}

#[test]
fn a_run_killed_with_sigkill_resumes_the_same_loss_curve() {
    let tmp = tempfile::tempdir().expect("tmp");
    let straight = write_config(tmp.path(), "straight", 20);
    let r = run(&["train", straight.to_str().expect("utf8")]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));

    let killed = write_config(tmp.path(), "killed", 1000);
    let mut child = bin()
        .args(["train", killed.to_str().expect("utf8")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    let started = Instant::now();
    while losses(&tmp.path().join("killed")).len() < 13 {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "training made no progress"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    child.kill().expect("SIGKILL"); // Child::kill is SIGKILL on Unix
    let _ = child.wait();

    let r = run(&["train", killed.to_str().expect("utf8"), "--steps", "20"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let (a, b) = (
        losses(&tmp.path().join("straight")),
        losses(&tmp.path().join("killed")),
    );
    assert_eq!(a.len(), 20, "one line per step in the straight run");
    assert_eq!(b.len(), 20, "one line per step after the resume");
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x["step"], y["step"]);
        let (x, y) = (
            x["total"].as_f64().expect("total"),
            y["total"].as_f64().expect("total"),
        );
        assert!((x - y).abs() <= 1e-4 * x.abs().max(1e-3), "{x} vs {y}");
    }
}

#[test]
fn relight_and_eval_write_what_they_promise() {
    let tmp = tempfile::tempdir().expect("tmp");
    let cfg = write_config(tmp.path(), "run", 4);
    let r = run(&["train", cfg.to_str().expect("utf8")]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let model = tmp.path().join("run");
    let m = model.to_str().expect("utf8");
    let exr = std::fs::read_dir(dataset())
        .expect("dataset")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|e| e == "exr"))
        .expect("an exr");

    // A sample EXR, relit under two catalog HDRIs.
    let relight_exr = |hdri: &str, name: &str| -> PathBuf {
        let out = tmp.path().join(format!("{name}.png"));
        let r = run(&[
            "relight",
            "--model",
            m,
            "--image",
            exr.to_str().expect("utf8"),
            "--hdri",
            hdri,
            "--out",
            out.to_str().expect("utf8"),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        out
    };
    let studio = relight_exr("studio_small_03", "relit");
    let sunset = relight_exr("venice_sunset", "sunset");
    let (w, h, mask) = sample_mask(&std::fs::read(&exr).expect("read the sample EXR"));
    assert_eq!((w, h), (16, 16));
    let open = |p: &Path| {
        let img = image::open(p)
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
            .to_rgb8();
        assert_eq!((img.width(), img.height()), (w, h), "{}", p.display());
        img
    };
    let side = |name: &str, s: &str| tmp.path().join(format!("{name}_{s}.png"));
    let (a, b) = (open(&studio), open(&sunset));
    let subject: Vec<(u32, u32)> = positions(w, h)
        .filter(|&(x, y)| mask[(y * w + x) as usize] > 0.0 && !inset(w, h, x, y))
        .collect();
    assert!(
        !subject.is_empty(),
        "the sample has subject pixels outside the inset"
    );
    assert_relit_masked(&a, &mask, "relit under studio_small_03");
    assert_relit_masked(&b, &mask, "relit under venice_sunset");
    assert!(
        subject
            .iter()
            .any(|&(x, y)| a.get_pixel(x, y).0 != b.get_pixel(x, y).0),
        "two HDRIs relit the subject identically"
    );
    // The intermediates are not masked: f_N and f_A see the input alone, so normals and
    // albedo are the same under either HDRI (to a PNG rounding step), while the light maps
    // looked up with those normals are the HDRIs'.
    let differs = |s: &str| {
        let (x, y) = (open(&side("relit", s)), open(&side("sunset", s)));
        x.pixels()
            .zip(y.pixels())
            .map(|(p, q)| (0..3).map(|c| p[c].abs_diff(q[c])).max().unwrap_or(0))
            .max()
            .unwrap_or(0)
    };
    for s in ["normal", "normal_lens", "albedo"] {
        assert!(differs(s) <= 1, "{s} changed with the HDRI");
    }
    for s in ["diffuse", "specular"] {
        assert!(differs(s) > 1, "{s} did not change with the HDRI");
    }
    // Normal PNGs hold (n + 1)/2 of unit vectors, everywhere (the networks' normals are
    // normalised before any mask applies); rounding three components to 8 bits moves |n| by
    // at most √3/255 ≈ 0.007.
    for s in ["normal", "normal_lens"] {
        for p in open(&side("relit", s)).pixels() {
            let len =
                p.0.iter()
                    .map(|&v| (f32::from(v) / 255.0 * 2.0 - 1.0).powi(2))
                    .sum::<f32>()
                    .sqrt();
            assert!((len - 1.0).abs() < 0.01, "{s}: |n| = {len} at {p:?}");
        }
    }

    // A plain PNG portrait with a mask, 20×12 (not a multiple of the UNet's 4: padded).
    let png = tmp.path().join("photo.png");
    let mask = tmp.path().join("mask.png");
    image::RgbImage::from_fn(20, 12, |x, y| {
        image::Rgb([(x * 12) as u8, (y * 20) as u8, 128])
    })
    .save(&png)
    .expect("png");
    image::GrayImage::from_fn(20, 12, |x, _| image::Luma([if x > 4 { 255 } else { 0 }]))
        .save(&mask)
        .expect("mask");
    let out2 = tmp.path().join("photo_relit.png");
    let r = run(&[
        "relight",
        "--model",
        m,
        "--image",
        png.to_str().expect("utf8"),
        "--mask",
        mask.to_str().expect("utf8"),
        "--hdri",
        "venice_sunset",
        "--rotation",
        "-90",
        "--flip",
        "--out",
        out2.to_str().expect("utf8"),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let img = image::open(&out2).expect("png").to_rgb8();
    assert_eq!((img.width(), img.height()), (20, 12));
    // The mask PNG is white for x > 4: the relit image is black elsewhere, outside the inset
    // (it covers x >= 4, y >= 4 here).
    let photo_mask: Vec<f32> = positions(20, 12)
        .map(|(x, _)| if x > 4 { 1.0 } else { 0.0 })
        .collect();
    assert_relit_masked(&img, &photo_mask, "the relit photo");

    // A real photograph without alpha or --mask is matted with MODNet (installed by
    // fetch-models.sh): a 128² copy of the astronaut portrait. Its `_mask.png` is the matte:
    // face foreground, the flag in the top-left corner background.
    let astronaut = image::open(common::repo().join("assets/photos/astronaut.png"))
        .expect("assets/photos/astronaut.png: run ./scripts/fetch-models.sh")
        .resize_exact(128, 128, image::imageops::FilterType::Triangle)
        .to_rgb8();
    let photo = tmp.path().join("astronaut.png");
    astronaut.save(&photo).expect("png");
    let hdr = common::repo().join("assets/hdri/venice_sunset_1k.hdr");
    let relight_photo = |extra: &[&str], name: &str| {
        let out = tmp.path().join(format!("{name}.png"));
        let mut args = vec![
            "relight",
            "--model",
            m,
            "--image",
            photo.to_str().expect("utf8"),
            "--hdri",
            hdr.to_str().expect("utf8"),
            "--out",
            out.to_str().expect("utf8"),
        ];
        args.extend_from_slice(extra);
        let r = run(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let mask = image::open(tmp.path().join(format!("{name}_mask.png")))
            .expect("_mask.png")
            .to_luma8();
        assert_eq!((mask.width(), mask.height()), (128, 128));
        (String::from_utf8_lossy(&r.stdout).into_owned(), mask)
    };
    let (said, mask) = relight_photo(&[], "astronaut_relit");
    assert!(said.contains("MODNet"), "{said}");
    assert!(
        mask.get_pixel(55, 30)[0] > 240,
        "face {:?}",
        mask.get_pixel(55, 30)
    );
    assert!(
        mask.get_pixel(4, 4)[0] < 15,
        "corner {:?}",
        mask.get_pixel(4, 4)
    );
    let relit = image::open(tmp.path().join("astronaut_relit.png"))
        .expect("png")
        .to_rgb8();
    let corner = relit.get_pixel(4, 4).0;
    assert!(
        corner.iter().all(|&v| v < 40),
        "background is not relit: {corner:?}"
    );
    let (said, mask) = relight_photo(&["--no-matte"], "astronaut_whole");
    assert!(!said.contains("MODNet"), "{said}");
    assert!(
        mask.pixels().all(|p| p[0] == 255),
        "--no-matte: all foreground"
    );
    // MODNet not installed: the error names the file, the script and --mask.
    let empty = tempfile::tempdir().expect("tmp");
    let r = bin()
        .args(["relight", "--model", m, "--image"])
        .arg(&photo)
        .arg("--hdri")
        .arg(&hdr)
        .arg("--out")
        .arg(tmp.path().join("never.png"))
        .env("LIGHTFARM_ASSETS", empty.path())
        .output()
        .expect("run lightfarm");
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{err}");
    assert!(
        err.contains("modnet.onnx") && err.contains("fetch-models.sh") && err.contains("--mask"),
        "{err}"
    );

    // eval: the input row and one per model.
    let json = tmp.path().join("eval.json");
    let r = run(&[
        "eval",
        "--model",
        m,
        "--model",
        m,
        "--split",
        "all",
        "--json",
        json.to_str().expect("utf8"),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let table = String::from_utf8_lossy(&r.stdout);
    assert!(
        table.contains("MAE")
            && table.contains("input (not relit)")
            && table.matches("decomposed").count() == 2,
        "{table}"
    );
    let rows: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&json).expect("json")).expect("json");
    let rows = rows.as_array().expect("an array of rows");
    assert_eq!(rows.len(), 3);
    // LPIPS is on by default, with the built-in weights (scripts/test.sh installs them).
    assert!(table.contains("LPIPS"), "{table}");
    for row in rows {
        for key in ["mae", "mse", "ssim", "lpips"] {
            assert!(
                row[key].as_f64().is_some_and(f64::is_finite),
                "{key} of {row}"
            );
        }
    }
    let r = run(&["eval", "--model", m, "--split", "all", "--lpips", "none"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(!String::from_utf8_lossy(&r.stdout).contains("LPIPS"));
    // Built-in weights that are not installed: an error naming the file and the fix.
    let empty = tempfile::tempdir().expect("tmp");
    let r = bin()
        .args(["eval", "--model", m, "--split", "all"])
        .env("LIGHTFARM_ASSETS", empty.path())
        .output()
        .expect("run lightfarm");
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{err}");
    assert!(
        err.contains("vgg16_lpips.safetensors")
            && err.contains("fetch-models.sh")
            && err.contains("--lpips none"),
        "{err}"
    );
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let tmp = tempfile::tempdir().expect("tmp");
    let cfg = write_config(tmp.path(), "run", 2);
    let r = run(&["train", cfg.to_str().expect("utf8")]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let m = tmp.path().join("run");
    let m = m.to_str().expect("utf8");
    let junk = tmp.path().join("junk.png");
    std::fs::write(&junk, b"not a png").expect("junk");
    let out = tmp.path().join("o.png");
    let o = out.to_str().expect("utf8");
    let exr = std::fs::read_dir(dataset())
        .expect("dataset")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|e| e == "exr"))
        .expect("an exr");
    let e = exr.to_str().expect("utf8");
    let c = cfg.to_str().expect("utf8");
    for (args, needle) in [
        (vec!["train", "no/such.toml"], "no/such.toml"),
        (
            vec![
                "relight",
                "--model",
                "/no/model",
                "--image",
                e,
                "--hdri",
                "studio_small_03",
                "--out",
                o,
            ],
            "/no/model",
        ),
        (
            vec![
                "relight",
                "--model",
                m,
                "--image",
                junk.to_str().expect("utf8"),
                "--hdri",
                "studio_small_03",
                "--out",
                o,
            ],
            "junk.png",
        ),
        (
            vec![
                "relight",
                "--model",
                m,
                "--image",
                e,
                "--hdri",
                "no_such_hdri",
                "--out",
                o,
            ],
            "no_such_hdri",
        ),
        (
            vec![
                "relight",
                "--model",
                m,
                "--image",
                e,
                "--hdri",
                "studio_small_03",
                "--out",
                "/no/dir/o.png",
            ],
            "/no/dir",
        ),
        (vec!["eval", "--model", m, "--split", "bogus"], "bogus"),
    ] {
        let r = run(&args);
        assert_eq!(r.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    assert!(!out.exists());
    // Usage errors (clap's exit code 2).
    for (args, needle) in [
        (vec!["train", c, "--precision", "f8"], "f8"),
        (
            vec![
                "train",
                c,
                "--precision",
                "f16",
                "--trainer",
                "http://127.0.0.1:1",
            ],
            "--trainer",
        ),
    ] {
        let r = run(&args);
        assert_eq!(r.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}
