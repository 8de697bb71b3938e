//! Generated people assemble like catalog heads: landmarks from their eyes, lids and lashes,
//! a fitted garment with the covered skin removed, and no NaN anywhere.

use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;
use lightfarm_subject::assemble;

#[test]
fn synthetic_people_assemble_with_garment_hair_and_lashes() {
    let catalog = Catalog::builtin().unwrap();
    let text = "name = \"syn\"\nseed = 11\ncount = 6\nwidth = 64\nheight = 64\n[assets]\nheads = [\"synthetic\"]\n[subject]\ngarment_probability = 1.0\nexpression_probability = 0.5\n";
    let spec = DatasetSpec::from_toml_str(text, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap();
    for i in 0..6 {
        let sample = expand(&spec, i).unwrap();
        let a = assemble(&sample, &catalog).unwrap_or_else(|e| panic!("sample {i}: {e}"));
        eprintln!("sample {i} {}: {:?}", sample.head.expression.name, a.stats);
        // Closed lids leave fewer lashes room to grow (as on the built-in heads).
        let min_lashes = if sample.head.expression.name == "blink" {
            40
        } else {
            200
        };
        assert!(
            a.stats.eyelash_strands > min_lashes,
            "sample {i}: {:?}",
            a.stats
        );
        assert!(
            a.stats.eyebrow_strands > 0 && a.stats.hair_strands > 0,
            "sample {i}: {:?}",
            a.stats
        );
        assert!(
            a.stats.hidden_skin_triangles > 0,
            "sample {i}: the garment hides no skin"
        );
        for m in &a.scene.meshes {
            assert!(
                m.positions.iter().flatten().all(|x| x.is_finite()),
                "sample {i}: NaN in {}",
                m.name
            );
        }
        let skin = a.scene.materials.iter().find(|m| m.name == "skin").unwrap();
        assert_eq!(skin.model, lightfarm_render::scene::MaterialModel::Skin);
        assert!(skin.base_color_texture.is_some() && skin.normal_texture.is_some());
    }
}
