//! A rendered sample as the trainer sees it: the passes of its EXR and the spec in its header.

use lightfarm_scene::expand::SampleSpec;

use crate::TrainError;

use lightfarm_store::ExrLayer;
pub use lightfarm_store::SAMPLE_ATTRIBUTE;

/// Row-major RGB passes and the coverage mask of one sample.
#[derive(Clone, Debug)]
pub struct SampleImages {
    pub width: usize,
    pub height: usize,
    /// Radiance under HDRI 0 and HDRI 1.
    pub lit: [Vec<[f32; 3]>; 2],
    pub albedo: Vec<[f32; 3]>,
    pub normal: Vec<[f32; 3]>,
    pub normal_lens: Vec<[f32; 3]>,
    pub mask: Vec<f32>,
    /// 1 where the first surface the camera sees is skin (the `id` pass), when the sample has
    /// that pass and its id table.
    pub skin: Option<Vec<f32>>,
    pub spec: SampleSpec,
}

/// Decodes a sample EXR; `name` (a path or sample id) is what errors mention.
pub fn decode_sample(bytes: &[u8], name: &str) -> Result<SampleImages, TrainError> {
    let bad = |reason: String| TrainError::Sample {
        name: name.to_owned(),
        reason,
    };
    let layer = ExrLayer::read(bytes).map_err(bad)?;
    let rgb = |base: &str, names: [&str; 3]| layer.rgb(base, names).map_err(bad);
    let Some(text) = layer.text(SAMPLE_ATTRIBUTE) else {
        return Err(bad(format!(
            "has no {SAMPLE_ATTRIBUTE} header attribute (not written by a lightfarm worker)"
        )));
    };
    let spec = spec_from_attribute(&text).map_err(bad)?;
    let skin = match (skin_id(&text), layer.channel("id.A")) {
        (Some(id), Some(Ok(ids))) => Some(
            ids.into_iter()
                .map(|v| f32::from(u8::from(v == id as f32)))
                .collect(),
        ),
        _ => None,
    };
    let normal = rgb("normal", ["X", "Y", "Z"])?;
    let normal_lens = lens_normals(&normal, rgb("normal_lens", ["X", "Y", "Z"])?);
    Ok(SampleImages {
        width: layer.width,
        height: layer.height,
        lit: [rgb("lit0", ["R", "G", "B"])?, rgb("lit1", ["R", "G", "B"])?],
        albedo: rgb("albedo", ["R", "G", "B"])?,
        normal,
        normal_lens,
        mask: coverage(layer.require("mask.A").map_err(bad)?),
        skin,
        spec,
    })
}

/// The sample spec in the text of a `SAMPLE_ATTRIBUTE` header; the error says what is wrong.
pub(crate) fn spec_from_attribute(text: &str) -> Result<SampleSpec, String> {
    let meta: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("{SAMPLE_ATTRIBUTE} is not JSON ({e})"))?;
    serde_json::from_value(
        meta.get("sample")
            .cloned()
            .unwrap_or(serde_json::Value::Null),
    )
    .map_err(|e| format!("{SAMPLE_ATTRIBUTE} holds no valid sample spec ({e})"))
}

/// The `id` pass's value for skin, from the `id_table` of a `SAMPLE_ATTRIBUTE` header.
fn skin_id(text: &str) -> Option<u32> {
    let meta: serde_json::Value = serde_json::from_str(text).ok()?;
    meta.get("id_table")?
        .as_object()?
        .iter()
        .find(|(_, name)| name.as_str() == Some("skin"))
        .and_then(|(id, _)| id.parse().ok())
}

/// A mask channel as coverage: clamped to [0, 1], non-finite values as 0.
pub(crate) fn coverage(mask: Vec<f32>) -> Vec<f32> {
    mask.into_iter()
        .map(|v| {
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
        .collect()
}

/// The normal with lenses, N_l: the lens normal where a lens covers the pixel, the normal
/// elsewhere. Samples rendered before lightfarm wrote it that way have zeros off the lenses;
/// those pixels take the normal, so f_N is never asked for a unit vector against a zero target.
pub fn lens_normals(normal: &[[f32; 3]], mut normal_lens: Vec<[f32; 3]>) -> Vec<[f32; 3]> {
    for (nl, n) in normal_lens.iter_mut().zip(normal) {
        if *nl == [0.0; 3] {
            *nl = *n;
        }
    }
    normal_lens
}

#[cfg(test)]
mod tests {
    use super::lens_normals;

    #[test]
    fn zero_lens_normals_of_older_samples_take_the_normal() {
        let normal = vec![[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0; 3]];
        let lens = vec![[0.0; 3], [0.0, 0.6, 0.8], [0.0; 3]];
        let got = lens_normals(&normal, lens);
        assert_eq!(got, vec![[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [0.0; 3]]);
    }
}
