//! The identity loss (section 4.3) on a real portrait: zero when the relighting only changes
//! the exposure (identity does not depend on it), positive when the relighting changes the
//! face's shading, with a finite, non-zero gradient back into what produced the relit image.

mod common;

use burn::prelude::*;
use lightfarm_face::{builtin_face_net, identity_loss, FaceAligner, FaceNet, Image};

#[test]
fn identity_loss_ignores_exposure_and_has_a_gradient() {
    let plain = Device::default();
    let device = plain.clone().autodiff();
    let img = image::imageops::resize(
        &common::photo("astronaut.png"),
        192,
        192,
        image::imageops::FilterType::Triangle,
    );
    let n = 192;
    let aligner = FaceAligner::builtin(&plain).unwrap_or_else(|e| panic!("{e}"));
    let face = aligner
        .align(&Image::new(img.as_raw(), n, n).expect("image"))
        .expect("the astronaut's face");
    let net = FaceNet::load(&builtin_face_net(), &device).unwrap_or_else(|e| panic!("{e}"));
    // Linear RGB, planar.
    let mut planar = vec![0f32; 3 * n * n];
    for (i, p) in img.pixels().enumerate() {
        for c in 0..3 {
            planar[c * n * n + i] = (f32::from(p[c]) / 255.0).powf(2.2);
        }
    }
    let input = Tensor::<1>::from_floats(planar.as_slice(), &device).reshape([1, 3, n, n]);
    let mask = Tensor::<4>::ones([1, 1, n, n], &device);
    let faces = [face];

    let brighter = identity_loss(
        &net,
        input.clone(),
        input.clone().mul_scalar(3.0),
        mask.clone(),
        &faces,
    )
    .into_scalar::<f32>();
    assert!(
        brighter < 1e-3,
        "exposure ×3 changed the identity descriptor: {brighter}"
    );

    // A relighting that darkens the image-left side of the face: shading, not exposure.
    let w = Tensor::<4>::from_floats([[[[0.9f32]]]], &device).require_grad();
    let ramp: Vec<f32> = (0..n * n).map(|i| (i % n) as f32 / n as f32).collect();
    let ramp = Tensor::<1>::from_floats(ramp.as_slice(), &device).reshape([1, 1, n, n]);
    let shading = (ramp.sub_scalar(1.0) * w.clone()).add_scalar(1.0);
    let loss = identity_loss(&net, input.clone(), input * shading, mask, &faces);
    let value = loss.clone().into_scalar::<f32>();
    assert!(value.is_finite() && value > 1e-3, "loss {value}");
    let grads = loss.backward();
    let g = w
        .grad(&grads)
        .expect("a gradient into the relighting")
        .into_scalar::<f32>();
    assert!(g.is_finite() && g != 0.0, "gradient {g}");
}
