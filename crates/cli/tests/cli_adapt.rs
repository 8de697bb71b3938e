//! `lightfarm adapt` through the real binary: a model trained on renders is adapted on a
//! folder of real photos (the three public-domain portraits, shrunk, plus a file that is not
//! an image). Every loss stays finite and the total falls; a photo that cannot be used is
//! named and skipped; a resumed run continues the same loss curve; the adapted checkpoint
//! relights; bad input is an error naming it.

mod common;

use common::losses;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lightfarm"));
    c.env("LIGHTFARM_TRAIN_DEVICE", "cpu");
    c
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("run lightfarm")
}

fn ok(r: &Output) -> String {
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    String::from_utf8_lossy(&r.stdout).into_owned()
}

/// A tiny model trained for 4 steps on four 16² rendered samples.
fn base_model(dir: &Path) -> PathBuf {
    let demo = dir.join("demo");
    ok(&run(&[
        "demo",
        "--out",
        demo.to_str().expect("utf8"),
        "--count",
        "4",
        "--size",
        "16",
        "--spp",
        "1",
        "--train-steps",
        "0",
    ]));
    let cfg = dir.join("train.toml");
    std::fs::write(
        &cfg,
        format!(
            "dataset = {:?}\nout = \"base\"\nsplit = \"all\"\nsteps = 4\nbatch = 2\ncrop = 16\n\
             loader_threads = 1\nvgg_weights = \"none\"\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n",
            demo.join("dataset")
        ),
    )
    .expect("config");
    ok(&run(&["train", cfg.to_str().expect("utf8")]));
    dir.join("base")
}

/// The three portraits at 128², and a broken "photo".
fn photos(dir: &Path) -> PathBuf {
    let out = dir.join("photos");
    std::fs::create_dir_all(out.join("more")).expect("mkdir");
    for (name, sub) in [
        ("astronaut.png", ""),
        ("camera.png", ""),
        ("grace_hopper.jpg", "more"),
    ] {
        let src = common::repo().join("assets/photos").join(name);
        let img = image::open(&src)
            .unwrap_or_else(|e| panic!("{}: {e}; run ./scripts/fetch-models.sh", src.display()))
            .resize_exact(128, 128, image::imageops::FilterType::Triangle)
            .to_rgb8();
        img.save(out.join(sub).join(name).with_extension("png"))
            .expect("save");
    }
    std::fs::write(out.join("broken.jpg"), b"this is not a JPEG").expect("junk");
    out
}

/// A config adapting `base` on `photos` into `<dir>/<name>`: 12 steps of batch 2 at `size`²,
/// a tiny f_Ā; `extra` is appended (a `[weights]` table).
fn write_config(
    dir: &Path,
    name: &str,
    base: &Path,
    photos: &Path,
    size: usize,
    extra: &str,
) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "base = {base:?}\nphotos = {photos:?}\nout = {name:?}\nsteps = 12\nbatch = 2\n\
             size = {size}\nlr = 2e-3\ncheckpoint_every = 3\n\
             hdris = [\"studio_small_03\", \"venice_sunset\"]\ncritic_width = 8\nolat_lights = 8\n\
             [adapter]\nbase = 4\nblocks = 2\n{extra}"
        ),
    )
    .expect("config");
    path
}

#[test]
fn adaptation_trains_on_photos_resumes_and_relights() {
    let tmp = tempfile::tempdir().expect("tmp");
    let base = base_model(tmp.path());
    let photos = photos(tmp.path());

    // The paper's losses at their weights, GAN off so the total is a loss
    // that must fall (an adversarial term rises as its critic learns).
    let cfg = write_config(
        tmp.path(),
        "full",
        &base,
        &photos,
        32,
        "[weights]\ngan = 0\n",
    );
    let r = run(&["adapt", cfg.to_str().expect("utf8"), "--steps", "30"]);
    let said = ok(&r);
    assert!(said.contains("on 4 photos (1 skipped"), "{said}");
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(
        stderr.contains("broken.jpg") && stderr.contains("not a readable image"),
        "{stderr}"
    );
    let log = losses(&tmp.path().join("full"));
    assert_eq!(log.len(), 30);
    for l in &log {
        for key in ["total", "olat", "relative", "similarity", "identity"] {
            assert!(l[key].as_f64().is_some_and(f64::is_finite), "{key} in {l}");
        }
        assert!(l.get("gan").is_none(), "gan is off: {l}");
        // The broken file is found out the first time a step draws it.
        assert!(l["skipped_photos"].as_u64().is_some_and(|n| n <= 1), "{l}");
    }
    assert_eq!(log[log.len() - 1]["skipped_photos"], 1);
    let mean = |ls: &[serde_json::Value]| {
        ls.iter()
            .map(|l| l["total"].as_f64().expect("total"))
            .sum::<f64>()
            / ls.len() as f64
    };
    let (first, last) = (mean(&log[..10]), mean(&log[20..]));
    assert!(
        last < first,
        "the total did not fall: first ten {first}, last ten {last}"
    );

    // With the GAN: finite terms, the critic trains; killed between checkpoints (here: a
    // 6-step run, then continued to 12) it continues the uninterrupted run's curve exactly.
    // (Identity off here: the run above covers it, and its face network is the slowest term
    // on a CPU.)
    let gan = |name: &str| {
        write_config(
            tmp.path(),
            name,
            &base,
            &photos,
            32,
            "[weights]\nidentity = 0\n",
        )
    };
    ok(&run(&["adapt", gan("whole").to_str().expect("utf8")]));
    ok(&run(&[
        "adapt",
        gan("halves").to_str().expect("utf8"),
        "--steps",
        "6",
    ]));
    ok(&run(&["adapt", gan("halves").to_str().expect("utf8")]));
    let (whole, halves) = (
        losses(&tmp.path().join("whole")),
        losses(&tmp.path().join("halves")),
    );
    assert_eq!(whole.len(), 12);
    for (a, b) in whole.iter().zip(&halves) {
        for key in [
            "step",
            "total",
            "olat",
            "relative",
            "similarity",
            "gan",
            "critic",
        ] {
            assert_eq!(a[key], b[key], "{key} at step {}", a["step"]);
        }
        assert!(a["gan"].as_f64().is_some_and(f64::is_finite));
    }

    // The adapted checkpoint is a model: relight a photo with it.
    let out = tmp.path().join("relit.png");
    ok(&run(&[
        "relight",
        "--model",
        tmp.path().join("full").to_str().expect("utf8"),
        "--image",
        photos.join("astronaut.png").to_str().expect("utf8"),
        "--hdri",
        "venice_sunset",
        "--out",
        out.to_str().expect("utf8"),
    ]));
    let img = image::open(&out).expect("relit png");
    assert_eq!((img.width(), img.height()), (128, 128));

    // The ablation "finetune only": no f_Ā, the base networks themselves train; its
    // checkpoint is a plain model with weights of its own, and it relights.
    let cfg = write_config(
        tmp.path(),
        "tuned",
        &base,
        &photos,
        32,
        "[weights]\ngan = 0\nidentity = 0\n",
    );
    let text = std::fs::read_to_string(&cfg).expect("config");
    std::fs::write(&cfg, format!("finetune = true\n{text}")).expect("config");
    ok(&run(&[
        "adapt",
        cfg.to_str().expect("utf8"),
        "--steps",
        "3",
    ]));
    let log = losses(&tmp.path().join("tuned"));
    assert_eq!(log.len(), 3);
    assert!(log
        .iter()
        .all(|l| l["total"].as_f64().is_some_and(f64::is_finite)));
    let checkpoint = |run: &Path| {
        let dir = run.join("checkpoints");
        let name = std::fs::read_to_string(dir.join("latest")).expect("latest");
        dir.join(name.trim())
    };
    let tuned = checkpoint(&tmp.path().join("tuned"));
    assert!(!tuned.join("adapter.json").exists());
    let weights = |dir: &Path| std::fs::read(dir.join("model.safetensors")).expect("weights");
    assert_ne!(
        weights(&tuned),
        weights(&checkpoint(&base)),
        "the networks did not train"
    );
    ok(&run(&[
        "relight",
        "--model",
        tmp.path().join("tuned").to_str().expect("utf8"),
        "--image",
        photos.join("astronaut.png").to_str().expect("utf8"),
        "--hdri",
        "venice_sunset",
        "--out",
        tmp.path().join("tuned.png").to_str().expect("utf8"),
    ]));

    // The real-photo metrics (Table 4) of the base and the adapted model.
    let json = tmp.path().join("real.json");
    let eval = |photos: &Path| {
        bin()
            .env("LIGHTFARM_CACHE", tmp.path().join("cache"))
            .args([
                "eval",
                "--model",
                base.to_str().expect("utf8"),
                "--model",
                tmp.path().join("full").to_str().expect("utf8"),
                "--real",
                photos.to_str().expect("utf8"),
                "--lightings",
                "2",
                "--size",
                "64",
                "--json",
                json.to_str().expect("utf8"),
            ])
            .output()
            .expect("run lightfarm")
    };
    let said = ok(&eval(&photos));
    assert!(
        said.contains("FD-VGG") && said.contains("OLAT cons"),
        "{said}"
    );
    let rows: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("rows");
    assert_eq!(rows.len(), 2);
    for r in &rows {
        assert!(r["photos"].as_u64().is_some_and(|n| n >= 1), "{r}");
        // `lighting` needs the face mesh's skin on at least one photo at 64².
        for key in [
            "lighting",
            "identity",
            "identity_distance",
            "identity_kept",
            "fd_vgg",
            "kid",
            "olat_consistency",
        ] {
            assert!(r[key].as_f64().is_some_and(f64::is_finite), "{key} in {r}");
        }
        let id = r["identity"].as_f64().unwrap_or(2.0);
        assert!((-1.0..=1.0).contains(&id), "{r}");
        assert!(
            r["olat_consistency"].as_f64().is_some_and(|e| e >= 0.0),
            "{r}"
        );
    }

    // Input that needs the base model to judge: a size the networks cannot take, and a
    // folder where no photo is usable.
    let fails = |cfg: &Path| {
        let r = run(&["adapt", cfg.to_str().expect("utf8")]);
        assert_eq!(r.status.code(), Some(1));
        String::from_utf8_lossy(&r.stderr).into_owned()
    };
    let err = fails(&write_config(tmp.path(), "odd", &base, &photos, 30, ""));
    assert!(
        err.contains("size = 30") && err.contains("multiple of 4"),
        "{err}"
    );
    let junk = tmp.path().join("junk");
    std::fs::create_dir_all(&junk).expect("mkdir");
    std::fs::write(junk.join("a.png"), b"not a png").expect("junk");
    let err = fails(&write_config(tmp.path(), "junk", &base, &junk, 32, ""));
    assert!(
        err.contains("none of its 1 photos can be used") && err.contains("junk"),
        "{err}"
    );
    let r = eval(&junk);
    assert_eq!(r.status.code(), Some(1));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("junk") && err.contains("none of its 1 photos"),
        "{err}"
    );
}

#[test]
fn bad_adaptation_input_is_an_error_naming_it() {
    let tmp = tempfile::tempdir().expect("tmp");
    let fails = |cfg: &Path| {
        let r = run(&["adapt", cfg.to_str().expect("utf8")]);
        assert_eq!(r.status.code(), Some(1));
        String::from_utf8_lossy(&r.stderr).into_owned()
    };
    let nowhere = tmp.path().join("nowhere");
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).expect("mkdir");
    let err = fails(&write_config(tmp.path(), "a", &nowhere, &empty, 32, ""));
    assert!(err.contains("base") && err.contains("nowhere"), "{err}");
    let err = fails(&write_config(tmp.path(), "c", &nowhere, &empty, 8, ""));
    assert!(err.contains("size = 8"), "{err}");
    let err = fails(&write_config(
        tmp.path(),
        "d",
        &nowhere,
        &empty,
        32,
        "[weights]\nolat = -1\n",
    ));
    assert!(err.contains("weights"), "{err}");
}
