//! dlib's face-recognition ResNet, read from its own file and run on Burn, separates people the
//! way dlib documents it (same person < 0.6 < different people) on the public-domain portraits
//! that ./scripts/fetch-models.sh installs; and a broken file is an error naming it.

use std::path::{Path, PathBuf};

mod common;

use burn::prelude::*;
use common::{distance, photo, tensor};
use lightfarm_face::{builtin_face_net, FaceNet, CHIP_SIZE, SAME_PERSON_DISTANCE};

/// The square `(x, y, side)` of `img` resampled to a 150² chip, as [1, 3, 150, 150] in 0..255.
fn chip(img: &image::RgbImage, (x, y, side): (u32, u32, u32)) -> Tensor<4> {
    let crop = image::imageops::crop_imm(img, x, y, side, side).to_image();
    let n = CHIP_SIZE as u32;
    tensor(&image::imageops::resize(
        &crop,
        n,
        n,
        image::imageops::FilterType::Triangle,
    ))
}

fn net() -> FaceNet {
    let path = builtin_face_net();
    FaceNet::load(&path, &Device::default())
        .unwrap_or_else(|e| panic!("{e} (run ./scripts/fetch-models.sh)"))
}

const ASTRONAUT_FACE: (u32, u32, u32) = (160, 62, 130);
const HOPPER_FACE: (u32, u32, u32) = (160, 125, 210);

#[test]
fn separates_people_like_dlib() {
    let net = net();
    let astronaut = photo("astronaut.png");
    let hopper = photo("grace_hopper.jpg");
    let embed = |t: Tensor<4>| net.embed(t);

    let a = embed(chip(&astronaut, ASTRONAUT_FACE));
    assert_eq!(a.dims(), [1, 128]);
    let norm = a.clone().powi_scalar(2).sum().sqrt().into_scalar::<f32>();
    // dlib's descriptors are close to unit length.
    assert!((0.2..2.0).contains(&norm), "descriptor norm {norm}");

    let mirrored = embed(chip(
        &image::imageops::flip_horizontal(&astronaut),
        (512 - 160 - 130, 62, 130),
    ));
    let mut darker = astronaut.clone();
    darker
        .pixels_mut()
        .for_each(|p| p.0 = p.0.map(|v| (f32::from(v) * 0.7) as u8));
    let darker = embed(chip(&darker, ASTRONAUT_FACE));
    let shifted = embed(chip(&astronaut, (166, 58, 138)));
    let h = embed(chip(&hopper, HOPPER_FACE));

    let same = [
        ("mirrored", distance(&a, &mirrored)),
        ("darker", distance(&a, &darker)),
        ("shifted crop", distance(&a, &shifted)),
    ];
    let different = distance(&a, &h);
    eprintln!("same person: {same:?}; astronaut vs Grace Hopper: {different}");
    for (what, d) in same {
        assert!(
            d < 0.4,
            "astronaut vs {what}: {d} (dlib: same person < {SAME_PERSON_DISTANCE})"
        );
    }
    assert!(
        different > SAME_PERSON_DISTANCE,
        "astronaut vs Grace Hopper: {different}, dlib separates people above {SAME_PERSON_DISTANCE}"
    );
    // A batch gives each chip its own descriptor.
    let both = embed(Tensor::cat(
        vec![chip(&astronaut, ASTRONAUT_FACE), chip(&hopper, HOPPER_FACE)],
        0,
    ));
    let rows: Vec<Tensor<2>> = both.chunk(2, 0);
    assert!(distance(&rows[0], &a) < 1e-4 && distance(&rows[1], &h) < 1e-4);
}

fn broken_copy(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn broken_files_are_errors_naming_them() {
    let bytes = std::fs::read(builtin_face_net())
        .unwrap_or_else(|e| panic!("{e}: run ./scripts/fetch-models.sh"));
    let dir = std::env::temp_dir().join(format!("lightfarm-face-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let device = Device::default();
    let cases = [
        (
            broken_copy(&dir, "truncated.dat", &bytes[..bytes.len() / 2]),
            "truncated",
        ),
        (broken_copy(&dir, "empty.dat", &[]), "truncated"),
        (
            broken_copy(&dir, "text.dat", b"hello, I am not a network"),
            "does not start a dlib integer",
        ),
        (dir.join("missing.dat"), "cannot read"),
    ];
    for (path, expect) in cases {
        let err = FaceNet::load(&path, &device)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains(&path.display().to_string()) && err.contains(expect),
            "{}: {err}",
            path.display()
        );
    }
    // A layer of the wrong kind: the first convolution's tag bytes changed.
    let mut wrong = bytes.clone();
    let at = wrong.windows(5).position(|w| w == b"con_4").unwrap();
    wrong[at..at + 5].copy_from_slice(b"con_9");
    let path = broken_copy(&dir, "wrong_layer.dat", &wrong);
    let err = FaceNet::load(&path, &device)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        err.contains("con_9") && err.contains("wrong_layer.dat"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
