//! dlib's detector and 5-point landmarks, read from their own files, find and align the faces
//! of the public-domain portraits that ./scripts/fetch-models.sh installs: the box holds the
//! face, the landmarks sit where eyes and nose are (mirror-consistent), a faceless picture has
//! no face, and aligned chips give dlib's identity separation. Broken files are errors naming
//! them.

mod common;

use burn::prelude::*;
use common::{distance, photo, tensor};
use lightfarm_face::{
    builtin_face_net, face_chips, Alignment, FaceAligner, FaceNet, Image, SAME_PERSON_DISTANCE,
};

fn view(img: &image::RgbImage) -> Image<'_> {
    Image::new(img.as_raw(), img.width() as usize, img.height() as usize).unwrap()
}

fn aligner() -> FaceAligner {
    FaceAligner::builtin(&Device::default())
        .unwrap_or_else(|e| panic!("{e} (run ./scripts/fetch-models.sh)"))
}

/// The hand-located centre of each portrait's face (between the eyes and the mouth).
const FACES: [(&str, [f32; 2]); 2] = [
    ("astronaut.png", [226.0, 125.0]),
    ("grace_hopper.jpg", [262.0, 235.0]),
];

fn check_landmarks(name: &str, a: &Alignment) {
    let l = &a.landmarks;
    assert_eq!(l.len(), 5, "{name}");
    let eye_y = (l[0][1] + l[1][1] + l[2][1] + l[3][1]) / 4.0;
    // Outer and inner corners in order across the face, image-left eye left of the other.
    assert!(
        l[2][0] < l[3][0] && l[3][0] < l[1][0] && l[1][0] < l[0][0],
        "{name}: eye corners out of order {l:?}"
    );
    let eye_span = l[0][0] - l[2][0];
    assert!(
        l[4][1] > eye_y + 0.25 * eye_span,
        "{name}: nose {:?} not below the eyes (y {eye_y})",
        l[4]
    );
    assert!(
        (l[4][0] - (l[0][0] + l[2][0]) / 2.0).abs() < 0.2 * eye_span,
        "{name}: nose not between the eyes {l:?}"
    );
}

#[test]
fn finds_and_aligns_the_portraits() {
    let aligner = aligner();
    for (name, centre) in FACES {
        let img = photo(name);
        let faces = aligner.detect(&view(&img));
        let Some(best) = faces.first() else {
            panic!("{name}: no face found")
        };
        eprintln!("{name}: {} face(s), best {best:?}", faces.len());
        assert!(
            best.left < centre[0]
                && centre[0] < best.left + best.width
                && best.top < centre[1]
                && centre[1] < best.top + best.height,
            "{name}: the face at {centre:?} is not in {best:?}"
        );
        assert!(
            (60.0..400.0).contains(&best.width),
            "{name}: implausible face size {best:?}"
        );
        let a = aligner.align(&view(&img)).unwrap();
        eprintln!("{name}: landmarks {:?}", a.landmarks);
        check_landmarks(name, &a);

        // The mirrored photo's landmarks are the mirrored landmarks (outer/inner corners
        // of the two eyes swap roles).
        let flipped = image::imageops::flip_horizontal(&img);
        let m = aligner.align(&view(&flipped)).unwrap();
        check_landmarks(name, &m);
        let w = img.width() as f32 - 1.0;
        let eye_span = a.landmarks[0][0] - a.landmarks[2][0];
        for (i, j) in [(0, 2), (1, 3), (2, 0), (3, 1), (4, 4)] {
            let (p, q) = (a.landmarks[i], m.landmarks[j]);
            let err = ((w - q[0]) - p[0]).hypot(q[1] - p[1]);
            assert!(
                err < 0.1 * eye_span,
                "{name}: landmark {i} at {p:?}, mirrored {q:?} ({err} px apart)"
            );
        }
    }
}

#[test]
fn a_picture_without_a_face_has_none() {
    let aligner = aligner();
    // The astronaut photo's top-right corner: mottled studio backdrop and the shuttle model.
    let img = photo("astronaut.png");
    let corner = image::imageops::crop_imm(&img, 320, 0, 192, 192).to_image();
    let found = aligner.detect(&view(&corner));
    assert!(found.is_empty(), "faces in the backdrop: {found:?}");
    let grey = image::RgbImage::from_pixel(200, 200, image::Rgb([128, 128, 128]));
    assert!(aligner.detect(&view(&grey)).is_empty());
    // A tiny image is too small for the 80-pixel window even upsampled: no face, no panic.
    let tiny = image::RgbImage::from_pixel(20, 30, image::Rgb([200, 150, 120]));
    assert!(aligner.detect(&view(&tiny)).is_empty());
}

#[test]
fn aligned_chips_separate_people() {
    let aligner = aligner();
    let net = FaceNet::load(&builtin_face_net(), &Device::default())
        .unwrap_or_else(|e| panic!("{e} (run ./scripts/fetch-models.sh)"));
    let embed = |img: &image::RgbImage| {
        let a = aligner.align(&view(img)).expect("a face");
        net.embed(face_chips(tensor(img), &[a]))
    };
    let astronaut = photo("astronaut.png");
    let hopper = photo("grace_hopper.jpg");
    let a = embed(&astronaut);
    let mut darker = astronaut.clone();
    darker
        .pixels_mut()
        .for_each(|p| p.0 = p.0.map(|v| (f32::from(v) * 0.6) as u8));
    let half = image::imageops::resize(&astronaut, 256, 256, image::imageops::FilterType::Triangle);
    let same = [
        (
            "mirrored",
            distance(&a, &embed(&image::imageops::flip_horizontal(&astronaut))),
        ),
        ("darker", distance(&a, &embed(&darker))),
        ("half size", distance(&a, &embed(&half))),
    ];
    let different = distance(&a, &embed(&hopper));
    eprintln!("same person: {same:?}; astronaut vs Grace Hopper: {different}");
    for (what, d) in same {
        assert!(
            d < 0.4,
            "astronaut vs {what}: {d} (dlib: same person < {SAME_PERSON_DISTANCE})"
        );
    }
    assert!(
        different > SAME_PERSON_DISTANCE,
        "astronaut vs Grace Hopper: {different}"
    );
}

#[test]
fn broken_model_files_are_errors_naming_them() {
    let dir = std::env::temp_dir().join(format!("lightfarm-align-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let device = Device::default();
    for builtin in [
        lightfarm_face::builtin_detector(),
        lightfarm_face::builtin_landmarks(),
    ] {
        let bytes = std::fs::read(&builtin)
            .unwrap_or_else(|e| panic!("{e}: run ./scripts/fetch-models.sh"));
        let path = dir.join("cut.dat");
        std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let (det, lm) = if builtin == lightfarm_face::builtin_detector() {
            (path.clone(), lightfarm_face::builtin_landmarks())
        } else {
            (lightfarm_face::builtin_detector(), path.clone())
        };
        let err = FaceAligner::load(&det, &lm, &device)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("cut.dat") && err.contains("truncated"),
            "{err}"
        );
    }
    // The detector's file where the landmark model belongs: wrong kind of object.
    let err = FaceAligner::load(
        &lightfarm_face::builtin_detector(),
        &lightfarm_face::builtin_detector(),
        &device,
    )
    .err()
    .map(|e| e.to_string())
    .unwrap_or_default();
    assert!(err.contains("mmod_human_face_detector.dat"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
