//! Writes the procedural glasses assets.
//!
//! ```text
//! cargo run -p lightfarm-subject --example make_glasses [ROUND.glb RECT.glb]
//! ```
//!
//! Defaults to `assets/accessories/glasses_round.glb` and `glasses_rect.glb` in the workspace.
//! The files are bit-reproducible; after changing the generator, rerun this and update their
//! `blake3` in `assets/catalog.toml`.

use std::path::PathBuf;

use lightfarm_render::scene::write_glb;
use lightfarm_subject::glasses::{procedural_glasses, FrameStyle};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() > 2 || args.iter().any(|a| a.starts_with('-')) {
        return Err("usage: make_glasses [ROUND.glb RECT.glb]".into());
    }
    let assets = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../assets/accessories"
    ));
    let jobs = [
        (FrameStyle::Round, args.first(), "glasses_round.glb"),
        (FrameStyle::Rectangular, args.get(1), "glasses_rect.glb"),
    ];
    for (style, arg, default) in jobs {
        let path = arg.map_or_else(|| assets.join(default), PathBuf::from);
        let scene = procedural_glasses(style);
        write_glb(&scene, &path)?;
        let bytes = std::fs::metadata(&path)?.len();
        println!(
            "{style:?}: {} ({} triangles, {bytes} bytes)",
            path.display(),
            scene.triangle_count()
        );
    }
    Ok(())
}
