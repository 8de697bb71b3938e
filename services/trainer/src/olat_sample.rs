//! The OLAT images of a sample (`lighting.olat` in the dataset spec): one half-float
//! `olatNNN.R/G/B` layer per light of the virtual light stage's basis, beside the sample's
//! usual layers. `lightfarm relight-olat` and the synthetic-to-real OLAT losses read them here.

use lightfarm_scene::expand::SampleSpec;

use lightfarm_store::ExrLayer;

use crate::sample::{coverage, spec_from_attribute, SAMPLE_ATTRIBUTE};
use crate::TrainError;

/// Row-major images of one sample under each OLAT light, and its coverage mask.
#[derive(Clone, Debug)]
pub struct OlatImages {
    pub width: usize,
    pub height: usize,
    /// `lights[i]`: the subject under light i of `lightfarm_light::OlatBasis` with that many
    /// lights (4° discs, world frame).
    pub lights: Vec<Vec<[f32; 3]>>,
    pub mask: Vec<f32>,
    /// The sample's spec, when the file carries one (farm samples do).
    pub spec: Option<SampleSpec>,
}

/// Decodes the OLAT layers of a sample EXR; `name` (a path or sample id) is what errors
/// mention.
pub fn decode_olat(bytes: &[u8], name: &str) -> Result<OlatImages, TrainError> {
    let bad = |reason: String| TrainError::Sample {
        name: name.to_owned(),
        reason,
    };
    let layer = ExrLayer::read(bytes).map_err(bad)?;
    let (width, height) = (layer.width, layer.height);
    let channel = |n: &str| layer.channel(n).map(|c| c.map_err(bad));
    let mut lights = Vec::new();
    loop {
        let base = lightfarm_light::olat_layer(lights.len());
        let Some(r) = channel(&format!("{base}.R")) else {
            break;
        };
        let missing = |c: &str| bad(format!("has {base}.R but no {base}.{c}"));
        let g = channel(&format!("{base}.G")).ok_or_else(|| missing("G"))?;
        let b = channel(&format!("{base}.B")).ok_or_else(|| missing("B"))?;
        let (r, g, b) = (r?, g?, b?);
        lights.push(
            (0..width * height)
                .map(|i| [r[i], g[i], b[i]].map(|v| if v.is_finite() { v } else { 0.0 }))
                .collect(),
        );
    }
    if lights.is_empty() {
        return Err(bad(
            "has no OLAT layers (olat000.R ...): render it from a dataset spec with \
             `olat = 168` under [lighting]"
                .into(),
        ));
    }
    let mask = match channel("mask.A") {
        Some(m) => coverage(m?),
        None => vec![1.0; width * height],
    };
    let spec = match layer.text(SAMPLE_ATTRIBUTE) {
        Some(text) => {
            let spec = spec_from_attribute(&text).map_err(bad)?;
            if spec.render.olat as usize != lights.len() {
                return Err(bad(format!(
                    "its spec asks for {} OLAT lights but the file holds {} layers (truncated \
                     or edited): re-render the sample",
                    spec.render.olat,
                    lights.len()
                )));
            }
            Some(spec)
        }
        None => None,
    };
    Ok(OlatImages {
        width,
        height,
        lights,
        mask,
        spec,
    })
}
