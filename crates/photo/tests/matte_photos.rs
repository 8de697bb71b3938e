//! MODNet on the three public-domain portraits that `./scripts/fetch-models.sh` installs under
//! `assets/photos/`: the face is foreground, the background corners are not. And what a bad
//! network file gives: an error naming the file and the fix.

use std::path::{Path, PathBuf};

use lightfarm_photo::{Matting, PhotoError};

fn photo(name: &str) -> (usize, usize, Vec<[f32; 3]>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/photos")
        .join(name);
    let img = image::open(&path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e}; run ./scripts/fetch-models.sh (it installs the test photos)",
                path.display()
            )
        })
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    (w, h, img.pixels().map(|p| [p[0], p[1], p[2]]).collect())
}

/// A photo, its face centre and two background points.
type Case = (&'static str, (usize, usize), [(usize, usize); 2]);

fn matting() -> Matting {
    Matting::builtin().unwrap_or_else(|e| panic!("{e}"))
}

/// Mean alpha over the `r`-pixel box around (x, y).
fn mean(alpha: &[f32], w: usize, x: usize, y: usize, r: usize) -> f32 {
    let mut sum = 0.0;
    let mut n = 0.0;
    for yy in y - r..=y + r {
        for xx in x - r..=x + r {
            sum += alpha[yy * w + xx];
            n += 1.0;
        }
    }
    sum / n
}

#[test]
fn the_face_is_foreground_and_the_background_corners_are_not() {
    let m = matting();
    // (photo, face centre, background corners), read off the photos: the astronaut's top
    // corners are flag and studio backdrop, the cameraman's are sky, Grace Hopper's are the
    // studio backdrop.
    let cases: [Case; 3] = [
        ("astronaut.png", (222, 120), [(16, 16), (495, 16)]),
        ("camera.png", (215, 150), [(16, 16), (495, 16)]),
        ("grace_hopper.jpg", (260, 230), [(16, 16), (495, 16)]),
    ];
    for (name, (fx, fy), corners) in cases {
        let (w, h, rgb) = photo(name);
        let alpha = m.alpha(&rgb, w, h).expect("matte");
        assert_eq!(alpha.len(), w * h);
        assert!(alpha.iter().all(|a| (0.0..=1.0).contains(a)));
        let face = mean(&alpha, w, fx, fy, 8);
        assert!(face > 0.95, "{name}: face alpha {face}");
        for (cx, cy) in corners {
            let c = mean(&alpha, w, cx, cy, 12);
            assert!(c < 0.05, "{name}: background alpha {c} at ({cx}, {cy})");
        }
        // A portrait, not all or nothing: the subject covers a plausible share of the frame.
        let cover = alpha.iter().sum::<f32>() / alpha.len() as f32;
        assert!((0.15..0.85).contains(&cover), "{name}: coverage {cover}");
    }
}

#[test]
fn a_matte_follows_the_photo_when_it_is_mirrored_and_resized() {
    let m = matting();
    let (w, h, rgb) = photo("astronaut.png");
    let alpha = m.alpha(&rgb, w, h).expect("matte");
    // Mirrored photo: mirrored matte, up to resampling.
    let flipped: Vec<[f32; 3]> = (0..w * h)
        .map(|i| rgb[i / w * w + (w - 1 - i % w)])
        .collect();
    let alpha_f = m.alpha(&flipped, w, h).expect("matte");
    let diff: f32 = (0..w * h)
        .map(|i| (alpha[i] - alpha_f[i / w * w + (w - 1 - i % w)]).abs())
        .sum::<f32>()
        / (w * h) as f32;
    assert!(diff < 0.02, "mean |alpha − mirrored alpha| = {diff}");
    // A quarter-size copy (the network sees it at its 512 reference size again) is matted the
    // same way, measured on the quarter-size grid.
    let (qw, qh) = (w / 4, h / 4);
    let quarter: Vec<[f32; 3]> = (0..qw * qh)
        .map(|i| {
            let (x, y) = (i % qw * 4, i / qw * 4);
            let mut s = [0.0f32; 3];
            for dy in 0..4 {
                for dx in 0..4 {
                    let p = rgb[(y + dy) * w + x + dx];
                    for c in 0..3 {
                        s[c] += p[c] / 16.0;
                    }
                }
            }
            s
        })
        .collect();
    let alpha_q = m.alpha(&quarter, qw, qh).expect("matte");
    let diff: f32 = (0..qw * qh)
        .map(|i| (alpha_q[i] - alpha[(i / qw * 4 + 2) * w + i % qw * 4 + 2]).abs())
        .sum::<f32>()
        / (qw * qh) as f32;
    assert!(diff < 0.06, "mean |alpha(quarter) − alpha| = {diff}");
}

#[test]
fn a_missing_or_broken_network_is_an_error_naming_it() {
    let tmp = tempfile::tempdir().expect("tmp");
    let missing = tmp.path().join("nowhere/modnet.onnx");
    let e = Matting::load(&missing).expect_err("missing");
    let text = e.to_string();
    assert!(
        text.contains("nowhere/modnet.onnx") && text.contains("fetch-models.sh"),
        "{text}"
    );
    let junk: PathBuf = tmp.path().join("junk.onnx");
    std::fs::write(&junk, b"not a protobuf at all \xff\xfe").expect("write");
    let e = Matting::load(&junk).expect_err("junk");
    assert!(matches!(e, PhotoError::Model { .. }));
    assert!(e.to_string().contains("junk.onnx"), "{e}");
    let m = matting();
    let e = m.alpha(&[[0.5; 3]; 5], 2, 3).expect_err("wrong size");
    assert!(e.to_string().contains("2x3"), "{e}");
}
