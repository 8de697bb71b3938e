//! dlib DNNs as this crate runs them. A dlib network is a nest of templates
//! (`relu<add_prev1<affine<con<…, tag1<…>>>>>>`), serialised outermost layer first for the
//! version headers and innermost first for the layer details. [`read_net`] reads such a file
//! against the expected nesting ([`Layer`]s, outermost first), checking every layer's kind,
//! filter count, kernel, stride, padding and weight count, and returns the forward pass as a
//! list of [`Op`]s: dlib's tag, skip and add_prev layers become a small register file, and
//! batch-norm layers saved from training become the affine maps dlib runs them as.

use burn::prelude::*;
use burn::tensor::activation::relu;
use burn::tensor::module::{avg_pool2d, conv2d, max_pool2d};
use burn::tensor::ops::{AvgPoolOptions, ConvOptions, MaxPoolOptions, PadMode};

use crate::dlib::Reader;
use crate::FaceError;

/// One layer of the serialised network, outermost first, as dlib's templates nest them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Layer {
    Fc {
        outputs: usize,
    },
    AvgPoolAll,
    Relu,
    AddPrev {
        tag: u8,
    },
    AvgPool {
        size: usize,
        stride: usize,
    },
    MaxPool {
        size: usize,
        stride: usize,
    },
    Skip {
        tag: u8,
    },
    Tag {
        tag: u8,
    },
    Affine,
    Con {
        filters: usize,
        size: usize,
        stride: usize,
    },
}

/// One step of the forward pass.
#[derive(Clone, Debug)]
pub(crate) enum Op {
    Conv {
        weight: Tensor<4>,
        bias: Tensor<1>,
        stride: usize,
        padding: usize,
    },
    Affine {
        gamma: Tensor<4>,
        beta: Tensor<4>,
    },
    Relu,
    MaxPool {
        size: usize,
        stride: usize,
    },
    AvgPool {
        size: usize,
        stride: usize,
    },
    AvgPoolAll,
    Tag(u8),
    Skip(u8),
    AddPrev(u8),
    Fc {
        weight: Tensor<2>,
    },
}

/// Reads the version headers of `layers` (outermost first); the innermost layer sits on the
/// input layer, whose details the caller reads next.
pub(crate) fn read_headers(r: &mut Reader<'_>, layers: &[Layer]) -> Result<Vec<i64>, FaceError> {
    let mut versions = Vec::with_capacity(layers.len());
    for (i, layer) in layers.iter().enumerate() {
        let innermost = i + 1 == layers.len();
        let allowed: &[i64] = match layer {
            Layer::Tag { .. } | Layer::Skip { .. } => &[1],
            _ if innermost => &[2, 3],
            _ => &[1, 2],
        };
        versions.push(r.version(&format!("layer {i} ({layer:?})"), allowed)?);
    }
    Ok(versions)
}

/// Reads the details of `layers` (after the input layer's) and returns the forward pass.
pub(crate) fn read_layers(
    r: &mut Reader<'_>,
    layers: &[Layer],
    versions: &[i64],
    device: &Device,
) -> Result<Vec<Op>, FaceError> {
    let mut ops = Vec::with_capacity(layers.len());
    let mut channels = Channels {
        now: 3,
        ..Channels::default()
    };
    for (i, layer) in layers.iter().enumerate().rev() {
        let op = read_layer(r, *layer, &mut channels, device)?;
        if let Some(op) = op {
            ops.push(op);
        }
        if matches!(layer, Layer::Tag { .. } | Layer::Skip { .. }) {
            continue;
        }
        for _ in 0..3 {
            r.boolean()?;
        }
        r.tensor()?; // x_grad
        r.tensor()?; // cached_output
        let innermost = i + 1 == layers.len();
        if innermost {
            r.tensor()?; // grad_final
            if versions[i] >= 3 {
                r.int()?; // sample_expansion_factor
            }
        } else if versions[i] == 2 {
            r.tensor()?; // params_grad
        }
    }
    Ok(ops)
}

/// Runs the forward pass on an NCHW input.
pub(crate) fn forward(ops: &[Op], mut x: Tensor<4>) -> Tensor<4> {
    let mut tags: [Option<Tensor<4>>; 3] = [None, None, None];
    for op in ops {
        x = match op {
            Op::Conv {
                weight,
                bias,
                stride,
                padding,
            } => conv2d(
                x,
                weight.clone(),
                Some(bias.clone()),
                ConvOptions::new([*stride; 2], [*padding; 2], [1, 1], 1),
            ),
            Op::Affine { gamma, beta } => x * gamma.clone() + beta.clone(),
            Op::Relu => relu(x),
            Op::MaxPool { size, stride } => {
                max_pool2d(x, MaxPoolOptions::new([*size; 2]).with_stride([*stride; 2]))
            }
            Op::AvgPool { size, stride } => {
                avg_pool2d(x, AvgPoolOptions::new([*size; 2]).with_stride([*stride; 2]))
            }
            Op::AvgPoolAll => x.mean_dim(3).mean_dim(2),
            Op::Tag(t) => {
                tags[usize::from(*t)] = Some(x.clone());
                x
            }
            Op::Skip(t) => tags[usize::from(*t)].clone().unwrap_or(x),
            Op::AddPrev(t) => match tags[usize::from(*t)].clone() {
                Some(prev) => add_zero_padded(x, prev),
                None => x,
            },
            Op::Fc { weight } => {
                let [b, c, _, _] = x.dims();
                let [_, out] = weight.dims();
                x.reshape([b, c])
                    .matmul(weight.clone())
                    .reshape([b, out, 1, 1])
            }
        };
    }
    x
}

/// dlib's `add_prev`: the sum of two tensors of possibly different sizes, as if the smaller
/// were zero-padded at its far end in every dimension.
fn add_zero_padded(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    let (da, db) = (a.dims(), b.dims());
    let target: [usize; 4] = std::array::from_fn(|i| da[i].max(db[i]));
    let pad = |t: Tensor<4>, d: [usize; 4]| {
        if d == target {
            t
        } else {
            let pairs: [(usize, usize); 4] = std::array::from_fn(|i| (0, target[i] - d[i]));
            t.pad(pairs, PadMode::Constant(0.0))
        }
    };
    pad(a, da) + pad(b, db)
}

/// Reads one layer's details and returns its forward operation; `ch` tracks the
/// channel counts, to check weight counts.
fn read_layer(
    r: &mut Reader<'_>,
    layer: Layer,
    ch: &mut Channels,
    device: &Device,
) -> Result<Option<Op>, FaceError> {
    let op = match layer {
        Layer::Tag { tag } => {
            ch.tags[usize::from(tag)] = ch.now;
            Some(Op::Tag(tag))
        }
        Layer::Skip { tag } => {
            ch.now = ch.tags[usize::from(tag)];
            Some(Op::Skip(tag))
        }
        Layer::AddPrev { tag } => {
            r.tag(&["add_prev_"])?;
            ch.now = (ch.now).max(ch.tags[usize::from(tag)]);
            Some(Op::AddPrev(tag))
        }
        Layer::Relu => {
            if r.tag(&["relu_", "relu_2"])? == "relu_2" && r.boolean()? {
                return Err(r.error("a disabled relu layer"));
            }
            Some(Op::Relu)
        }
        Layer::AvgPoolAll | Layer::AvgPool { .. } | Layer::MaxPool { .. } => {
            let max = matches!(layer, Layer::MaxPool { .. });
            r.tag(&[if max { "max_pool_2" } else { "avg_pool_2" }])?;
            let got: Vec<i64> = (0..6).map(|_| r.int()).collect::<Result<_, _>>()?;
            let (size, stride) = match layer {
                Layer::AvgPool { size, stride } | Layer::MaxPool { size, stride } => {
                    (size as i64, stride as i64)
                }
                _ => (0, 1),
            };
            let want = [size, size, stride, stride, 0, 0];
            if got != want {
                return Err(r.error(format!(
                    "pooling layer (rows, cols, strides, paddings) {got:?}, expected {want:?}"
                )));
            }
            Some(match layer {
                Layer::AvgPool { size, stride } => Op::AvgPool { size, stride },
                Layer::MaxPool { size, stride } => Op::MaxPool { size, stride },
                _ => Op::AvgPoolAll,
            })
        }
        Layer::Affine => {
            let version = r.tag(&["affine_", "affine_2", "bn_con2"])?;
            let params = r.tensor()?;
            let gamma = r.alias_tensor()?;
            let beta = r.alias_tensor()?;
            let c = ch.now;
            if params.len() != 2 * c || gamma != [1, c, 1, 1] || beta != [1, c, 1, 1] {
                return Err(r.error(format!(
                    "affine layer of {} values ({gamma:?}, {beta:?}) after {c} channels",
                    params.len()
                )));
            }
            let (mut scale, mut shift) = (params.values[..c].to_vec(), params.values[c..].to_vec());
            if version == "bn_con2" {
                // A batch-norm layer saved from training: dlib runs it as the affine map of its
                // running statistics, γ/√(σ²+ε) and β − mean·γ/√(σ²+ε).
                let _means = r.tensor()?;
                let _invstds = r.tensor()?;
                let mean = r.tensor()?;
                let var = r.tensor()?;
                let _updates = r.int()?;
                let _window = r.int()?;
                for _ in 0..4 {
                    r.float()?;
                }
                let eps = r.float()?;
                if mean.len() != c || var.len() != c {
                    return Err(r.error(format!(
                        "batch norm with {} means and {} variances after {c} channels",
                        mean.len(),
                        var.len()
                    )));
                }
                for k in 0..c {
                    scale[k] /= (var.values[k] + eps).sqrt();
                    shift[k] -= mean.values[k] * scale[k];
                }
            } else {
                let _mode = r.int()?;
                if version == "affine_2" && r.boolean()? {
                    return Err(r.error("a disabled affine layer"));
                }
            }
            let t = |v: &[f32]| Tensor::<1>::from_floats(v, device).reshape([1, c, 1, 1]);
            Some(Op::Affine {
                gamma: t(&scale),
                beta: t(&shift),
            })
        }
        Layer::Con {
            filters,
            size,
            stride,
        } => {
            let version = r.tag(&["con_4", "con_5", "con_6"])?;
            let params = r.tensor()?;
            let got: Vec<i64> = (0..7).map(|_| r.int()).collect::<Result<_, _>>()?;
            // dlib pads a stride-1 convolution by half the kernel and a strided one not at all.
            let padding = if stride == 1 { size / 2 } else { 0 };
            let want = [filters, size, size, stride, stride, padding, padding].map(|v| v as i64);
            if got != want {
                return Err(r.error(format!(
                    "convolution (filters, rows, cols, strides, paddings) {got:?}, expected {want:?}"
                )));
            }
            let cin = ch.now;
            let wshape = [filters, cin, size, size];
            let (w, b) = (r.alias_tensor()?, r.alias_tensor()?);
            for _ in 0..4 {
                r.float()?; // learning-rate and weight-decay multipliers
            }
            if version != "con_4" && !r.boolean()? {
                return Err(r.error("a convolution without bias"));
            }
            if version == "con_6" && r.boolean()? {
                return Err(r.error("a convolution with a fused relu"));
            }
            let nw: usize = wshape.iter().product();
            if w != wshape || b != [1, filters, 1, 1] || params.len() != nw + filters {
                return Err(r.error(format!(
                    "convolution weights {w:?} + {b:?} ({} values) after {cin} channels, expected {wshape:?}",
                    params.len()
                )));
            }
            ch.now = filters;
            Some(Op::Conv {
                weight: Tensor::<1>::from_floats(&params.values[..nw], device).reshape(wshape),
                bias: Tensor::<1>::from_floats(&params.values[nw..], device),
                stride,
                padding,
            })
        }
        Layer::Fc { outputs } => {
            r.tag(&["fc_2", "fc_3"])?;
            let (nout, nin) = (
                r.size("fc outputs", 1 << 20)?,
                r.size("fc inputs", 1 << 20)?,
            );
            let params = r.tensor()?;
            let (w, _b) = (r.alias_tensor()?, r.alias_tensor()?);
            let bias_mode = r.int()?;
            for _ in 0..4 {
                r.float()?;
            }
            // fc_no_bias is bias mode 1 (FC_NO_BIAS).
            if nout != outputs || nin != ch.now || bias_mode != 1 || params.len() != nin * nout {
                return Err(r.error(format!(
                    "fc layer {nin}→{nout} (bias mode {bias_mode}, {} values, weights {w:?}), expected {}→{outputs} without bias",
                    params.len(),
                    ch.now
                )));
            }
            ch.now = nout;
            Some(Op::Fc {
                weight: Tensor::<1>::from_floats(params.values.as_slice(), device)
                    .reshape([nin, nout]),
            })
        }
    };
    Ok(op)
}

/// Channel counts while reading: what flows out of the last layer read, and what each tag
/// holds.
#[derive(Default)]
pub(crate) struct Channels {
    now: usize,
    tags: [usize; 3],
}
