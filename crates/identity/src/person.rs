//! Synthetic person *k*: its parameters (from `lightfarm_scene::identity`) → a head scene with
//! generated skin textures, ready for `lightfarm_subject::Head::from_scene`.

use glam::Mat4;
use lightfarm_render::scene::{Instance, Material, Scene};
use lightfarm_scene::identity::{SyntheticIdentity, GENERATOR};
use serde::Serialize;

use crate::error::IdentityError;
use crate::eyes::{eye_texture, EyeLook};
use crate::makehuman::bust::{
    self, Shape, HEAD_ISLAND, SLOTS, SLOT_BODY, SLOT_CORNEA, SLOT_EYES, SLOT_FACE,
    SLOT_FACE_CENTRE, SLOT_TEETH, SLOT_TONGUE,
};
use crate::makehuman::macros::{age_slider, Macros};
use crate::makehuman::MakeHuman;
use crate::skin::chromophore::{
    category_ita_bounds, ita_deg, melanin_for_ita, Chromophores, MELANIN_MAX,
};
use crate::skin::maps::{albedo_table, skin_textures, SkinLook, CHEEK_BLOOD};

/// Texture sizes: the face (brows to chin, temple to temple), the rest of the head island
/// (scalp, forehead edge), the atlas of the rest (neck, shoulders, ears) and the eyeballs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TextureSize {
    pub face: u32,
    pub island: [u32; 2],
    pub atlas: u32,
    pub eyes: u32,
}

impl TextureSize {
    /// For 512² portraits: the face fills ~1,450 × 1,370 of its 1,536² texels, several
    /// texels per pixel of a 512² head-and-shoulders portrait.
    pub const FULL: TextureSize = TextureSize {
        face: 1536,
        island: [1024, 2048],
        atlas: 1024,
        eyes: 1024,
    };
    /// For tests and previews of a few dozen pixels.
    pub const SMALL: TextureSize = TextureSize {
        face: 128,
        island: [160, 320],
        atlas: 128,
        eyes: 128,
    };
}

/// The ITA° range used inside the open-ended outer categories, so the lightest and darkest
/// people stay within measured skin (Del Bino & Bernerd 2013 report ITA from about +70° to
/// −60°).
const ITA_LIMITS: (f64, f64) = (-55.0, 68.0);
/// Oxygen saturation of skin blood (Jimenez et al. 2010 use 0.75 for venous-arterial mix).
const OXYGENATION: f64 = 0.75;

/// What was derived while generating, for logs and tests (every input is in the sample JSON).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PersonRecord {
    pub generator: String,
    pub identity: u64,
    pub chromophores: Chromophores,
    /// ITA° of the base albedo (no regional variation), and its category.
    pub ita_deg: f64,
    pub category: u8,
    pub beard: f32,
    pub shape_targets: usize,
}

pub struct Person {
    pub scene: Scene,
    pub record: PersonRecord,
}

fn generate_error(id: &SyntheticIdentity, reason: impl Into<String>) -> IdentityError {
    IdentityError::Generate {
        identity: format!("synthetic-{:07}", id.id),
        reason: reason.into(),
    }
}

/// The skin chromophores of `id`: the melanin that puts the cheek's ITA° at `tone` within the
/// category's interval (the cheek's blood included).
pub fn chromophores(id: &SyntheticIdentity) -> Chromophores {
    let (lo, hi) = category_ita_bounds(id.skin.category);
    let (lo, hi) = (lo.max(ITA_LIMITS.0), hi.min(ITA_LIMITS.1));
    let ita = hi - id.skin.tone.clamp(0.0, 1.0) * (hi - lo);
    let mut c = Chromophores {
        melanin: 0.0,
        eumelanin_ratio: id.skin.eumelanin_ratio,
        haemoglobin: id.skin.haemoglobin,
        oxygenation: OXYGENATION,
    };
    // The tone is the cheek's, which has more blood than the base skin.
    let cheek = Chromophores {
        haemoglobin: c.haemoglobin * (1.0 + f64::from(CHEEK_BLOOD)),
        ..c
    };
    // Unreachable targets (very light skin with much blood) take the nearest end.
    c.melanin = melanin_for_ita(ita, &cheek).unwrap_or(if ita > 0.0 { 0.0 } else { MELANIN_MAX });
    c
}

/// The MakeHuman shape of `id`.
pub fn shape_of(id: &SyntheticIdentity) -> Shape {
    Shape {
        macros: Macros {
            gender: id.gender,
            age: age_slider(id.age_years),
            muscle: id.muscle,
            weight: id.weight,
            ethnicity: id.ancestry,
        },
        seed: id.shape_seed,
        detail_sd: id.face_shape_sd,
        asymmetry_sd: id.asymmetry_sd,
        ict: id.ict_shape.clone(),
    }
}

/// Builds person `id` with textures of `size`.
pub fn generate(
    model: &MakeHuman,
    id: &SyntheticIdentity,
    size: TextureSize,
) -> Result<Person, IdentityError> {
    if id.generator != GENERATOR {
        return Err(generate_error(
            id,
            format!(
                "was made by generator {:?}; this build has {GENERATOR:?}: re-expand the spec",
                id.generator
            ),
        ));
    }
    let shape = shape_of(id);
    let bust = bust::build(model, &shape).map_err(|reason| generate_error(id, reason))?;
    let base = chromophores(id);
    let ita = ita_deg(base.albedo());
    // Stubble: men from their late teens, a per-person strength.
    let adult = ((id.age_years - 16.0) / 10.0).clamp(0.0, 1.0);
    let beard_draw = crate::skin::noise::lattice(7, 11, id.skin.texture_seed);
    let beard = (id.gender * adult * (0.2 + 0.8 * beard_draw as f64)) as f32;
    let look = SkinLook {
        base,
        freckles: id.skin.freckles as f32,
        beard,
        seed: id.skin.texture_seed,
    };

    let table = albedo_table(&look);
    let mut scene = Scene::default();
    let add_skin = |scene: &mut Scene, name: &str, rect: [[f32; 2]; 2], w: u32, h: u32| {
        let t = skin_textures(model, &look, &table, rect, w, h);
        let first = scene.textures.len() as u32;
        scene
            .textures
            .extend([t.albedo, t.roughness, t.specular, t.normal]);
        Material {
            name: name.to_owned(),
            base_color_texture: Some(first),
            metallic: 0.0,
            roughness: 1.0,
            metallic_roughness_texture: Some(first + 1),
            specular_texture: Some(first + 2),
            normal_texture: Some(first + 3),
            ..Material::default()
        }
    };
    let face = add_skin(
        &mut scene,
        "skin_face",
        model.face_uv.face_rect,
        size.face,
        size.face,
    );
    let island = add_skin(
        &mut scene,
        "skin",
        HEAD_ISLAND,
        size.island[0],
        size.island[1],
    );
    let body = add_skin(
        &mut scene,
        "skin_body",
        [[0.0, 0.0], [1.0, 1.0]],
        size.atlas,
        size.atlas,
    );
    let eye_tex = scene.textures.len() as u32;
    // Sclera vessels show more with age; how much is the person's own.
    let age = ((id.age_years - 18.0) / 58.0).clamp(0.0, 1.0) as f32;
    let eye_look = EyeLook {
        iris_melanin: id.iris_melanin as f32,
        vessels: 0.25
            + 0.45 * age
            + 0.3 * crate::skin::noise::lattice(13, 17, id.skin.texture_seed),
        seed: id.skin.texture_seed ^ 0xE7E5,
    };
    scene.textures.push(eye_texture(
        &model.eye_texture,
        &model.irises,
        &eye_look,
        size.eyes,
    ));
    let plain = |name: &str, rgb: [f32; 3], roughness: f32| Material {
        name: name.to_owned(),
        base_color: [rgb[0], rgb[1], rgb[2], 1.0],
        metallic: 0.0,
        roughness,
        ..Material::default()
    };
    // Slot order of `bust::SLOT_*`.
    let mut materials = vec![Material::default(); SLOTS];
    materials[SLOT_FACE as usize] = island;
    materials[SLOT_FACE_CENTRE as usize] = face;
    materials[SLOT_BODY as usize] = body;
    materials[SLOT_EYES as usize] = Material {
        base_color_texture: Some(eye_tex),
        ..plain("eyes", [1.0; 3], 0.05)
    };
    materials[SLOT_CORNEA as usize] = Material {
        opacity: 0.08,
        ..plain("cornea", [1.0; 3], 0.0)
    };
    materials[SLOT_TEETH as usize] = plain("teeth", [0.80, 0.76, 0.66], 0.3);
    materials[SLOT_TONGUE as usize] = plain("tongue", [0.55, 0.20, 0.20], 0.4);
    scene.materials = materials;
    let shape_targets = bust.weights.len();
    scene.meshes.push(bust.mesh);
    scene.instances.push(Instance {
        mesh: 0,
        transform: Mat4::IDENTITY,
    });
    Ok(Person {
        scene,
        record: PersonRecord {
            generator: GENERATOR.to_owned(),
            identity: id.id,
            chromophores: base,
            ita_deg: ita,
            category: crate::skin::chromophore::skin_category(ita),
            beard,
            shape_targets,
        },
    })
}
