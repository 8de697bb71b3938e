//! `lightfarm preview` and `lightfarm demo` end to end through the real binary.

mod common;

use std::process::{Command, Output};

use common::{assert_relit_masked, sample_mask};

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
    let mut samples = samples;
    samples.sort_by_key(|s| s.index);

    // The sheet: six 16 px tile columns with 2 px gaps; a header line, then a caption line
    // and a row of tiles per sample, in index order. Its mask tiles are the samples' masks as
    // 8-bit grey, (m·255 + 0.5) truncated.
    let sheet = image::open(dir.path().join("demo/sheet.png"))
        .expect("sheet.png")
        .to_rgb8();
    assert_eq!(
        (sheet.width(), sheet.height()),
        (6 * (16 + 2) + 2, 12 + 3 * (12 + 16 + 2) + 2)
    );
    for (row, s) in samples.iter().enumerate() {
        let (w, h, mask) = sample_mask(&s.exr);
        assert_eq!((w, h), (16, 16));
        let (x0, y0) = (2 + 5 * (16 + 2), 12 + row as u32 * (12 + 16 + 2) + 12);
        for y in 0..h {
            for x in 0..w {
                let m = mask[(y * w + x) as usize];
                let grey = (m.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                assert_eq!(
                    sheet.get_pixel(x0 + x, y0 + y).0,
                    [grey; 3],
                    "sample {} mask tile at ({x}, {y})",
                    s.index
                );
            }
        }
    }

    // Then it trained: `latest` names the final step's complete checkpoint.
    let checkpoints = dir.path().join("demo/train/checkpoints");
    let latest = std::fs::read_to_string(checkpoints.join("latest")).expect("checkpoints/latest");
    assert_eq!(latest.trim(), "step-000000003");
    let model = checkpoints.join(latest.trim()).join("model.safetensors");
    let size = std::fs::metadata(&model)
        .unwrap_or_else(|e| panic!("{}: {e}", model.display()))
        .len();
    assert!(size > 0, "{} is empty", model.display());

    // It relit the first test-split sample (else the first): black off its mask outside the
    // light-ball inset, not black all over the subject.
    let entries = lightfarm_store::list_export_folder(&dir.path().join("demo/dataset"))
        .expect("export listing");
    let entry = entries
        .iter()
        .find(|e| e.split == "test")
        .or(entries.first())
        .expect("an exported sample");
    let relit_sample = samples
        .iter()
        .find(|s| s.index == entry.index)
        .expect("the relit sample is exported");
    let (w, h, mask) = sample_mask(&relit_sample.exr);
    let relit = image::open(dir.path().join("demo/relit.png"))
        .expect("relit.png")
        .to_rgb8();
    assert_eq!((relit.width(), relit.height()), (w, h));
    assert_relit_masked(&relit, &mask, "relit.png");

    // And scored the model: the input row and the model's, with finite metrics.
    let eval: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("demo/eval.json")).expect("eval.json"),
    )
    .expect("eval json");
    let rows = eval.as_array().expect("an array of rows");
    assert_eq!(rows.len(), 2, "{eval}");
    for row in rows {
        for key in ["mae", "mse", "ssim"] {
            assert!(
                row[key].as_f64().is_some_and(f64::is_finite),
                "{key} of {row}"
            );
        }
    }
}
