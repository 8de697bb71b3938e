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

/// Sample `index` of `spec` with its person replaced by identity `k`, so consecutive
/// identities can be checked whatever the spec's identity draw.
fn with_identity(
    spec: &lightfarm_scene::spec::ResolvedSpec,
    index: u64,
    k: u64,
) -> lightfarm_scene::expand::SampleSpec {
    let mut sample = expand(spec, index).unwrap();
    let people = spec.synthetic.as_ref().unwrap();
    let head = sample.head.synthetic.as_mut().unwrap();
    head.identity = lightfarm_scene::identity::sample_identity(&people.spec, spec.seed, k);
    sample
}

/// A hundred consecutive identities, each dressed and groomed: finite unit-normal geometry,
/// both eyes inside the head, no skin through the garment (`lightfarm people check` runs
/// 1,000 with renders; see the README).
#[test]
fn a_hundred_consecutive_people_assemble_cleanly() {
    let catalog = Catalog::builtin().unwrap();
    let text = "name = \"syn\"\nseed = 5\ncount = 100\nwidth = 32\nheight = 32\n[assets]\nheads = [\"synthetic\"]\n[subject]\ngarment_probability = 1.0\n";
    let spec = DatasetSpec::from_toml_str(text, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap();
    let mut poking = Vec::new();
    for k in 0..100 {
        let sample = with_identity(&spec, k, k);
        let a = assemble(&sample, &catalog).unwrap_or_else(|e| panic!("identity {k}: {e}"));
        let problems = lightfarm_subject::sanity::check_assembly(&a);
        assert!(problems.is_empty(), "identity {k}: {problems:?}");
        assert!(
            a.stats.hidden_skin_triangles > 0,
            "identity {k}: garment hides no skin"
        );
        poking.push(a.stats.skin_through_garment);
    }
    eprintln!("skin vertices through the garment per person: {poking:?}");
}

/// A worker keeps generated people: the second sample of a person is built from the cache and
/// is identical to the first.
#[test]
fn a_cached_person_is_the_same_person() {
    let catalog = Catalog::builtin().unwrap();
    let text = "name = \"syn\"\nseed = 3\ncount = 4\nwidth = 48\nheight = 48\n[assets]\nheads = [\"synthetic\"]\n[subject]\nexpression_probability = 0.0\n";
    let spec = DatasetSpec::from_toml_str(text, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap();
    let sample = with_identity(&spec, 0, 123_456);
    let first = assemble(&sample, &catalog).unwrap();
    assert!(lightfarm_subject::synthetic::cached_people() >= 1);
    let second = assemble(&sample, &catalog).unwrap();
    assert_eq!(first.scene.textures.len(), second.scene.textures.len());
    for (a, b) in first.scene.textures.iter().zip(&second.scene.textures) {
        assert!(a.rgba8 == b.rgba8, "a cached texture differs");
    }
    for (a, b) in first.scene.meshes.iter().zip(&second.scene.meshes) {
        assert_eq!(a.positions, b.positions, "mesh {} differs", a.name);
    }
}
