//! Strands as the renderer's fibres: [`Strands::to_curves`] and the hair material of a sample.

use lightfarm_render::scene::{Curves, Material, MaterialModel};
use lightfarm_scene::expand::HairSample;

use super::Strands;

impl Strands {
    /// The strands as a fibre set (radius = half the width) whose segments use `material`.
    pub fn to_curves(&self, name: &str, material: u32) -> Curves {
        Curves {
            name: name.to_owned(),
            points: self.points.iter().map(|p| p.to_array()).collect(),
            radii: self.widths.iter().map(|w| 0.5 * w).collect(),
            offsets: self.offsets.clone(),
            material,
        }
    }
}

/// The Chiang fibre material of a sample's hair: its melanin, redness and roughness, the
/// `hair` preset's IOR (1.55) and cuticle tilt (2°).
pub fn hair_fibre_material(name: &str, hair: &HairSample) -> Material {
    let unit = |x: f64| {
        if x.is_finite() {
            x.clamp(0.0, 1.0) as f32
        } else {
            0.0
        }
    };
    let mut m = Material {
        name: name.to_owned(),
        ..Material::default()
    };
    m.apply_model(MaterialModel::Hair);
    m.melanin = unit(hair.melanin);
    m.melanin_redness = unit(hair.melanin_redness);
    m.longitudinal_roughness = unit(hair.longitudinal_roughness);
    m.azimuthal_roughness = unit(hair.azimuthal_roughness);
    m
}
