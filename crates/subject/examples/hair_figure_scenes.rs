//! Writes the scenes of the README's hair figure: one sample of a dataset spec with its hair
//! recoloured to black, brown, blond and red, each as fibres (what lightfarm renders) and as
//! the camera-facing ribbons it rendered before (a glTF dielectric with the melanin colour).
//!
//! ```text
//! cargo run -p lightfarm-subject --example hair_figure_scenes -- SPEC INDEX OUT_DIR
//! ```
//!
//! Writes `OUT_DIR/{black,brown,blond,red}_{fibres,ribbons}.glb` with the sample's camera;
//! `bench/hair_figure.py` renders them and composes docs/hair.png.

use std::path::PathBuf;

use glam::{Mat4, Vec3};
use lightfarm_render::scene::{write_glb, Material, ObjectClass, Scene};
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;
use lightfarm_subject::hair::{hair_albedo, Strands};

/// (name, melanin, redness).
const COLOURS: [(&str, f64, f64); 4] = [
    ("black", 0.95, 0.1),
    ("brown", 0.6, 0.3),
    ("blond", 0.2, 0.25),
    ("red", 0.5, 0.95),
];

/// The fibres of `scene` as ribbons facing `eye`, in the ribbon material of before.
fn as_ribbons(scene: &Scene, eye: Vec3, melanin: f64, redness: f64) -> Scene {
    let mut out = scene.clone();
    let curves = std::mem::take(&mut out.curves);
    let albedo = hair_albedo(melanin, redness);
    for c in &curves {
        let strands = Strands {
            points: c.points.iter().map(|p| Vec3::from(*p)).collect(),
            widths: c.radii.iter().map(|r| 2.0 * r).collect(),
            offsets: c.offsets.clone(),
        };
        let material = Material {
            name: c.name.clone(),
            class: ObjectClass::Hair,
            base_color: [albedo[0], albedo[1], albedo[2], 1.0],
            metallic: 0.0,
            roughness: 0.35,
            specular: 1.0,
            ior: 1.55,
            double_sided: true,
            ..Material::default()
        };
        out.add_mesh_instance(strands.ribbon_mesh(eye, &c.name), material, Mat4::IDENTITY);
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [spec, index, out] = args.as_slice() else {
        return Err("usage: hair_figure_scenes SPEC INDEX OUT_DIR".into());
    };
    let catalog = Catalog::builtin()?;
    let spec = DatasetSpec::load(PathBuf::from(spec))?.validate(&catalog)?;
    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out)?;
    for (name, melanin, redness) in COLOURS {
        let mut sample = expand(&spec, index.parse()?)?;
        sample.hair.melanin = melanin;
        sample.hair.melanin_redness = redness;
        let mut a = lightfarm_subject::assemble(&sample, &catalog)?;
        a.scene.cameras = vec![a.camera];
        write_glb(&a.scene, &out.join(format!("{name}_fibres.glb")))?;
        let ribbons = as_ribbons(&a.scene, a.camera.position, melanin, redness);
        write_glb(&ribbons, &out.join(format!("{name}_ribbons.glb")))?;
        println!("{name}: melanin {melanin}, redness {redness}");
    }
    Ok(())
}
