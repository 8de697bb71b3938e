//! Times generating synthetic people: model load once (MakeHuman, and the ICT Face Model with
//! its match to the base mesh), then per person the bust (shape, eyes, 52 Face Units with their
//! normals), the same without the ICT modes, and the person with full-size and small skin
//! textures.
//!
//!     cargo run --release -p lightfarm-identity --example generation_cost -- [PEOPLE]
//!
//! Reads the model files of the asset pack (`./scripts/fetch-models.sh` first).

use std::path::PathBuf;
use std::time::Instant;

use lightfarm_identity::makehuman::{bust, MakeHuman, CORE_FILE, TARGETS_FILE};
use lightfarm_identity::person::{generate, shape_of, TextureSize};
use lightfarm_scene::identity::{sample_identity, IdentitySpec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: u64 = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(10);
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let t = Instant::now();
    let model = MakeHuman::load(&assets.join(CORE_FILE), &assets.join(TARGETS_FILE))?
        .with_ict(&assets.join(lightfarm_identity::ict::ICT_FILE))?;
    println!("model load: {:.2} s", t.elapsed().as_secs_f64());
    let spec = IdentitySpec::default();
    let no_ict = IdentitySpec {
        ict_shape_sd: 0.0,
        ..IdentitySpec::default()
    };
    let (mut mesh_s, mut plain_s, mut full_s, mut small_s) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for k in 0..n {
        let id = sample_identity(&spec, 7, k);
        let t = Instant::now();
        bust::build(&model, &shape_of(&id))?;
        mesh_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        bust::build(&model, &shape_of(&sample_identity(&no_ict, 7, k)))?;
        plain_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        generate(&model, &id, TextureSize::FULL)?;
        full_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        generate(&model, &id, TextureSize::SMALL)?;
        small_s.push(t.elapsed().as_secs_f64());
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        format!(
            "min {:.3} s, median {:.3} s, max {:.3} s",
            v[0],
            v[v.len() / 2],
            v[v.len() - 1]
        )
    };
    println!("{n} people");
    println!("  bust mesh only:            {}", stats(&mut mesh_s));
    println!("  bust mesh without ICT:     {}", stats(&mut plain_s));
    println!("  person, full textures:     {}", stats(&mut full_s));
    println!("  person, small textures:    {}", stats(&mut small_s));
    Ok(())
}
