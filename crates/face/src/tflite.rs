//! A TensorFlow Lite graph of convolutions, run on Burn: enough of TFLite for MediaPipe's face
//! mesh (`face_landmark.tflite`), whose PReLU layers `tract-tflite` does not support. The
//! flatbuffer is parsed with `tract-tflite`'s generated schema; float16 weights behind
//! DEQUANTIZE are widened once at load. Every operator is checked as it is read (kind, operand
//! types and shapes, padding, activation), and an error names the file, the operator's index
//! and its output tensor.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::prelude::*;
use burn::tensor::activation::relu;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions, PadMode};
use tract_tflite::tflite::{self, ActivationFunctionType, BuiltinOperator, Padding, TensorType};

use crate::FaceError;

/// A constant: row-major values in TFLite's layout (NHWC, OHWI for kernels).
#[derive(Clone, Debug)]
struct Constant {
    shape: Vec<usize>,
    data: Vec<f32>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Activation {
    None,
    Relu,
    Relu6,
}

/// Zero rows/columns before and after, [top, bottom, left, right].
type Pads = [usize; 4];

#[derive(Debug)]
struct Conv {
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    stride: [usize; 2],
    pads: Pads,
    groups: usize,
}

#[derive(Debug)]
enum Step {
    Conv(Box<Conv>),
    MaxPool {
        size: [usize; 2],
        stride: [usize; 2],
        pads: Pads,
    },
    /// Element-wise sum with a second activation.
    Add {
        other: usize,
    },
    /// max(x, 0) + α·min(x, 0), α per channel ([1, C, 1, 1]).
    PRelu {
        alpha: Tensor<4>,
    },
    /// Zero padding of the channel dimension (how the mesh widens a residual branch).
    PadChannels {
        before: usize,
        after: usize,
    },
}

#[derive(Debug)]
struct Node {
    input: usize,
    output: usize,
    step: Step,
    activation: Activation,
}

/// A loaded graph: one float32 NHWC input, float32 outputs.
#[derive(Debug)]
pub(crate) struct Graph {
    input: usize,
    /// [height, width, channels] of the input.
    pub input_shape: [usize; 3],
    outputs: Vec<usize>,
    nodes: Vec<Node>,
}

struct Loader<'a> {
    path: &'a Path,
    model: tflite::Model<'a>,
    tensors: flatbuffers::Vector<'a, flatbuffers::ForwardsUOffset<tflite::Tensor<'a>>>,
    constants: HashMap<usize, Constant>,
    shapes: HashMap<usize, Vec<usize>>,
}

fn err(path: &Path, reason: impl Into<String>) -> FaceError {
    FaceError::Model {
        path: path.to_owned(),
        reason: reason.into(),
    }
}

impl<'a> Loader<'a> {
    fn name(&self, t: usize) -> String {
        self.tensors
            .get(t)
            .name()
            .map(str::to_owned)
            .unwrap_or_else(|| format!("tensor {t}"))
    }

    fn shape(&self, t: usize) -> Vec<usize> {
        let shape = self.tensors.get(t).shape();
        shape
            .map(|s| s.iter().map(|d| d.max(0) as usize).collect())
            .unwrap_or_default()
    }

    /// The bytes of a tensor's buffer, if it has one.
    fn buffer(&self, t: usize) -> Option<&'a [u8]> {
        let b = self.tensors.get(t).buffer() as usize;
        let buffers = self.model.buffers()?;
        (b < buffers.len())
            .then(|| buffers.get(b).data())
            .flatten()
            .map(|d| d.bytes())
    }

    fn constant(&self, t: usize, what: &str, at: &str) -> Result<Constant, FaceError> {
        self.constants.get(&t).cloned().ok_or_else(|| {
            err(
                self.path,
                format!("{at}: its {what} '{}' is not a constant", self.name(t)),
            )
        })
    }

    /// A FLOAT32 or FLOAT16 buffer as floats, checked against the shape.
    fn read_constant(&self, t: usize, at: &str) -> Result<Constant, FaceError> {
        let shape = self.shape(t);
        let n: usize = shape.iter().product();
        let bytes = self.buffer(t).unwrap_or(&[]);
        let kind = self.tensors.get(t).type_();
        let data: Vec<f32> = match kind {
            TensorType::FLOAT32 if bytes.len() == 4 * n => bytes
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
            TensorType::FLOAT16 if bytes.len() == 2 * n => bytes
                .chunks_exact(2)
                .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
                .collect(),
            _ => {
                return Err(err(
                    self.path,
                    format!(
                        "{at}: constant '{}' of type {:?} and shape {shape:?} has {} bytes of data",
                        self.name(t),
                        kind,
                        bytes.len()
                    ),
                ))
            }
        };
        Ok(Constant { shape, data })
    }
}

fn activation(path: &Path, at: &str, a: ActivationFunctionType) -> Result<Activation, FaceError> {
    match a {
        ActivationFunctionType::NONE => Ok(Activation::None),
        ActivationFunctionType::RELU => Ok(Activation::Relu),
        ActivationFunctionType::RELU6 => Ok(Activation::Relu6),
        other => Err(err(
            path,
            format!("{at}: fused activation {other:?} is not supported"),
        )),
    }
}

/// TFLite's SAME/VALID padding of one dimension → (before, after, output size).
fn same_or_valid(
    kind: Padding,
    size: usize,
    kernel: usize,
    stride: usize,
) -> (usize, usize, usize) {
    if kind == Padding::SAME {
        let out = size.div_ceil(stride);
        let total = ((out - 1) * stride + kernel).saturating_sub(size);
        (total / 2, total - total / 2, out)
    } else {
        (0, 0, (size.saturating_sub(kernel)) / stride + 1)
    }
}

fn tensor4(c: &Constant, perm: [usize; 4], device: &Device) -> Tensor<4> {
    let s = [c.shape[0], c.shape[1], c.shape[2], c.shape[3]];
    Tensor::<4>::from_data(TensorData::new(c.data.clone(), s), device).permute(perm)
}

impl Graph {
    /// Reads a `.tflite` file; `device` holds the weights.
    pub fn load(path: &Path, bytes: &[u8], device: &Device) -> Result<Graph, FaceError> {
        let model = tflite::root_as_model(bytes)
            .map_err(|e| err(path, format!("not a TensorFlow Lite flatbuffer ({e})")))?;
        let subgraph = model
            .subgraphs()
            .filter(|s| s.len() == 1)
            .map(|s| s.get(0))
            .ok_or_else(|| err(path, "expected exactly one subgraph"))?;
        let (Some(tensors), Some(ops), Some(codes)) = (
            subgraph.tensors(),
            subgraph.operators(),
            model.operator_codes(),
        ) else {
            return Err(err(path, "the subgraph has no tensors or operators"));
        };
        let mut l = Loader {
            path,
            model,
            tensors,
            constants: HashMap::new(),
            shapes: HashMap::new(),
        };
        let index = |v: Option<flatbuffers::Vector<'_, i32>>| -> Vec<usize> {
            v.map(|v| v.iter().map(|i| i.max(-1) as usize).collect())
                .unwrap_or_default()
        };
        let inputs = index(subgraph.inputs());
        let outputs = index(subgraph.outputs());
        let [input] = inputs[..] else {
            return Err(err(
                path,
                format!("expected one input, found {}", inputs.len()),
            ));
        };
        let input_shape = match l.shape(input)[..] {
            [1, h, w, c] if l.tensors.get(input).type_() == TensorType::FLOAT32 => [h, w, c],
            ref s => {
                return Err(err(
                    path,
                    format!(
                        "input '{}' of shape {s:?}, expected float32 [1, H, W, C]",
                        l.name(input)
                    ),
                ))
            }
        };
        l.shapes.insert(input, l.shape(input));
        let mut nodes = Vec::new();
        for (k, op) in ops.iter().enumerate() {
            let ins = index(op.inputs());
            let outs = index(op.outputs());
            let [out] = outs[..] else {
                return Err(err(
                    path,
                    format!("operator {k}: {} outputs, expected 1", outs.len()),
                ));
            };
            // Only a convolution's bias (operand 2) is optional (-1).
            let valid = |(j, &t): (usize, &usize)| t < tensors.len() || (j == 2 && t == usize::MAX);
            if ins.is_empty() || !ins.iter().enumerate().all(valid) || out >= tensors.len() {
                return Err(err(
                    path,
                    format!("operator {k}: a tensor index is missing or out of range"),
                ));
            }
            let code = (op.opcode_index() as usize)
                .lt(&codes.len())
                .then(|| codes.get(op.opcode_index() as usize))
                .map(|c| {
                    c.builtin_code()
                        .0
                        .max(i32::from(c.deprecated_builtin_code()))
                })
                .ok_or_else(|| err(path, format!("operator {k}: opcode index out of range")))?;
            let code = BuiltinOperator(code);
            let at = format!("operator {k} ({:?} → '{}')", code, l.name(out));
            if code == BuiltinOperator::DEQUANTIZE {
                let c = l.read_constant(ins[0], &at)?;
                l.constants.insert(out, c);
                continue;
            }
            let x = ins[0];
            let in_shape = l.shapes.get(&x).cloned().ok_or_else(|| {
                err(
                    path,
                    format!(
                        "{at}: input '{}' is neither the graph input nor computed",
                        l.name(x)
                    ),
                )
            })?;
            let [1, h, w, c] = in_shape[..] else {
                return Err(err(
                    path,
                    format!("{at}: input of shape {in_shape:?}, expected [1, H, W, C]"),
                ));
            };
            let (step, act, out_shape) = l.node(code, op, &ins, [h, w, c], &at, device)?;
            if l.shape(out) != out_shape {
                return Err(err(
                    path,
                    format!(
                        "{at}: computes {out_shape:?}, the file says {:?}",
                        l.shape(out)
                    ),
                ));
            }
            l.shapes.insert(out, out_shape);
            nodes.push(Node {
                input: x,
                output: out,
                step,
                activation: act,
            });
        }
        for &o in &outputs {
            if !l.shapes.contains_key(&o) {
                return Err(err(
                    path,
                    format!("output '{}' is never computed", l.name(o)),
                ));
            }
        }
        Ok(Graph {
            input,
            input_shape,
            outputs,
            nodes,
        })
    }

    /// Runs the graph on [B, C, H, W] input; returns each output flattened to [B, n] (in
    /// TFLite's NHWC order).
    pub fn forward(&self, x: Tensor<4>) -> Vec<Tensor<2>> {
        let mut values: HashMap<usize, Tensor<4>> = HashMap::new();
        values.insert(self.input, x);
        for node in &self.nodes {
            let x = values[&node.input].clone();
            let y = match &node.step {
                Step::Conv(c) => conv2d(
                    pad(x, c.pads, 0.0),
                    c.weight.clone(),
                    c.bias.clone(),
                    ConvOptions::new(c.stride, [0, 0], [1, 1], c.groups),
                ),
                Step::MaxPool { size, stride, pads } => max_pool2d(
                    pad(x, *pads, f32::NEG_INFINITY),
                    MaxPoolOptions::new(*size).with_stride(*stride),
                ),
                Step::Add { other } => x + values[other].clone(),
                Step::PRelu { alpha } => relu(x.clone()) - relu(-x) * alpha.clone(),
                Step::PadChannels { before, after } => {
                    let [b, _, h, w] = x.dims();
                    let device = x.device();
                    let zeros = |n| Tensor::<4>::zeros([b, n, h, w], &device);
                    Tensor::cat(vec![zeros(*before), x, zeros(*after)], 1)
                }
            };
            let y = match node.activation {
                Activation::None => y,
                Activation::Relu => relu(y),
                Activation::Relu6 => y.clamp(0.0, 6.0),
            };
            values.insert(node.output, y);
        }
        self.outputs
            .iter()
            .map(|o| {
                let t = values[o].clone();
                let [b, c, h, w] = t.dims();
                t.permute([0, 2, 3, 1]).reshape([b, h * w * c])
            })
            .collect()
    }
}

fn pad(x: Tensor<4>, [t, b, l, r]: Pads, value: f32) -> Tensor<4> {
    if t + b + l + r == 0 {
        return x;
    }
    x.pad([(0, 0), (0, 0), (t, b), (l, r)], PadMode::Constant(value))
}

impl<'a> Loader<'a> {
    #[allow(clippy::type_complexity)]
    fn node(
        &self,
        code: BuiltinOperator,
        op: tflite::Operator<'a>,
        ins: &[usize],
        [h, w, c]: [usize; 3],
        at: &str,
        device: &Device,
    ) -> Result<(Step, Activation, Vec<usize>), FaceError> {
        let path = self.path;
        let bad = |what: String| err(path, format!("{at}: {what}"));
        match code {
            BuiltinOperator::CONV_2D | BuiltinOperator::DEPTHWISE_CONV_2D => {
                let depthwise = code == BuiltinOperator::DEPTHWISE_CONV_2D;
                let k = self.constant(
                    *ins.get(1).ok_or_else(|| bad("no kernel".into()))?,
                    "kernel",
                    at,
                )?;
                let bias = match ins.get(2) {
                    Some(&b) if b != usize::MAX => Some(self.constant(b, "bias", at)?),
                    _ => None,
                };
                let (padding, stride, dilation, act) = if depthwise {
                    let o = op
                        .builtin_options_as_depthwise_conv_2_doptions()
                        .ok_or_else(|| bad("no options".into()))?;
                    if o.depth_multiplier() > 1
                        && k.shape.last() != Some(&(c * o.depth_multiplier() as usize))
                    {
                        return Err(bad(format!(
                            "depth multiplier {} with kernel {:?}",
                            o.depth_multiplier(),
                            k.shape
                        )));
                    }
                    (
                        o.padding(),
                        [o.stride_h(), o.stride_w()],
                        [o.dilation_h_factor(), o.dilation_w_factor()],
                        o.fused_activation_function(),
                    )
                } else {
                    let o = op
                        .builtin_options_as_conv_2_doptions()
                        .ok_or_else(|| bad("no options".into()))?;
                    (
                        o.padding(),
                        [o.stride_h(), o.stride_w()],
                        [o.dilation_h_factor(), o.dilation_w_factor()],
                        o.fused_activation_function(),
                    )
                };
                if dilation != [1, 1] || stride.iter().any(|&s| s < 1) {
                    return Err(bad(format!(
                        "stride {stride:?} / dilation {dilation:?} are not supported"
                    )));
                }
                let [o0, kh, kw, k3] = k.shape[..] else {
                    return Err(bad(format!("kernel of shape {:?}", k.shape)));
                };
                let (outc, groups) = if depthwise {
                    if o0 != 1 || k3 % c != 0 {
                        return Err(bad(format!(
                            "depthwise kernel {:?} on {c} channels",
                            k.shape
                        )));
                    }
                    (k3, c)
                } else {
                    if k3 != c {
                        return Err(bad(format!("kernel {:?} on {c} channels", k.shape)));
                    }
                    (o0, 1)
                };
                if let Some(b) = &bias {
                    if b.data.len() != outc {
                        return Err(bad(format!(
                            "bias of {} values for {outc} channels",
                            b.data.len()
                        )));
                    }
                }
                let stride = stride.map(|s| s as usize);
                let (pt, pb, oh) = same_or_valid(padding, h, kh, stride[0]);
                let (pl, pr, ow) = same_or_valid(padding, w, kw, stride[1]);
                let weight = if depthwise {
                    tensor4(&k, [3, 0, 1, 2], device)
                } else {
                    tensor4(&k, [0, 3, 1, 2], device)
                };
                let bias =
                    bias.map(|b| Tensor::<1>::from_data(TensorData::new(b.data, [outc]), device));
                Ok((
                    Step::Conv(Box::new(Conv {
                        weight,
                        bias,
                        stride,
                        pads: [pt, pb, pl, pr],
                        groups,
                    })),
                    activation(path, at, act)?,
                    vec![1, oh, ow, outc],
                ))
            }
            BuiltinOperator::MAX_POOL_2D => {
                let o = op
                    .builtin_options_as_pool_2_doptions()
                    .ok_or_else(|| bad("no options".into()))?;
                let size = [o.filter_height(), o.filter_width()].map(|v| v.max(1) as usize);
                let stride = [o.stride_h(), o.stride_w()].map(|v| v.max(1) as usize);
                let (pt, pb, oh) = same_or_valid(o.padding(), h, size[0], stride[0]);
                let (pl, pr, ow) = same_or_valid(o.padding(), w, size[1], stride[1]);
                Ok((
                    Step::MaxPool {
                        size,
                        stride,
                        pads: [pt, pb, pl, pr],
                    },
                    activation(path, at, o.fused_activation_function())?,
                    vec![1, oh, ow, c],
                ))
            }
            BuiltinOperator::ADD => {
                let other = *ins.get(1).ok_or_else(|| bad("one operand".into()))?;
                let shape = self
                    .shapes
                    .get(&other)
                    .cloned()
                    .ok_or_else(|| bad("its second operand is not computed".into()))?;
                if shape != [1, h, w, c] {
                    return Err(bad(format!(
                        "operands of shapes [1, {h}, {w}, {c}] and {shape:?}"
                    )));
                }
                let act = op
                    .builtin_options_as_add_options()
                    .map(|o| o.fused_activation_function())
                    .unwrap_or(ActivationFunctionType::NONE);
                Ok((
                    Step::Add { other },
                    activation(path, at, act)?,
                    vec![1, h, w, c],
                ))
            }
            BuiltinOperator::PRELU => {
                let a = self.constant(
                    *ins.get(1).ok_or_else(|| bad("no alpha".into()))?,
                    "alpha",
                    at,
                )?;
                if a.data.len() != c || a.shape.last() != Some(&c) {
                    return Err(bad(format!("alpha of shape {:?} on {c} channels", a.shape)));
                }
                let alpha = Tensor::<4>::from_data(TensorData::new(a.data, [1, c, 1, 1]), device);
                Ok((Step::PRelu { alpha }, Activation::None, vec![1, h, w, c]))
            }
            BuiltinOperator::PAD => {
                let p = *ins.get(1).ok_or_else(|| bad("no paddings".into()))?;
                let bytes = self.buffer(p).unwrap_or(&[]);
                let v: Vec<i32> = bytes
                    .chunks_exact(4)
                    .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .collect();
                match v[..] {
                    [0, 0, 0, 0, 0, 0, before, after] if before >= 0 && after >= 0 => {
                        let (before, after) = (before as usize, after as usize);
                        Ok((
                            Step::PadChannels { before, after },
                            Activation::None,
                            vec![1, h, w, c + before + after],
                        ))
                    }
                    _ => Err(bad(format!(
                        "paddings {v:?}; only channel padding is supported"
                    ))),
                }
            }
            other => Err(bad(format!("operator {other:?} is not supported"))),
        }
    }
}

/// Reads the graph at `path`; a missing built-in file names the fix.
pub(crate) fn read_graph(
    path: &Path,
    builtin: PathBuf,
    fix: &str,
    device: &Device,
) -> Result<Graph, FaceError> {
    let bytes = std::fs::read(path).map_err(|e| FaceError::Model {
        path: path.to_owned(),
        reason: if path == builtin {
            format!("cannot read this built-in model ({e}): {fix}")
        } else {
            format!("cannot read ({e}); expected a TensorFlow Lite model")
        },
    })?;
    Graph::load(path, &bytes, device)
}
