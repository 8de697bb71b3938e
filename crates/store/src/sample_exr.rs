//! Reading the images inside a stored sample: the first layer of an OpenEXR file, its channels
//! by name and its text attributes. The coordinator's dashboard (previews) and the trainer
//! (training data, OLAT bases, real portraits) read samples through this one reader, so a file
//! that one of them rejects the other rejects in the same words.

use std::io::Cursor;

use exr::prelude::{AnyChannels, AttributeValue, FlatSamples, Layer, ReadChannels, ReadLayers};

/// The header attribute a render worker writes into every sample: JSON
/// `{"renderer": .., "sample": SampleSpec, ..}`.
pub const SAMPLE_ATTRIBUTE: &str = "lightfarm.sample";

/// The first valid layer of an OpenEXR file, every channel and attribute, at full resolution.
pub struct ExrLayer {
    pub width: usize,
    pub height: usize,
    layer: Layer<AnyChannels<FlatSamples>>,
}

impl ExrLayer {
    /// Decodes `bytes`; the error says the file is no readable OpenEXR and why.
    pub fn read(bytes: &[u8]) -> Result<ExrLayer, String> {
        let img = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(bytes))
            .map_err(|e| format!("not a readable OpenEXR file ({e})"))?;
        let layer = img.layer_data;
        Ok(ExrLayer {
            width: layer.size.width(),
            height: layer.size.height(),
            layer,
        })
    }

    /// Channel `name` (exact) as f32, row-major: None when the layer has no such channel, an
    /// error when it holds other than one value per pixel.
    pub fn channel(&self, name: &str) -> Option<Result<Vec<f32>, String>> {
        self.find(|n| n == name).map(|v| self.check(name, v))
    }

    /// Channel `name` (exact), which a lightfarm sample must have.
    pub fn require(&self, name: &str) -> Result<Vec<f32>, String> {
        self.channel(name)
            .unwrap_or_else(|| Err(format!("has no channel {name}; is it a lightfarm sample?")))
    }

    /// Channel `name` in any case (`R` or `r`), for images written by other programs.
    pub fn channel_any_case(&self, name: &str) -> Option<Result<Vec<f32>, String>> {
        self.find(|n| n.eq_ignore_ascii_case(name))
            .map(|v| self.check(name, v))
    }

    /// The pass `base` as RGB triples from its channels `base.names[0..3]` (required), with
    /// every non-finite value as 0: one NaN must not poison a preview or a batch.
    pub fn rgb(&self, base: &str, names: [&str; 3]) -> Result<Vec<[f32; 3]>, String> {
        let [a, b, c] = names.map(|n| self.require(&format!("{base}.{n}")));
        let (a, b, c) = (a?, b?, c?);
        Ok(a.iter()
            .zip(&b)
            .zip(&c)
            .map(|((&a, &b), &c)| [a, b, c].map(|v| if v.is_finite() { v } else { 0.0 }))
            .collect())
    }

    /// The text of header attribute `name`, if the file has it as text.
    pub fn text(&self, name: &str) -> Option<String> {
        match self
            .layer
            .attributes
            .other
            .get(&exr::prelude::Text::from(name))
        {
            Some(AttributeValue::Text(t)) => Some(t.to_string()),
            _ => None,
        }
    }

    fn find(&self, matches: impl Fn(&str) -> bool) -> Option<Vec<f32>> {
        self.layer
            .channel_data
            .list
            .iter()
            .find(|c| matches(&c.name.to_string()))
            .map(|c| c.sample_data.values_as_f32().collect())
    }

    fn check(&self, name: &str, v: Vec<f32>) -> Result<Vec<f32>, String> {
        if v.len() == self.width * self.height {
            Ok(v)
        } else {
            Err(format!(
                "channel {name} holds {} values for {}x{}",
                v.len(),
                self.width,
                self.height
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::{AnyChannel, Encoding, Image, LayerAttributes, Text, WritableImage};

    fn write(channels: Vec<(&str, Vec<f32>)>, w: usize, h: usize, attr: Option<&str>) -> Vec<u8> {
        let list = channels
            .into_iter()
            .map(|(n, v)| AnyChannel::new(n, FlatSamples::F32(v)))
            .collect();
        let mut attributes = LayerAttributes::named("");
        if let Some(a) = attr {
            attributes.other.insert(
                Text::from(SAMPLE_ATTRIBUTE),
                AttributeValue::Text(Text::from(a)),
            );
        }
        let layer = Layer::new(
            (w, h),
            attributes,
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(list),
        );
        let mut bytes = Vec::new();
        Image::from_layer(layer)
            .write()
            .to_buffered(Cursor::new(&mut bytes))
            .expect("write a test EXR");
        bytes
    }

    #[test]
    fn reads_passes_attributes_and_names_what_is_wrong() {
        let bytes = write(
            vec![
                ("lit0.R", vec![1.0, f32::NAN]),
                ("lit0.G", vec![2.0, 0.5]),
                ("lit0.B", vec![3.0, f32::INFINITY]),
                ("mask.A", vec![1.0, 0.0]),
            ],
            2,
            1,
            Some("{\"sample\": 1}"),
        );
        let l = ExrLayer::read(&bytes).expect("read back");
        assert_eq!((l.width, l.height), (2, 1));
        assert_eq!(
            l.rgb("lit0", ["R", "G", "B"]),
            Ok(vec![[1.0, 2.0, 3.0], [0.0, 0.5, 0.0]])
        );
        assert_eq!(l.require("mask.A"), Ok(vec![1.0, 0.0]));
        assert_eq!(l.text(SAMPLE_ATTRIBUTE).as_deref(), Some("{\"sample\": 1}"));
        assert_eq!(l.text("other"), None);
        assert!(l.channel("albedo.R").is_none());
        assert_eq!(
            l.require("albedo.R"),
            Err("has no channel albedo.R; is it a lightfarm sample?".to_owned())
        );
        assert_eq!(l.channel_any_case("MASK.a"), Some(Ok(vec![1.0, 0.0])));
        let err = ExrLayer::read(b"not an exr").err().unwrap_or_default();
        assert!(err.starts_with("not a readable OpenEXR file ("), "{err}");
    }
}
