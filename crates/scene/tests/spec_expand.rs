//! The dataset spec and its deterministic expansion, end to end against the built-in catalog:
//! the documented example loads, expansion is reproducible (golden JSON), the sampled
//! distributions match the paper's, the held-out split holds, and bad specs name their key.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use lightfarm_scene::expand::{expand, expand_json, SampleSpec, Split};
use lightfarm_scene::spec::{DatasetSpec, ResolvedSpec, HAIR_STYLES};
use lightfarm_scene::Catalog;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn example_path() -> PathBuf {
    repo().join("examples/dataset.toml")
}

fn example_text() -> String {
    std::fs::read_to_string(example_path()).expect("examples/dataset.toml is readable")
}

fn catalog() -> Catalog {
    Catalog::builtin().expect("the built-in catalog loads")
}

fn resolve(text: &str) -> Result<ResolvedSpec, lightfarm_scene::SceneError> {
    DatasetSpec::from_toml_str(text, "test.toml")?.validate(&catalog())
}

/// The example with one line replaced; panics if the line is not there, so the tests notice
/// when the example drifts instead of silently testing the unmodified file.
fn example_with(old: &str, new: &str) -> String {
    let text = example_text();
    assert!(
        text.contains(old),
        "examples/dataset.toml no longer contains {old:?}"
    );
    text.replacen(old, new, 1)
}

fn example_resolved(count: u64) -> ResolvedSpec {
    let mut spec = DatasetSpec::load(example_path()).expect("example parses");
    spec.count = i64::try_from(count).expect("small count");
    spec.validate(&catalog()).expect("example validates")
}

#[test]
fn example_loads_with_builtin_catalog() {
    let spec = DatasetSpec::load(example_path()).expect("example parses");
    assert_eq!(spec.name, "demo");
    let resolved = spec.validate(&catalog()).expect("example validates");
    assert_eq!(resolved.count, 1000);
    assert_eq!(
        (resolved.width, resolved.height, resolved.spp),
        (512, 512, 256)
    );
    assert!(resolved.hdris.len() >= 2);
    assert_eq!(resolved.test_identities(), vec!["lee_perry_smith"]);
    assert!(!resolved.train_identities().contains(&"lee_perry_smith"));
    // Written-out defaults and omitted keys agree: the example documents the real defaults.
    let minimal = DatasetSpec::from_toml_str(
        "name = \"demo\"\nseed = 7\ncount = 1000\n[split]\ntest_identities = [\"lee_perry_smith\"]\n",
        "minimal.toml",
    )
    .expect("minimal spec parses");
    assert_eq!(
        minimal
            .validate(&catalog())
            .expect("minimal validates")
            .subject,
        resolved.subject
    );
    assert_eq!(minimal.camera, spec.camera);
    assert_eq!(minimal.lighting, spec.lighting);
    assert_eq!(minimal.assets, spec.assets);
}

/// A spec naming its assets explicitly, so that adding assets to the catalog does not change
/// the golden sample (changing one of these files' bytes does, through its hash: intended).
const GOLDEN_SPEC: &str = r#"
name = "golden"
seed = 7
count = 100
[assets]
heads = ["mh01_f_young_caucasian", "mh02_m_young_african", "mh03_f_old_asian", "lee_perry_smith"]
hdris = ["studio_small_03", "rooitou_park", "venice_sunset"]
garments = ["garment_f_casualsuit01", "garment_m_casualsuit06"]
glasses = ["sunglasses_khronos"]
headsets = ["headphones_procedural"]
[subject]
glasses_probability = 1.0
headset_probability = 1.0
[split]
test_identities = ["lee_perry_smith"]
"#;

#[test]
fn same_index_gives_identical_json_and_matches_golden() {
    let spec = resolve(GOLDEN_SPEC).expect("golden spec validates");
    let a = expand_json(&spec, 17).expect("expands");
    let b = expand_json(&spec, 17).expect("expands");
    assert_eq!(a, b);
    // Re-resolving from scratch (as another process would) gives the same bytes too.
    let again = resolve(GOLDEN_SPEC).expect("golden spec validates");
    assert_eq!(a, expand_json(&again, 17).expect("expands"));

    // The golden file was produced once and committed: it pins the sampling algorithm across
    // machines, compilers and releases. Regenerate with LIGHTFARM_BLESS=1 only when the sample
    // format changes on purpose (that changes every existing dataset).
    let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/sample17.json");
    if std::env::var_os("LIGHTFARM_BLESS").is_some() {
        std::fs::create_dir_all(golden.parent().expect("has parent")).expect("mkdir golden");
        std::fs::write(&golden, format!("{a}\n")).expect("write golden");
    }
    let expected = std::fs::read_to_string(&golden).expect("tests/golden/sample17.json exists");
    assert_eq!(
        a,
        expected.trim_end(),
        "sample 17 differs from the committed golden JSON"
    );
    let parsed: SampleSpec =
        serde_json::from_str(&expected).expect("golden parses as a SampleSpec");
    assert_eq!(parsed, expand(&spec, 17).expect("expands"));
}

#[test]
fn different_indices_differ() {
    let spec = example_resolved(1000);
    let mut seen = BTreeSet::new();
    for i in 0..200 {
        let mut s = expand(&spec, i).expect("expands");
        s.index = 0; // compare the content, not the index field
        assert!(
            seen.insert(serde_json::to_string(&s).expect("json")),
            "sample {i} repeats an earlier one"
        );
    }
    // And a different seed gives a different sample at the same index.
    let mut other = spec.clone();
    other.seed += 1;
    assert_ne!(
        expand(&spec, 5).expect("expands"),
        expand(&other, 5).expect("expands")
    );
}

#[test]
fn distributions_over_ten_thousand_samples() {
    const N: u64 = 10_000;
    let spec = example_resolved(N);
    let samples: Vec<SampleSpec> = (0..N).map(|i| expand(&spec, i).expect("expands")).collect();
    let rate =
        |f: &dyn Fn(&SampleSpec) -> bool| samples.iter().filter(|s| f(s)).count() as f64 / N as f64;

    let glasses = rate(&|s| s.glasses.is_some());
    assert!((glasses - 0.2).abs() <= 0.01, "glasses rate {glasses}");
    let headset = rate(&|s| s.headset.is_some());
    assert!((headset - 0.05).abs() <= 0.006, "headset rate {headset}");
    let garment = rate(&|s| s.garment.is_some());
    assert_eq!(
        garment, 1.0,
        "garment_probability = 1 must always dress the subject"
    );

    let flips = samples
        .iter()
        .flat_map(|s| s.lighting.iter())
        .filter(|l| l.flip)
        .count() as f64;
    let flip = flips / (2 * N) as f64;
    assert!((flip - 0.5).abs() <= 0.015, "flip rate {flip}");

    let yaw: Vec<f64> = samples.iter().map(|s| s.camera.yaw_deg).collect();
    let pitch: Vec<f64> = samples.iter().map(|s| s.camera.pitch_deg).collect();
    let melanin: Vec<f64> = samples.iter().map(|s| s.hair.melanin).collect();
    let redness: Vec<f64> = samples.iter().map(|s| s.hair.melanin_redness).collect();
    let beta_m: Vec<f64> = samples
        .iter()
        .map(|s| s.hair.longitudinal_roughness)
        .collect();
    let beta_n: Vec<f64> = samples.iter().map(|s| s.hair.azimuthal_roughness).collect();
    let rotation: Vec<f64> = samples
        .iter()
        .flat_map(|s| s.lighting.iter().map(|l| l.rotation_deg))
        .collect();
    // The spec's ranges (examples/dataset.toml): each value uniform on its interval, tested by
    // Kolmogorov–Smirnov; 7 tests at a family-wise level of 1%.
    for (name, v, lo, hi) in [
        ("yaw", &yaw, -45.0, 45.0),
        ("pitch", &pitch, -22.5, 22.5),
        ("melanin", &melanin, 0.0, 1.0),
        ("melanin redness", &redness, 0.0, 1.0),
        ("hair longitudinal roughness", &beta_m, 0.15, 0.4),
        ("hair azimuthal roughness", &beta_n, 0.25, 0.6),
        ("HDRI rotation", &rotation, 0.0, 360.0),
    ] {
        assert!(
            v.iter().all(|x| (lo..=hi).contains(x)),
            "{name} outside [{lo}, {hi}]"
        );
        let (d, p) = ks_uniform(v, lo, hi);
        println!("{name}: KS D = {d:.5}, p = {p:.3}");
        assert!(
            p > 0.01 / 7.0,
            "{name} is not uniform on [{lo}, {hi}]: D = {d}, p = {p}"
        );
        // The test must be able to fail: the same values pushed towards `lo` by a mild power
        // (u → u^1.1, at most 3.5% of the range) are rejected.
        let skewed: Vec<f64> = v
            .iter()
            .map(|x| lo + (hi - lo) * ((x - lo) / (hi - lo)).powf(1.1))
            .collect();
        let (ds, ps) = ks_uniform(&skewed, lo, hi);
        assert!(
            ps < 1e-6,
            "{name}: KS accepted a skewed copy (D = {ds}, p = {ps})"
        );
    }
    for s in &samples {
        assert!(s.camera.subject_offset_m.iter().all(|o| o.abs() <= 0.02));
    }

    let styles: BTreeSet<&str> = samples.iter().map(|s| s.hair.style.as_str()).collect();
    let all: BTreeSet<&str> = HAIR_STYLES.into_iter().collect();
    assert_eq!(styles, all, "every hair style appears");

    let mut expressions: BTreeMap<&str, usize> = BTreeMap::new();
    for s in &samples {
        *expressions
            .entry(s.head.expression.name.as_str())
            .or_default() += 1;
        let w = &s.head.expression.weights;
        assert!(w.values().all(|x| (0.0..=1.0).contains(x)));
        match s.head.expression.name.as_str() {
            "neutral" => assert!(w.is_empty()),
            "random" => assert!(
                (3..=6).contains(&w.len()),
                "random mix of {} shapes",
                w.len()
            ),
            _ => assert!(!w.is_empty()),
        }
    }
    assert_eq!(
        expressions.len(),
        7,
        "all expression kinds appear: {expressions:?}"
    );
    // Heads without morph targets (the scan, the ICT heads) are always neutral; the others
    // are neutral with probability 1 - expression_probability = 0.3.
    let no_morphs = ["lee_perry_smith", "ict_seed7_1", "ict_seed7_2"];
    let rigid = samples
        .iter()
        .filter(|s| no_morphs.contains(&s.head.id.as_str()))
        .count();
    for s in samples
        .iter()
        .filter(|s| no_morphs.contains(&s.head.id.as_str()))
    {
        assert_eq!(
            s.head.expression.name, "neutral",
            "sample {}: {} has no morphs",
            s.index, s.head.id
        );
    }
    let expected = (rigid as f64 + 0.3 * (N as f64 - rigid as f64)) / N as f64;
    let neutral = expressions.get("neutral").copied().unwrap_or(0) as f64 / N as f64;
    assert!(
        (neutral - expected).abs() <= 0.015,
        "neutral rate {neutral}, expected {expected}"
    );

    for s in &samples {
        assert_ne!(
            s.lighting[0].hdri, s.lighting[1].hdri,
            "sample {} lit twice by one HDRI",
            s.index
        );
    }
    let pairs: BTreeSet<(&str, &str)> = samples
        .iter()
        .map(|s| (s.lighting[0].hdri.as_str(), s.lighting[1].hdri.as_str()))
        .collect();
    let n = spec.hdris.len();
    assert_eq!(
        pairs.len(),
        n * (n - 1),
        "every ordered pair of distinct HDRIs occurs"
    );
}

#[test]
fn held_out_identities_never_train() {
    const N: u64 = 10_000;
    let spec = example_resolved(N);
    let test: BTreeSet<&str> = spec.test_identities().into_iter().collect();
    assert_eq!(test, BTreeSet::from(["lee_perry_smith"]));
    let mut counts = [0usize; 2];
    for i in 0..N {
        let s = expand(&spec, i).expect("expands");
        let held = test.contains(s.identity.as_str());
        match s.split {
            Split::Train => {
                assert!(
                    !held,
                    "sample {i}: held-out identity {} in train",
                    s.identity
                );
                counts[0] += 1;
            }
            Split::Test => {
                assert!(
                    held,
                    "sample {i}: test sample uses training identity {}",
                    s.identity
                );
                counts[1] += 1;
            }
        }
        let head_identity = spec
            .identities
            .iter()
            .find(|id| id.heads.iter().any(|h| h.id == s.head.id))
            .map(|id| id.name.as_str());
        assert_eq!(
            head_identity,
            Some(s.identity.as_str()),
            "head and identity agree"
        );
    }
    // Identity is uniform over all identities, so the test share is 1 / (number of identities).
    let share = counts[1] as f64 / N as f64;
    let expected = 1.0 / spec.identities.len() as f64;
    assert!(
        (share - expected).abs() < 0.01,
        "test share {share}, expected {expected}"
    );

    // A fraction holds out ceil(f * n) identities, chosen by the seed, and also never trains.
    let text = example_with(
        "test_identities = [\"lee_perry_smith\"]",
        "test_identities = []",
    )
    .replacen("test_fraction = 0.0", "test_fraction = 0.25", 1);
    let spec = resolve(&text).expect("fraction spec validates");
    let n = spec.identities.len();
    assert_eq!(
        spec.test_identities().len(),
        (0.25 * n as f64).ceil() as usize
    );
    let held: BTreeSet<&str> = spec.test_identities().into_iter().collect();
    for i in 0..spec.count {
        let s = expand(&spec, i).expect("expands");
        assert_eq!(
            s.split == Split::Test,
            held.contains(s.identity.as_str()),
            "sample {i}"
        );
    }
}

/// `lighting.olat` reaches every sample's render block, and is absent from the JSON of samples
/// that do not ask for OLAT images (whose bytes, and so hashes, stay what they were).
#[test]
fn olat_is_carried_into_each_sample_only_when_asked_for() {
    let plain = expand_json(&example_resolved(4), 0).expect("expand");
    assert!(!plain.contains("olat"), "{plain}");
    let spec = resolve(&example_with("olat = 0", "olat = 168")).expect("valid");
    let s = expand(&spec, 3).expect("expand");
    assert_eq!(s.render.olat, 168);
    let json = expand_json(&spec, 3).expect("json");
    let back: SampleSpec = serde_json::from_str(&json).expect("round trip");
    assert_eq!(back.render.olat, 168);
}

/// Each bad spec must fail, and the message must name the key a person has to edit.
#[test]
fn bad_specs_name_their_key() {
    let cases: Vec<(&str, String)> = vec![
        ("count", example_with("count = 1000", "count = 0")),
        ("count", example_with("count = 1000", "count = -5")),
        ("count", example_with("count = 1000", "count = 10000001")),
        ("width", example_with("width = 512", "width = 0")),
        ("spp", example_with("spp = 256", "spp = 0")),
        (
            "passes",
            example_with("spp = 256", "spp = 256\npasses = [\"diffuse\", \"albedo\"]"),
        ),
        ("name", example_with("name = \"demo\"", "name = \"\"")),
        (
            "subject.glasses_probability",
            example_with("glasses_probability = 0.2", "glasses_probability = 1.5"),
        ),
        (
            "subject.headset_probability",
            example_with("headset_probability = 0.05", "headset_probability = -0.1"),
        ),
        (
            "lighting.flip_probability",
            example_with("flip_probability = 0.5", "flip_probability = 2.0"),
        ),
        ("lighting.olat", example_with("olat = 0", "olat = 1")),
        ("lighting.olat", example_with("olat = 0", "olat = 257")),
        (
            "camera.yaw_deg",
            example_with("yaw_deg = [-45.0, 45.0]", "yaw_deg = [45.0, -45.0]"),
        ),
        (
            "camera.pitch_deg",
            example_with("pitch_deg = [-22.5, 22.5]", "pitch_deg = [-90.0, 22.5]"),
        ),
        (
            "camera.radius_m",
            example_with("radius_m = 1.0", "radius_m = 0.0"),
        ),
        (
            "subject.melanin",
            example_with("melanin = [0.0, 1.0]", "melanin = [0.8, 0.2]"),
        ),
        (
            "subject.garment_roughness",
            example_with(
                "garment_roughness = [0.1, 1.0]",
                "garment_roughness = [0.1, 1.5]",
            ),
        ),
        (
            "assets.heads",
            example_with("heads = [\"*\"]", "heads = [\"no_such_head\"]"),
        ),
        (
            "assets.hdris",
            example_with("hdris = [\"*\"]", "hdris = [\"studio_small_03\"]"),
        ),
        (
            "assets.glasses",
            example_with("glasses = [\"*\"]", "glasses = [\"studio_small_03\"]"),
        ),
        (
            "subject.glasses_probability",
            example_with("glasses = [\"*\"]", "glasses = []"),
        ),
        (
            "subject.hair_styles",
            example_with("\"curly\", \"ponytail\"]", "\"curly\", \"mohawk\"]"),
        ),
        (
            "glases_probability",
            example_with("glasses_probability = 0.2", "glases_probability = 0.2"),
        ),
        (
            "split.test_identities",
            example_with("[\"lee_perry_smith\"]", "[\"nobody\"]"),
        ),
        (
            "split.test_identities",
            example_with("[\"lee_perry_smith\"]", "[\"rooitou_park\"]"),
        ),
        (
            "split",
            example_with("heads = [\"*\"]", "heads = [\"lee_perry_smith\"]"),
        ),
        (
            "split",
            example_with("test_fraction = 0.0", "test_fraction = 0.5"),
        ),
        (
            "split",
            example_with(
                "test_identities = [\"lee_perry_smith\"]",
                "test_identities = []",
            )
            .replacen("test_fraction = 0.0", "test_fraction = 1.0", 1),
        ),
        (
            "split.test_fraction",
            example_with("test_fraction = 0.0", "test_fraction = -0.5"),
        ),
    ];
    for (key, text) in cases {
        match resolve(&text) {
            Ok(_) => panic!("spec with a bad `{key}` was accepted"),
            Err(e) => {
                // Both SceneError::Invalid and toml's unknown-field message put the key in
                // backticks; matching them avoids passing on an incidental mention.
                let msg = e.to_string();
                if std::env::var_os("LIGHTFARM_SHOW_ERRORS").is_some() {
                    eprintln!("{msg}\n");
                }
                assert!(
                    msg.contains(&format!("`{key}`")),
                    "error for `{key}` does not name it: {msg}"
                );
            }
        }
    }
}

#[test]
fn index_out_of_range_names_the_flag() {
    let spec = example_resolved(1000);
    assert!(expand(&spec, 999).is_ok());
    for index in [1000, u64::MAX] {
        let msg = expand(&spec, index)
            .expect_err("index >= count")
            .to_string();
        assert!(msg.contains("--index") && msg.contains("0..=999"), "{msg}");
    }
}

/// Kolmogorov–Smirnov test of `v` against the uniform distribution on [lo, hi]: the statistic
/// D = sup |F_n − F| and its p-value from the Kolmogorov distribution with Stephens' (1970)
/// small-sample correction, P(D > d) ≈ Q((√n + 0.12 + 0.11/√n) d), Q(t) = 2 Σ (−1)^(k−1) e^(−2k²t²).
fn ks_uniform(v: &[f64], lo: f64, hi: f64) -> (f64, f64) {
    let mut x: Vec<f64> = v.iter().map(|x| (x - lo) / (hi - lo)).collect();
    x.sort_by(f64::total_cmp);
    let n = x.len() as f64;
    let d = x
        .iter()
        .enumerate()
        .map(|(i, &f)| ((i as f64 + 1.0) / n - f).max(f - i as f64 / n))
        .fold(0.0, f64::max);
    let t = (n.sqrt() + 0.12 + 0.11 / n.sqrt()) * d;
    let q: f64 = (1..=100)
        .map(|k| {
            let k = k as f64;
            let sign = if k as u64 % 2 == 1 { 1.0 } else { -1.0 };
            2.0 * sign * (-2.0 * k * k * t * t).exp()
        })
        .sum();
    (d, q.clamp(0.0, 1.0))
}

/// `passes` defaults to the issue's four, is kept in the renderer's order without duplicates,
/// and `[]` turns them off; it reaches every sample's render settings.
#[test]
fn passes_default_order_and_none() {
    let text = example_with("count = 1000", "count = 3");
    let spec = resolve(&text).expect("spec");
    assert_eq!(spec.passes, ["diffuse", "specular", "shadow", "id"]);
    let sample = lightfarm_scene::expand::expand(&spec, 1).expect("expand");
    assert_eq!(sample.render.passes, spec.passes);
    let text = example_with(
        "spp = 256",
        "spp = 256\npasses = [\"id\", \"sss\", \"sss\", \"coat\"]",
    );
    assert_eq!(resolve(&text).expect("spec").passes, ["sss", "coat", "id"]);
    let text = example_with("spp = 256", "spp = 256\npasses = []");
    assert!(resolve(&text).expect("spec").passes.is_empty());
}

/// `heads = ["synthetic"]`: every identity id is a person, held-out ids never train, and
/// identity k's parameters do not depend on which sample drew it.
#[test]
fn synthetic_identities_split_and_repeat() {
    let catalog = lightfarm_scene::Catalog::builtin().unwrap();
    let text = "name = \"syn\"\nseed = 5\ncount = 4000\n[assets]\nheads = [\"synthetic\", \"lee_perry_smith\"]\n[identity]\ncount = 300\n[split]\ntest_fraction = 0.2\n";
    let spec = lightfarm_scene::spec::DatasetSpec::from_toml_str(text, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap();
    let people = spec.synthetic.as_ref().expect("synthetic people");
    let held = (0..300).filter(|&k| people.held_out(k)).count();
    assert!(
        (35..=85).contains(&held),
        "{held} of 300 held out for a fraction of 0.2"
    );
    let mut seen = std::collections::BTreeMap::new();
    let mut scans = 0;
    for i in 0..4000 {
        let s = lightfarm_scene::expand::expand(&spec, i).unwrap();
        match &s.head.synthetic {
            Some(h) => {
                let k = h.identity.id;
                assert!(k < 300);
                assert_eq!(s.identity, lightfarm_scene::identity::identity_name(k));
                let want = if people.held_out(k) {
                    lightfarm_scene::expand::Split::Test
                } else {
                    lightfarm_scene::expand::Split::Train
                };
                assert_eq!(s.split, want, "sample {i}: identity {k}");
                if let Some(prev) = seen.insert(k, h.identity.clone()) {
                    assert_eq!(prev, h.identity, "identity {k} changed between samples");
                }
            }
            None => scans += 1,
        }
    }
    // One scan among 301 identities: about 13 of 4000 samples.
    assert!((2..=35).contains(&scans), "{scans} scan samples");
    assert!(
        seen.len() > 280,
        "only {} distinct people in 4000 samples",
        seen.len()
    );
    // A named synthetic identity can be held out; a name past the count cannot.
    let named = text.replace(
        "test_fraction = 0.2",
        "test_identities = [\"synthetic-0000007\"]",
    );
    let spec = lightfarm_scene::spec::DatasetSpec::from_toml_str(&named, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap();
    assert!(spec.synthetic.as_ref().unwrap().held_out(7));
    let bad = text.replace(
        "test_fraction = 0.2",
        "test_identities = [\"synthetic-0000300\"]",
    );
    let err = lightfarm_scene::spec::DatasetSpec::from_toml_str(&bad, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap_err();
    assert!(err.to_string().contains("synthetic-0000300"), "{err}");
    // The ICT shapes' spread: a value outside [0, 2] is named with its range; 0 draws none.
    let bad = text.replace("count = 300", "count = 300\nict_shape_sd = 3.0");
    let err = lightfarm_scene::spec::DatasetSpec::from_toml_str(&bad, "syn.toml")
        .unwrap()
        .validate(&catalog)
        .unwrap_err();
    assert!(
        err.to_string().contains("identity.ict_shape_sd") && err.to_string().contains("[0, 2]"),
        "{err}"
    );
    let spec = lightfarm_scene::identity::IdentitySpec::default();
    let person = lightfarm_scene::identity::sample_identity(&spec, 5, 3);
    assert_eq!(person.ict_shape.len(), lightfarm_scene::identity::ICT_MODES);
    assert!(person.ict_shape.iter().all(|c| c.abs() <= 2.5));
    let off = lightfarm_scene::identity::IdentitySpec {
        ict_shape_sd: 0.0,
        ..spec
    };
    let plain = lightfarm_scene::identity::sample_identity(&off, 5, 3);
    assert!(plain.ict_shape.is_empty());
    // The other parameters of a person do not depend on the ICT draw.
    assert_eq!(plain.skin, person.skin);
    assert_eq!(plain.shape_seed, person.shape_seed);
}
