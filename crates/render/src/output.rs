//! Writes a render as the sample contract's multi-layer OpenEXR (DESIGN.md, "The sample"), and a
//! tone-mapped PNG preview. Files are written beside the target and renamed into place, so an
//! interrupted write never leaves a truncated EXR under the final name.

use std::path::{Path, PathBuf};

use exr::prelude::*;

use lightfarm_light::olat_layer;

use crate::passes::{id_table, Pass};
use crate::renderer::RenderOutput;
use crate::RenderError;

fn out_err(path: &Path, reason: impl ToString) -> RenderError {
    RenderError::Output {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

fn temp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(format!(".tmp{}", std::process::id()));
    path.with_file_name(name)
}

fn channel(name: String, data: Vec<f32>) -> AnyChannel<FlatSamples> {
    AnyChannel::new(name.as_str(), FlatSamples::F32(data))
}

fn split3(v: &[[f32; 3]], layer: &str, names: [&str; 3], out: &mut Vec<AnyChannel<FlatSamples>>) {
    for (k, n) in names.iter().enumerate() {
        out.push(channel(
            format!("{layer}.{n}"),
            v.iter().map(|p| p[k]).collect(),
        ));
    }
}

/// Channel names of an output with `lightings` lit layers, in the order they are written.
pub fn channel_names(lightings: usize) -> Vec<String> {
    let mut v = Vec::new();
    for l in 0..lightings {
        for c in ["R", "G", "B"] {
            v.push(format!("lit{l}.{c}"));
        }
    }
    for c in ["R", "G", "B"] {
        v.push(format!("albedo.{c}"));
    }
    for layer in ["normal", "normal_lens"] {
        for c in ["X", "Y", "Z"] {
            v.push(format!("{layer}.{c}"));
        }
    }
    v.push("mask.A".into());
    v
}

/// Channel names of the optional passes `passes` for `lightings` lit layers, as written.
pub fn pass_channel_names(lightings: usize, passes: &[Pass]) -> Vec<String> {
    let mut v = Vec::new();
    for l in 0..lightings {
        for p in passes {
            match p {
                Pass::Shadow => v.push(format!("shadow{l}.A")),
                Pass::Id => {}
                rgb => {
                    for c in ["R", "G", "B"] {
                        v.push(format!("{}{l}.{c}", rgb.name()));
                    }
                }
            }
        }
    }
    if passes.contains(&Pass::Id) {
        v.push("id.A".into());
    }
    v
}

/// The id pass's table as JSON, `{"0": "background", "1": "other", ...}`: the CLI writes it as
/// the `lightfarm.id_table` attribute, a farm sample as the `id_table` field of its one
/// `lightfarm.sample` attribute (exr keeps attributes in a HashMap, so a file with more than
/// one is not byte-reproducible across processes, and a sample's bytes must be).
pub fn id_table_json() -> String {
    let map: serde_json::Map<String, serde_json::Value> = id_table()
        .into_iter()
        .map(|(k, v)| (k.to_string(), serde_json::Value::from(v)))
        .collect();
    serde_json::Value::Object(map).to_string()
}

/// Writes every pass as 32-bit float channels (ZIP compressed) with `attributes` as string
/// header attributes (sample spec, renderer version, statistics).
pub fn write_exr(
    path: &Path,
    out: &RenderOutput,
    attributes: &[(String, String)],
) -> std::result::Result<(), RenderError> {
    let mut channels = Vec::new();
    for (l, img) in out.lit.iter().enumerate() {
        split3(img, &format!("lit{l}"), ["R", "G", "B"], &mut channels);
    }
    split3(&out.albedo, "albedo", ["R", "G", "B"], &mut channels);
    split3(&out.normal, "normal", ["X", "Y", "Z"], &mut channels);
    split3(
        &out.normal_lens,
        "normal_lens",
        ["X", "Y", "Z"],
        &mut channels,
    );
    channels.push(channel("mask.A".into(), out.mask.clone()));
    for (l, lp) in out.passes.iter().enumerate() {
        for p in &out.pass_set {
            if let Some(img) = lp.rgb(*p) {
                split3(
                    img,
                    &format!("{}{l}", p.name()),
                    ["R", "G", "B"],
                    &mut channels,
                );
            } else if *p == Pass::Shadow {
                channels.push(channel(format!("shadow{l}.A"), lp.shadow.clone()));
            }
        }
    }
    if out.pass_set.contains(&Pass::Id) {
        channels.push(channel(
            "id.A".into(),
            out.id.iter().map(|v| *v as f32).collect(),
        ));
    }
    // Half floats: 11 bits of mantissa are far below a Monte Carlo image's noise, and 168
    // lights at 512² would be ~0.5 GB as f32.
    for (i, img) in out.olat.iter().enumerate() {
        let layer = olat_layer(i);
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            channels.push(AnyChannel::new(
                format!("{layer}.{c}").as_str(),
                FlatSamples::F16(
                    img.iter()
                        .map(|p| f16::from_f32(p[k].min(65504.0)))
                        .collect(),
                ),
            ));
        }
    }
    let mut attrs = LayerAttributes::default();
    for (k, v) in attributes {
        attrs.other.insert(
            Text::from(k.as_str()),
            AttributeValue::Text(Text::from(v.as_str())),
        );
    }
    let layer = Layer::new(
        (out.width as usize, out.height as usize),
        attrs,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    let tmp = temp_path(path);
    Image::from_layer(layer)
        .write()
        .to_file(&tmp)
        .map_err(|e| out_err(path, e))?;
    std::fs::rename(&tmp, path).map_err(|e| out_err(path, e))
}

/// A small sRGB preview of a lit layer (see `tonemap_srgb8`).
pub fn write_preview_png(
    path: &Path,
    out: &RenderOutput,
    lighting: usize,
) -> std::result::Result<(), RenderError> {
    let lit = out
        .lit
        .get(lighting)
        .ok_or_else(|| out_err(path, format!("no lighting {lighting}")))?;
    write_rgb8_png(path, out.width, out.height, &tonemap_srgb8(lit, &out.mask))
}

/// Radiance to 8-bit sRGB for a look: exposure set so the subject's mean luminance (weighted
/// by `mask`) lands at 0.18 before a Reinhard curve.
pub fn tonemap_srgb8(lit: &[[f32; 3]], mask: &[f32]) -> Vec<[u8; 3]> {
    let (mut sum, mut weight) = (0.0f64, 0.0f64);
    for (p, m) in lit.iter().zip(mask) {
        sum += (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) as f64;
        weight += *m as f64;
    }
    let mean = if weight > 0.0 { sum / weight } else { 0.0 };
    let exposure = if mean > 0.0 {
        (0.18 / mean) as f32
    } else {
        1.0
    };
    let encode = |x: f32| {
        let t = (x * exposure) / (1.0 + x * exposure);
        let s = if t <= 0.0031308 {
            12.92 * t
        } else {
            1.055 * t.powf(1.0 / 2.4) - 0.055
        };
        (s.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
    };
    lit.iter()
        .map(|p| [encode(p[0]), encode(p[1]), encode(p[2])])
        .collect()
}

/// An 8-bit RGB image as PNG, written atomically (a temporary file renamed into place).
pub fn write_rgb8_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[u8; 3]],
) -> std::result::Result<(), RenderError> {
    let bytes: Vec<u8> = pixels.iter().flatten().copied().collect();
    let img = image::RgbImage::from_raw(width, height, bytes)
        .ok_or_else(|| out_err(path, "image size mismatch"))?;
    let tmp = temp_path(path);
    img.save_with_format(&tmp, image::ImageFormat::Png)
        .map_err(|e| out_err(path, e))?;
    std::fs::rename(&tmp, path).map_err(|e| out_err(path, e))
}
