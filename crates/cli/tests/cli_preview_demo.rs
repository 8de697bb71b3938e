//! `lightfarm preview` and `lightfarm demo` end to end through the real binary.

use std::process::{Command, Output};

fn run(args: &[&str], dir: &std::path::Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lightfarm"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run lightfarm")
}

fn example() -> String {
    format!("{}/../../examples/dataset.toml", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn preview_writes_a_labelled_contact_sheet() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("sheet.png");
    let r = run(
        &[
            "preview",
            &example(),
            "--count",
            "2",
            "--start",
            "3",
            "--size",
            "24",
            "--spp",
            "1",
            "--out",
            out.to_str().expect("utf8"),
        ],
        dir.path(),
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let img = image::open(&out).expect("png").to_rgb8();
    // Six columns of 24 px tiles with 2 px gaps; a header line, then caption + tiles per row.
    assert_eq!(img.width(), 6 * (24 + 2) + 2);
    assert_eq!(img.height(), 12 + 2 * (12 + 24 + 2) + 2);
    // The mask tile of the first row has a subject in it (white pixels).
    let (x0, y0) = (2 + 5 * 26, 12 + 12);
    let white = (0..24)
        .flat_map(|y| (0..24).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x0 + x, y0 + y)[0] > 200)
        .count();
    assert!(white > 24, "mask tile has {white} subject pixels");
}

#[test]
fn preview_rejects_bad_arguments() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("s.png");
    let o = out.to_str().expect("utf8");
    for (args, needle) in [
        (
            vec!["preview", &example(), "--count", "0", "--out", o],
            "--count",
        ),
        (
            vec![
                "preview",
                &example(),
                "--count",
                "2",
                "--start",
                "999999",
                "--out",
                o,
            ],
            "--start",
        ),
        (vec!["preview", "no/such.toml", "--out", o], "no/such.toml"),
        (
            vec!["preview", &example(), "--size", "0", "--out", o],
            "--size",
        ),
        (
            vec!["preview", &example(), "--out", "/no/such/dir/s.png"],
            "/no/such/dir",
        ),
    ] {
        let r = run(&args, dir.path());
        assert_eq!(r.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    assert!(!out.exists());
}

#[test]
fn demo_renders_exports_and_draws_a_sheet() {
    let dir = tempfile::tempdir().expect("tmp");
    let r = run(
        &[
            "demo",
            "--out",
            "demo",
            "--count",
            "3",
            "--size",
            "16",
            "--spp",
            "1",
            "--train-steps",
            "3",
        ],
        dir.path(),
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let samples =
        lightfarm_store::read_export(&dir.path().join("demo/dataset")).expect("exported dataset");
    assert_eq!(samples.len(), 3);
    assert!(samples
        .iter()
        .all(|s| !s.exr.is_empty() && s.json["sample"]["index"] == s.index));
    assert!(dir.path().join("demo/sheet.png").is_file());
    // Then it trained, relit a sample and scored the model.
    assert!(dir.path().join("demo/train/checkpoints/latest").is_file());
    assert!(dir.path().join("demo/relit.png").is_file());
    let eval: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("demo/eval.json")).expect("eval.json"),
    )
    .expect("eval json");
    assert_eq!(eval.as_array().map(Vec::len), Some(2), "{eval}");
}
