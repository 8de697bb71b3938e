//! Material models and the `extras.lightfarm` schema of a glTF material.
//!
//! A glTF material renders with the glTF metallic-roughness mapping ([`MaterialModel::Gltf`])
//! unless its `extras` carry a `lightfarm` object:
//!
//! ```json
//! "extras": { "lightfarm": { "model": "skin", "subsurface_radius": [1.0, 0.4, 0.25] } }
//! ```
//!
//! `model` (required) selects a preset ([`Material::apply_model`]), which is applied first; every
//! other key is an Autodesk Standard Surface parameter that then overrides it ([`OVERRIDE_KEYS`],
//! ranges in [`apply_lightfarm`]). Anything the schema does not know, or a value outside its
//! range, fails the load with [`SceneError::BadMaterial`]; nothing is clamped or skipped.

use std::path::Path;

use serde_json::Value;

use super::{Material, MaterialModel, ObjectClass, SceneError};

/// The models `extras.lightfarm.model` may name (every model but `gltf`, which is what a
/// material without `extras.lightfarm` gets).
pub const EXTRAS_MODELS: [MaterialModel; 10] = [
    MaterialModel::Skin,
    MaterialModel::Eye,
    MaterialModel::Mouth,
    MaterialModel::Teeth,
    MaterialModel::Cloth,
    MaterialModel::Plastic,
    MaterialModel::Metal,
    MaterialModel::Lens,
    MaterialModel::Cornea,
    MaterialModel::Hair,
];

/// The Standard Surface parameters `extras.lightfarm` may override, besides `model`.
pub const OVERRIDE_KEYS: [&str; 26] = [
    "base_color",
    "metalness",
    "specular",
    "specular_color",
    "specular_roughness",
    "specular_IOR",
    "subsurface",
    "subsurface_color",
    "subsurface_radius",
    "subsurface_scale",
    "subsurface_anisotropy",
    "coat",
    "coat_color",
    "coat_roughness",
    "coat_IOR",
    "sheen",
    "sheen_color",
    "sheen_roughness",
    "transmission",
    "opacity",
    "thin_walled",
    "melanin",
    "melanin_redness",
    "longitudinal_roughness",
    "azimuthal_roughness",
    "cuticle_tilt",
];

impl MaterialModel {
    pub const ALL: [MaterialModel; 11] = [
        MaterialModel::Gltf,
        MaterialModel::Skin,
        MaterialModel::Eye,
        MaterialModel::Mouth,
        MaterialModel::Teeth,
        MaterialModel::Cloth,
        MaterialModel::Plastic,
        MaterialModel::Metal,
        MaterialModel::Lens,
        MaterialModel::Cornea,
        MaterialModel::Hair,
    ];

    /// The model called `name` ([`MaterialModel::name`], exact, lower case), `None` for
    /// anything else.
    pub fn parse(name: &str) -> Option<MaterialModel> {
        MaterialModel::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The name used in `extras.lightfarm.model`, in records and in logs.
    pub fn name(self) -> &'static str {
        match self {
            MaterialModel::Gltf => "gltf",
            MaterialModel::Skin => "skin",
            MaterialModel::Eye => "eye",
            MaterialModel::Mouth => "mouth",
            MaterialModel::Teeth => "teeth",
            MaterialModel::Cloth => "cloth",
            MaterialModel::Plastic => "plastic",
            MaterialModel::Metal => "metal",
            MaterialModel::Lens => "lens",
            MaterialModel::Cornea => "cornea",
            MaterialModel::Hair => "hair",
        }
    }

    /// The object class the preset gives a material (`Other` for `gltf`, `plastic` and
    /// `metal`, whose role only the scene's assembler knows: a frame, a headset).
    pub fn class(self) -> ObjectClass {
        match self {
            MaterialModel::Skin => ObjectClass::Skin,
            MaterialModel::Eye | MaterialModel::Cornea => ObjectClass::Eyes,
            MaterialModel::Mouth | MaterialModel::Teeth => ObjectClass::Mouth,
            MaterialModel::Cloth => ObjectClass::Garment,
            MaterialModel::Lens => ObjectClass::Lens,
            MaterialModel::Hair => ObjectClass::Hair,
            MaterialModel::Gltf | MaterialModel::Plastic | MaterialModel::Metal => {
                ObjectClass::Other
            }
        }
    }
}

impl std::fmt::Display for MaterialModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Material {
    /// Turns this material into `model`: sets `model`, the preset's class and the parameters
    /// the preset decides, and keeps everything else as it is (the file's base colour and
    /// textures, normal map, opacity, double-sidedness, and the parameters listed as kept).
    /// Distances are metres.
    ///
    /// | model | sets | keeps | class |
    /// |---|---|---|---|
    /// | `gltf` | nothing | everything | unchanged |
    /// | `skin` | the paper's aiStandardSurface: subsurface 0.95, subsurface_color = base colour (with its texture), radius (1, 0.35, 0.2), scale 0.00225 (0.225 cm), anisotropy 0; specular 1, specular_color 0.82, roughness 0.4, IOR 1.5 (Arnold's default); coat 0.1 (colour 1, roughness 0.25, IOR 1.5); sheen 0.1 (colour 1, roughness 0.3); metalness 0, transmission 0 | base colour | skin |
    /// | `eye` | subsurface 0, sheen 0, specular 1, specular_color 1, roughness 0.1, IOR 1.5, coat 0.5 (roughness 0.1, IOR 1.376: the cornea's), metalness 0 | base colour, coat colour | eyes |
    /// | `mouth` | subsurface 0.6, radius (1, 0.4, 0.25), scale 0.001; specular 1, roughness 0.3, coat 0.3 (roughness 0.1, IOR 1.33: saliva), sheen 0, metalness 0 | base colour, subsurface colour | mouth |
    /// | `teeth` | subsurface 0.3, radius (1, 0.8, 0.6), scale 0.0005; specular 1, roughness 0.2, IOR 1.6 (enamel), coat 0, metalness 0 | base colour, subsurface colour | mouth |
    /// | `cloth` | subsurface 0, specular 1, IOR 1.5, coat 0, sheen 0, metalness 0 | colour, roughness | garment |
    /// | `plastic` | specular 1, IOR 1.5, metalness 0 | colour, roughness | other |
    /// | `metal` | metalness 1 | colour (= F0), roughness | other |
    /// | `lens` | transmission 1, metalness 0 | IOR (1.5 unless the file has KHR_materials_ior), colour, roughness | lens |
    /// | `cornea` | transmission 1, thin_walled, IOR 1.376, specular 1, specular_color 1, metalness 0, opacity 1 (MakeHuman's BLEND 0.08 stood in for clear) | nothing else matters to a clear sheet | eyes |
    /// | `hair` | the Chiang 2016 fibre (curves only): IOR 1.55, longitudinal and azimuthal roughness 0.3, cuticle tilt 2°, opacity 1, transmission 0 | melanin, melanin redness (absorption) | hair |
    pub fn apply_model(&mut self, model: MaterialModel) {
        self.model = model;
        if model == MaterialModel::Gltf {
            return;
        }
        self.class = model.class();
        match model {
            MaterialModel::Gltf => {}
            MaterialModel::Skin => {
                self.subsurface = 0.95;
                self.subsurface_color = None;
                self.subsurface_radius = [1.0, 0.35, 0.2];
                self.subsurface_scale = 0.00225;
                self.subsurface_anisotropy = 0.0;
                self.specular = 1.0;
                self.specular_color = [0.82; 3];
                self.roughness = 0.4;
                self.ior = 1.5;
                self.coat = 0.1;
                self.coat_color = [1.0; 3];
                self.coat_roughness = 0.25;
                self.coat_ior = 1.5;
                self.sheen = 0.1;
                self.sheen_color = [1.0; 3];
                self.sheen_roughness = 0.3;
                self.metallic = 0.0;
                self.transmission = 0.0;
            }
            MaterialModel::Eye => {
                self.subsurface = 0.0;
                self.sheen = 0.0;
                self.specular = 1.0;
                self.specular_color = [1.0; 3];
                self.roughness = 0.1;
                self.ior = 1.5;
                self.coat = 0.5;
                self.coat_roughness = 0.1;
                self.coat_ior = 1.376;
                self.metallic = 0.0;
            }
            MaterialModel::Mouth => {
                self.subsurface = 0.6;
                self.subsurface_radius = [1.0, 0.4, 0.25];
                self.subsurface_scale = 0.001;
                self.specular = 1.0;
                self.roughness = 0.3;
                self.coat = 0.3;
                self.coat_roughness = 0.1;
                self.coat_ior = 1.33;
                self.sheen = 0.0;
                self.metallic = 0.0;
            }
            MaterialModel::Teeth => {
                self.subsurface = 0.3;
                self.subsurface_radius = [1.0, 0.8, 0.6];
                self.subsurface_scale = 0.0005;
                self.specular = 1.0;
                self.roughness = 0.2;
                self.ior = 1.6;
                self.coat = 0.0;
                self.metallic = 0.0;
            }
            MaterialModel::Cloth => {
                self.subsurface = 0.0;
                self.specular = 1.0;
                self.ior = 1.5;
                self.coat = 0.0;
                self.sheen = 0.0;
                self.metallic = 0.0;
            }
            MaterialModel::Plastic => {
                self.specular = 1.0;
                self.ior = 1.5;
                self.metallic = 0.0;
            }
            MaterialModel::Metal => {
                self.metallic = 1.0;
            }
            MaterialModel::Lens => {
                self.transmission = 1.0;
                self.metallic = 0.0;
            }
            MaterialModel::Cornea => {
                self.transmission = 1.0;
                self.thin_walled = true;
                self.ior = 1.376;
                self.specular = 1.0;
                self.specular_color = [1.0; 3];
                self.metallic = 0.0;
                self.opacity = 1.0;
            }
            MaterialModel::Hair => {
                self.ior = 1.55;
                self.longitudinal_roughness = 0.3;
                self.azimuthal_roughness = 0.3;
                self.cuticle_tilt_deg = 2.0;
                self.opacity = 1.0;
                self.transmission = 0.0;
                self.metallic = 0.0;
            }
        }
    }
}

/// Applies a material's glTF `extras` (the raw JSON): its `lightfarm` object, when there is one,
/// through [`apply_lightfarm`]. Extras that are not an object, and keys other than `lightfarm`,
/// belong to other tools and are ignored.
pub(crate) fn apply_extras(
    material: &mut Material,
    extras: &str,
    path: &Path,
) -> Result<(), SceneError> {
    let bad = |key: &str, reason: String| SceneError::BadMaterial {
        path: path.to_path_buf(),
        material: material.name.clone(),
        key: key.to_string(),
        reason,
    };
    let value: Value = serde_json::from_str(extras)
        .map_err(|e| bad("extras", format!("is not valid JSON ({e})")))?;
    match value.get("lightfarm") {
        Some(lightfarm) => apply_lightfarm(material, lightfarm, path),
        None => Ok(()),
    }
}

fn model_list() -> String {
    EXTRAS_MODELS
        .iter()
        .map(|m| format!("\"{m}\""))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What kind of value a key takes, with its range.
#[derive(Clone, Copy)]
enum Kind {
    /// One number in [lo, hi] (`open_lo`: lo itself excluded).
    Scalar { lo: f32, hi: f32, open_lo: bool },
    /// [r, g, b] in [0, 1], or one number for grey.
    Colour,
    /// [r, g, b], each in (0, 100].
    Radius,
    /// true or false.
    Bool,
}

const UNIT: Kind = Kind::Scalar {
    lo: 0.0,
    hi: 1.0,
    open_lo: false,
};
const IOR: Kind = Kind::Scalar {
    lo: 1.0,
    hi: 3.0,
    open_lo: false,
};

fn kind_of(key: &str) -> Option<Kind> {
    Some(match key {
        "base_color" | "specular_color" | "subsurface_color" | "coat_color" | "sheen_color" => {
            Kind::Colour
        }
        "metalness"
        | "specular"
        | "specular_roughness"
        | "subsurface"
        | "coat"
        | "coat_roughness"
        | "sheen"
        | "sheen_roughness"
        | "transmission"
        | "opacity"
        | "melanin"
        | "melanin_redness"
        | "longitudinal_roughness"
        | "azimuthal_roughness" => UNIT,
        "cuticle_tilt" => Kind::Scalar {
            lo: -10.0,
            hi: 10.0,
            open_lo: false,
        },
        "specular_IOR" | "coat_IOR" => IOR,
        "subsurface_radius" => Kind::Radius,
        "thin_walled" => Kind::Bool,
        "subsurface_scale" => Kind::Scalar {
            lo: 0.0,
            hi: 1.0,
            open_lo: true,
        },
        "subsurface_anisotropy" => Kind::Scalar {
            lo: -0.95,
            hi: 0.95,
            open_lo: false,
        },
        _ => return None,
    })
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

fn range_text(lo: f32, hi: f32, open_lo: bool) -> String {
    format!("{}{lo}, {hi}]", if open_lo { "(" } else { "[" })
}

/// A number of `v` as a finite f32, or why not.
fn finite(v: &Value, expected: &str) -> Result<f32, String> {
    let Some(x) = v.as_f64() else {
        return Err(format!("must be {expected}, not {}", type_name(v)));
    };
    let x32 = x as f32;
    if !x32.is_finite() {
        return Err(format!(
            "is {v}, not a finite 32-bit number; expected {expected}"
        ));
    }
    Ok(x32)
}

fn scalar(v: &Value, lo: f32, hi: f32, open_lo: bool) -> Result<f32, String> {
    let range = range_text(lo, hi, open_lo);
    let x = finite(v, &format!("a number in {range}"))?;
    let below = if open_lo { x <= lo } else { x < lo };
    if below || x > hi {
        return Err(format!("is {x}, outside {range}"));
    }
    Ok(x)
}

fn rgb(v: &Value, kind: Kind) -> Result<[f32; 3], String> {
    let (expected, lo, hi, open_lo) = match kind {
        Kind::Radius => ("[r, g, b]: 3 numbers in (0, 100]", 0.0, 100.0, true),
        _ => (
            "[r, g, b] (3 numbers in [0, 1]) or one number in [0, 1] for grey",
            0.0,
            1.0,
            false,
        ),
    };
    let range = range_text(lo, hi, open_lo);
    let check = |x: f32| {
        let below = if open_lo { x <= lo } else { x < lo };
        if below || x > hi {
            Err(format!("has {x}, outside {range}; expected {expected}"))
        } else {
            Ok(x)
        }
    };
    match v {
        Value::Number(_) if !matches!(kind, Kind::Radius) => {
            let x = check(finite(v, expected)?)?;
            Ok([x; 3])
        }
        Value::Array(items) if items.len() == 3 => {
            let mut out = [0.0; 3];
            for (o, item) in out.iter_mut().zip(items) {
                *o = check(finite(item, expected).map_err(|_| {
                    format!("has {item}, which is not a finite number; expected {expected}")
                })?)?;
            }
            Ok(out)
        }
        Value::Array(items) => Err(format!("has {} elements; expected {expected}", items.len())),
        other => Err(format!("must be {expected}, not {}", type_name(other))),
    }
}

/// Applies one `extras.lightfarm` object to `material`: the preset its `model` names
/// ([`Material::apply_model`]), then each override. `path` is the file errors name.
///
/// Keys ([`OVERRIDE_KEYS`]) and ranges: `base_color`, `specular_color`, `subsurface_color`,
/// `coat_color`, `sheen_color`: [r, g, b] in [0, 1] (linear) or one number for grey
/// (`subsurface_color` may also be `null`: the base colour with its texture; `base_color`
/// multiplies the base-colour texture, as glTF's factor, and keeps the alpha); `metalness`,
/// `specular`, `specular_roughness`, `subsurface`, `coat`, `coat_roughness`, `sheen`,
/// `sheen_roughness`, `transmission`, `opacity` in [0, 1]; `specular_IOR`, `coat_IOR` in
/// [1, 3]; `subsurface_radius` [r, g, b], each in (0, 100] (in units of the scale);
/// `subsurface_scale` in (0, 1] metres; `subsurface_anisotropy` in [-0.95, 0.95];
/// `thin_walled` true or false; for `hair`: `melanin`, `melanin_redness`,
/// `longitudinal_roughness`, `azimuthal_roughness` in [0, 1], `cuticle_tilt` in [-10, 10]
/// degrees (and `specular_IOR`).
pub fn apply_lightfarm(
    material: &mut Material,
    lightfarm: &Value,
    path: &Path,
) -> Result<(), SceneError> {
    let name = material.name.clone();
    let bad = |key: &str, reason: String| SceneError::BadMaterial {
        path: path.to_path_buf(),
        material: name.clone(),
        key: if key.is_empty() {
            "extras.lightfarm".to_string()
        } else {
            format!("extras.lightfarm.{key}")
        },
        reason,
    };
    let Value::Object(fields) = lightfarm else {
        return Err(bad(
            "",
            format!(
                "must be an object {{\"model\": ..., overrides}}, not {}",
                type_name(lightfarm)
            ),
        ));
    };
    let model = match fields.get("model") {
        None => {
            return Err(bad(
                "model",
                format!(
                    "is missing (it is required in extras.lightfarm); use one of {}",
                    model_list()
                ),
            ))
        }
        Some(Value::String(s)) => EXTRAS_MODELS
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                bad(
                    "model",
                    format!("is \"{s}\", not a model; use one of {}", model_list()),
                )
            })?,
        Some(other) => {
            return Err(bad(
                "model",
                format!(
                    "must be a string, one of {}, not {}",
                    model_list(),
                    type_name(other)
                ),
            ))
        }
    };
    // Every key is checked before anything is changed.
    let mut overrides = Vec::with_capacity(fields.len());
    for (key, value) in fields {
        if key == "model" {
            continue;
        }
        let Some(kind) = kind_of(key) else {
            return Err(bad(
                key,
                format!(
                    "is not a key of extras.lightfarm; the keys are model, {}",
                    OVERRIDE_KEYS.join(", ")
                ),
            ));
        };
        let parsed = match (key.as_str(), value, kind) {
            ("subsurface_color", Value::Null, _) => Override::SubsurfaceBase,
            (_, Value::Bool(b), Kind::Bool) => Override::Bool(*b),
            (_, _, Kind::Bool) => {
                return Err(bad(
                    key,
                    format!("must be true or false, not {}", type_name(value)),
                ))
            }
            (_, _, Kind::Scalar { lo, hi, open_lo }) => {
                Override::Scalar(scalar(value, lo, hi, open_lo).map_err(|r| bad(key, r))?)
            }
            (_, _, Kind::Colour | Kind::Radius) => {
                Override::Rgb(rgb(value, kind).map_err(|r| bad(key, r))?)
            }
        };
        overrides.push((key.as_str(), parsed));
    }
    material.apply_model(model);
    for (key, value) in overrides {
        set(material, key, value);
    }
    Ok(())
}

enum Override {
    Scalar(f32),
    Bool(bool),
    Rgb([f32; 3]),
    /// `subsurface_color: null`.
    SubsurfaceBase,
}

fn set(m: &mut Material, key: &str, value: Override) {
    match value {
        Override::SubsurfaceBase => m.subsurface_color = None,
        Override::Bool(b) => match key {
            "thin_walled" => m.thin_walled = b,
            _ => unreachable!("{key} is checked by kind_of"),
        },
        Override::Rgb(c) => match key {
            "base_color" => m.base_color = [c[0], c[1], c[2], m.base_color[3]],
            "specular_color" => m.specular_color = c,
            "subsurface_color" => m.subsurface_color = Some(c),
            "subsurface_radius" => m.subsurface_radius = c,
            "coat_color" => m.coat_color = c,
            "sheen_color" => m.sheen_color = c,
            _ => unreachable!("{key} is checked by kind_of"),
        },
        Override::Scalar(x) => match key {
            "metalness" => m.metallic = x,
            "specular" => m.specular = x,
            "specular_roughness" => m.roughness = x,
            "specular_IOR" => m.ior = x,
            "subsurface" => m.subsurface = x,
            "subsurface_scale" => m.subsurface_scale = x,
            "subsurface_anisotropy" => m.subsurface_anisotropy = x,
            "coat" => m.coat = x,
            "coat_roughness" => m.coat_roughness = x,
            "coat_IOR" => m.coat_ior = x,
            "sheen" => m.sheen = x,
            "sheen_roughness" => m.sheen_roughness = x,
            "transmission" => m.transmission = x,
            "opacity" => m.opacity = x,
            "melanin" => m.melanin = x,
            "melanin_redness" => m.melanin_redness = x,
            "longitudinal_roughness" => m.longitudinal_roughness = x,
            "azimuthal_roughness" => m.azimuthal_roughness = x,
            "cuticle_tilt" => m.cuticle_tilt_deg = x,
            _ => unreachable!("{key} is checked by kind_of"),
        },
    }
}
