//! Writes the generated textures of synthetic people as PNGs, to look at them: per person
//! `synthetic-000000k_<material>_<map>.png` (albedo, roughness, specular, normal; eyes).
//!
//!     cargo run --release -p lightfarm-identity --example person_textures -- OUT_DIR [SEED] [K...]
//!
//! Reads the model files of the asset pack (`./scripts/fetch-models.sh` first).

use std::path::PathBuf;

use lightfarm_identity::makehuman::{MakeHuman, CORE_FILE, TARGETS_FILE};
use lightfarm_identity::person::{generate, TextureSize};
use lightfarm_scene::identity::{identity_name, sample_identity, IdentitySpec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(
        args.next()
            .ok_or("usage: person_textures OUT_DIR [SEED] [K...]")?,
    );
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(7);
    let mut ids: Vec<u64> = args.map(|s| s.parse()).collect::<Result<_, _>>()?;
    if ids.is_empty() {
        ids = vec![0, 1, 2];
    }
    std::fs::create_dir_all(&out)?;
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let model = MakeHuman::load(&assets.join(CORE_FILE), &assets.join(TARGETS_FILE))?
        .with_ict(&assets.join(lightfarm_identity::ict::ICT_FILE))?;
    for k in ids {
        let id = sample_identity(&IdentitySpec::default(), seed, k);
        let person = generate(&model, &id, TextureSize::FULL)?;
        let s = &person.scene;
        let mut written = vec![false; s.textures.len()];
        for m in &s.materials {
            let maps = [
                ("albedo", m.base_color_texture),
                ("roughness", m.metallic_roughness_texture),
                ("specular", m.specular_texture),
                ("normal", m.normal_texture),
            ];
            for (map, t) in maps {
                let Some(t) = t else { continue };
                let tex = &s.textures[t as usize];
                let path = out.join(format!("{}_{}_{map}.png", identity_name(k), m.name));
                image::save_buffer(
                    &path,
                    &tex.rgba8,
                    tex.width,
                    tex.height,
                    image::ColorType::Rgba8,
                )?;
                written[t as usize] = true;
            }
        }
        println!("{}: {:?}", identity_name(k), person.record);
    }
    Ok(())
}
