//! What the face tests share: the public-domain portraits and their tensors.
// Each test file uses a part of this module.
#![allow(dead_code)]

use burn::prelude::*;

/// A portrait `./scripts/fetch-models.sh` installs under `assets/photos/`.
pub fn photo(name: &str) -> image::RgbImage {
    let path = lightfarm_scene::catalog::builtin_assets_dir()
        .join("photos")
        .join(name);
    image::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e}; run ./scripts/fetch-models.sh", path.display()))
        .to_rgb8()
}

/// [1, 3, H, W] in 0..255.
pub fn tensor(img: &image::RgbImage) -> Tensor<4> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut planar = vec![0f32; 3 * w * h];
    for (i, p) in img.pixels().enumerate() {
        for c in 0..3 {
            planar[c * w * h + i] = f32::from(p[c]);
        }
    }
    Tensor::<1>::from_floats(planar.as_slice(), &Device::default()).reshape([1, 3, h, w])
}

/// Euclidean distance of two single descriptors.
pub fn distance(a: &Tensor<2>, b: &Tensor<2>) -> f32 {
    (a.clone() - b.clone())
        .powi_scalar(2)
        .sum()
        .sqrt()
        .into_scalar::<f32>()
}
