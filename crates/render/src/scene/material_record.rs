//! The record of a material as rendered: every parameter, by its Standard Surface name, for EXR
//! headers and sample metadata (so a sample stays reproducible from its file alone).

use serde_json::Value;

use super::{Material, MaterialModel, ObjectClass, Scene};

/// Every parameter of a [`Material`] that affects rendering, under its Standard Surface name
/// where it has one (the `extras.lightfarm` keys) and its glTF name otherwise. Texture fields
/// are indices into [`Scene::textures`]; `subsurface_color: null` is the base colour.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MaterialRecord {
    pub name: String,
    pub model: MaterialModel,
    pub class: ObjectClass,
    /// Linear RGBA factor; A is the glTF alpha (coverage is `opacity`).
    pub base_color: [f32; 4],
    pub base_color_texture: Option<u32>,
    pub metalness: f32,
    pub specular: f32,
    pub specular_color: [f32; 3],
    pub specular_roughness: f32,
    #[serde(rename = "specular_IOR")]
    pub specular_ior: f32,
    pub specular_texture: Option<u32>,
    pub metallic_roughness_texture: Option<u32>,
    pub normal_texture: Option<u32>,
    pub normal_scale: f32,
    pub transmission: f32,
    pub opacity: f32,
    pub double_sided: bool,
    pub subsurface: f32,
    pub subsurface_color: Option<[f32; 3]>,
    pub subsurface_radius: [f32; 3],
    /// Metres.
    pub subsurface_scale: f32,
    pub subsurface_anisotropy: f32,
    pub coat: f32,
    pub coat_color: [f32; 3],
    pub coat_roughness: f32,
    #[serde(rename = "coat_IOR")]
    pub coat_ior: f32,
    pub sheen: f32,
    pub sheen_color: [f32; 3],
    pub sheen_roughness: f32,
    pub thin_walled: bool,
    /// The fibre parameters of a `hair` material (absent for every other model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hair: Option<HairRecord>,
}

/// A hair material's fibre: what it was given and the absorption the shader used.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HairRecord {
    pub melanin: f32,
    pub melanin_redness: f32,
    pub longitudinal_roughness: f32,
    pub azimuthal_roughness: f32,
    /// Degrees.
    pub cuticle_tilt: f32,
    /// Per unit radius, linear Rec.709 ([`crate::hair::sigma_a_from_melanin`]).
    pub sigma_a: [f32; 3],
    /// The σ set `sigma_a` came from.
    pub sigma_set: &'static str,
    /// The colour the albedo pass reports ([`crate::hair::color_of_sigma_a`]).
    pub albedo: [f32; 3],
}

impl From<&Material> for MaterialRecord {
    fn from(m: &Material) -> Self {
        // Destructured without `..`, so a new field of Material fails to compile here until
        // it is recorded.
        let Material {
            name,
            base_color,
            base_color_texture,
            metallic,
            roughness,
            metallic_roughness_texture,
            normal_texture,
            normal_scale,
            specular,
            specular_color,
            transmission,
            ior,
            double_sided,
            opacity,
            model,
            class,
            subsurface,
            subsurface_color,
            subsurface_radius,
            subsurface_scale,
            subsurface_anisotropy,
            coat,
            coat_color,
            coat_roughness,
            coat_ior,
            sheen,
            sheen_color,
            sheen_roughness,
            specular_texture,
            thin_walled,
            melanin,
            melanin_redness,
            longitudinal_roughness,
            azimuthal_roughness,
            cuticle_tilt_deg,
        } = m.clone();
        let hair = (model == MaterialModel::Hair).then(|| {
            let sigma_a = crate::hair::sigma_a_from_melanin(melanin, melanin_redness);
            HairRecord {
                melanin,
                melanin_redness,
                longitudinal_roughness,
                azimuthal_roughness,
                cuticle_tilt: cuticle_tilt_deg,
                sigma_a,
                sigma_set: crate::hair::SIGMA_SET,
                albedo: crate::hair::color_of_sigma_a(sigma_a, azimuthal_roughness),
            }
        });
        MaterialRecord {
            name,
            model,
            class,
            base_color,
            base_color_texture,
            metalness: metallic,
            specular,
            specular_color,
            specular_roughness: roughness,
            specular_ior: ior,
            specular_texture,
            metallic_roughness_texture,
            normal_texture,
            normal_scale,
            transmission,
            opacity,
            double_sided,
            subsurface,
            subsurface_color,
            subsurface_radius,
            subsurface_scale,
            subsurface_anisotropy,
            coat,
            coat_color,
            coat_roughness,
            coat_ior,
            sheen,
            sheen_color,
            sheen_roughness,
            thin_walled,
            hair,
        }
    }
}

/// Every material of `scene` as a JSON array of [`MaterialRecord`]s, in material order (the
/// index a triangle's material refers to), for EXR headers and sample metadata. Numbers are the
/// shortest decimals that read back as the same f32 (0.82, not 0.8199999928474426); a
/// non-finite one would be `null`.
pub fn materials_json(scene: &Scene) -> Value {
    let records: Vec<MaterialRecord> = scene.materials.iter().map(MaterialRecord::from).collect();
    // Through text: serde_json writes an f32 as its shortest decimal, while a Value built
    // directly would hold the f32 widened to f64.
    let text = serde_json::to_string(&records)
        .expect("a MaterialRecord is strings, numbers, booleans and arrays");
    serde_json::from_str(&text).expect("serde_json reads back what it wrote")
}
