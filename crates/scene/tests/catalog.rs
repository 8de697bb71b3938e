//! The built-in asset pack and the catalog's validation, selection and verification.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use lightfarm_scene::{AssetKind, Catalog, SceneError};

const GOOD_HASH: &str = "0000000000000000000000000000000000000000000000000000000000000000";

/// A fresh directory per call: tests run in parallel and must not share files.
fn temp_dir(name: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "lightfarm-scene-test-{}-{}-{name}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

fn write_catalog(name: &str, toml: &str) -> PathBuf {
    let dir = temp_dir(name);
    let path = dir.join("catalog.toml");
    std::fs::write(&path, toml).expect("write catalog");
    path
}

fn entry(id: &str, kind: &str, path: &str, hash: &str) -> String {
    format!(
        "[[asset]]\nid = \"{id}\"\nkind = \"{kind}\"\npath = \"{path}\"\nblake3 = \"{hash}\"\n\
         license = \"CC0-1.0\"\n\n"
    )
}

/// Expects an `Invalid` error whose key is `key`; returns its reason.
fn expect_invalid(result: Result<impl std::fmt::Debug, SceneError>, key: &str) -> String {
    match result {
        Err(SceneError::Invalid { key: k, reason, .. }) => {
            assert_eq!(k, key, "wrong key; reason: {reason}");
            reason
        }
        other => panic!("expected Invalid at `{key}`, got {other:?}"),
    }
}

fn builtin() -> Catalog {
    Catalog::builtin().unwrap_or_else(|e| panic!("built-in catalog: {e}"))
}

#[test]
fn builtin_catalog_loads_and_every_hash_matches() {
    let catalog = builtin();
    catalog.verify().unwrap_or_else(|e| panic!("{e}"));
    for asset in &catalog.assets {
        assert!(catalog.path_of(asset).is_file(), "{}", asset.id);
        assert!(!asset.license.is_empty(), "{} has no licence", asset.id);
        if asset.license.starts_with("CC-BY") {
            assert!(
                !asset.attribution.is_empty(),
                "{} needs attribution",
                asset.id
            );
        }
    }
}

#[test]
fn builtin_catalog_has_the_pack() {
    let catalog = builtin();
    let heads = catalog.of_kind(AssetKind::Head);
    assert!(heads.len() >= 11, "{} heads", heads.len());
    let makehuman: Vec<_> = heads
        .iter()
        .filter(|h| h.tags.get("source").map(String::as_str) == Some("makehuman"))
        .collect();
    assert_eq!(makehuman.len(), 8);
    for head in &makehuman {
        assert!(head.tags.contains_key("gender"), "{}", head.id);
        assert!(head.tags.contains_key("age_band"), "{}", head.id);
    }
    for head in &heads {
        // Every head groups the split by some identity, defaulted by load if absent.
        assert!(head.identity.as_deref().is_some_and(|i| !i.is_empty()));
        if let Some(g) = head.tags.get("gender") {
            assert!(g == "f" || g == "m", "{}: gender {g}", head.id);
        }
        if let Some(a) = head.tags.get("age_band") {
            assert!(
                ["young", "middle", "old"].contains(&a.as_str()),
                "{}",
                head.id
            );
        }
    }
    for id in ["lee_perry_smith", "ict_seed7_1", "ict_seed7_2"] {
        assert_eq!(
            catalog.get(id).map(|a| a.kind),
            Some(AssetKind::Head),
            "{id}"
        );
    }
    let hdris = catalog.of_kind(AssetKind::Hdri);
    assert!(hdris.len() >= 6);
    for h in &hdris {
        let setting = h.tags.get("setting").map(String::as_str);
        assert!(matches!(setting, Some("indoor" | "outdoor")), "{}", h.id);
    }
    assert!(!catalog.of_kind(AssetKind::Glasses).is_empty());
    assert!(!catalog.of_kind(AssetKind::Headset).is_empty());
    assert!(!catalog.of_kind(AssetKind::Garment).is_empty());
}

#[test]
fn select_star_id_and_tag() {
    let catalog = builtin();
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();

    let all = catalog
        .select(AssetKind::Head, &s(&["*"]), "assets.heads")
        .unwrap();
    assert_eq!(all.len(), catalog.of_kind(AssetKind::Head).len());

    let one = catalog
        .select(AssetKind::Hdri, &s(&["studio_small_03"]), "assets.hdris")
        .unwrap();
    assert_eq!(one.len(), 1);
    assert_eq!(one[0].id, "studio_small_03");

    let women = catalog
        .select(AssetKind::Head, &s(&["tag:gender=f"]), "assets.heads")
        .unwrap();
    assert!(women.len() >= 4);
    assert!(women.iter().all(
        |h| h.kind == AssetKind::Head && h.tags.get("gender").map(String::as_str) == Some("f")
    ));

    // Union without duplicates, in catalog order.
    let union = catalog
        .select(
            AssetKind::Head,
            &s(&["mh03_f_old_asian", "tag:gender=f", "mh01_f_young_caucasian"]),
            "assets.heads",
        )
        .unwrap();
    let ids: Vec<&str> = union.iter().map(|a| a.id.as_str()).collect();
    let expected: Vec<&str> = women.iter().map(|a| a.id.as_str()).collect();
    assert_eq!(ids, expected);
}

#[test]
fn unknown_selectors_are_errors_listing_ids() {
    let catalog = builtin();
    let s = |x: &str| vec![x.to_string()];
    let reason = expect_invalid(
        catalog.select(AssetKind::Head, &s("no_such_head"), "assets.heads"),
        "assets.heads",
    );
    assert!(reason.contains("no_such_head"), "{reason}");
    assert!(reason.contains("mh01_f_young_caucasian"), "{reason}");
    assert!(reason.contains("lee_perry_smith"), "{reason}");

    // An id of another kind is not silently accepted.
    let reason = expect_invalid(
        catalog.select(AssetKind::Head, &s("studio_small_03"), "assets.heads"),
        "assets.heads",
    );
    assert!(reason.contains("hdri"), "{reason}");

    // A tag matching nothing of this kind is an error too (gender tags exist only on heads).
    expect_invalid(
        catalog.select(AssetKind::Hdri, &s("tag:gender=f"), "assets.hdris"),
        "assets.hdris",
    );
    expect_invalid(
        catalog.select(AssetKind::Head, &s("tag:gender"), "assets.heads"),
        "assets.heads",
    );
}

#[test]
fn bad_toml_is_a_toml_error() {
    let path = write_catalog("badtoml", "[[asset]]\nid = \"x\nkind = \"head\"\n");
    match Catalog::load(&path) {
        Err(SceneError::Toml { path: p, reason }) => {
            assert_eq!(p, path);
            assert!(reason.contains("line"), "{reason}");
        }
        other => panic!("expected Toml error, got {other:?}"),
    }
}

#[test]
fn duplicate_id_names_the_key() {
    let text = entry("a", "head", "a.glb", GOOD_HASH) + &entry("a", "hdri", "b.hdr", GOOD_HASH);
    let reason = expect_invalid(Catalog::load(&write_catalog("dup", &text)), "asset[1].id");
    assert!(reason.contains("asset[0]"), "{reason}");
}

#[test]
fn short_hash_names_the_key() {
    let text =
        entry("a", "head", "a.glb", GOOD_HASH) + &entry("b", "head", "b.glb", &GOOD_HASH[1..]);
    let reason = expect_invalid(
        Catalog::load(&write_catalog("hash63", &text)),
        "asset[1].blake3",
    );
    assert!(reason.contains("63"), "{reason}");
}

#[test]
fn unknown_kind_names_the_key() {
    let text = entry("a", "hat", "a.glb", GOOD_HASH);
    let reason = expect_invalid(
        Catalog::load(&write_catalog("kind", &text)),
        "asset[0].kind",
    );
    assert!(reason.contains("glasses"), "{reason}");
}

#[test]
fn other_field_errors_name_the_key() {
    let load = |name, text: String| Catalog::load(&write_catalog(name, &text));
    expect_invalid(
        load("emptyid", entry("", "head", "a.glb", GOOD_HASH)),
        "asset[0].id",
    );
    expect_invalid(
        load("emptypath", entry("a", "head", "", GOOD_HASH)),
        "asset[0].path",
    );
    expect_invalid(
        load("dotdot", entry("a", "head", "../a.glb", GOOD_HASH)),
        "asset[0].path",
    );
    let typo = entry("a", "head", "a.glb", GOOD_HASH).replace("license", "licence");
    expect_invalid(load("typo", typo), "asset[0]");
    let hdri_identity = entry("a", "hdri", "a.hdr", GOOD_HASH) + "identity = \"x\"\n";
    expect_invalid(load("identity", hdri_identity), "asset[0].identity");
}

#[test]
fn head_identity_defaults_to_id() {
    let path = write_catalog("identity-default", &entry("a", "head", "a.glb", GOOD_HASH));
    let catalog = Catalog::load(&path).unwrap();
    assert_eq!(catalog.assets[0].identity.as_deref(), Some("a"));
    assert_eq!(
        catalog.path_of(&catalog.assets[0]),
        path.with_file_name("a.glb")
    );
}

#[test]
fn wrong_hash_fails_verify() {
    let path = write_catalog("mismatch", &entry("a", "head", "a.glb", GOOD_HASH));
    let file = path.with_file_name("a.glb");
    std::fs::write(&file, b"not the bytes the catalog pins").unwrap();
    let actual_hash = blake3::hash(b"not the bytes the catalog pins")
        .to_hex()
        .to_string();
    let catalog = Catalog::load(&path).unwrap();
    match catalog.verify() {
        Err(SceneError::HashMismatch {
            id,
            file: f,
            expected,
            actual,
            ..
        }) => {
            assert_eq!(id, "a");
            assert_eq!(f, file);
            assert_eq!(expected, GOOD_HASH);
            assert_eq!(actual, actual_hash);
        }
        other => panic!("expected HashMismatch, got {other:?}"),
    }

    // With the right hash (given in upper case) the same file verifies.
    let text = entry("a", "head", "a.glb", &actual_hash.to_uppercase());
    std::fs::write(&path, text).unwrap();
    Catalog::load(&path).unwrap().verify().unwrap();
}

#[test]
fn missing_file_fails_verify() {
    let path = write_catalog("missing", &entry("a", "head", "gone.glb", GOOD_HASH));
    let catalog = Catalog::load(&path).unwrap();
    let reason = expect_invalid(catalog.verify(), "asset[0].path");
    assert!(reason.contains("gone.glb"), "{reason}");
}

#[test]
fn frame_and_landmark_errors_name_the_key() {
    let load = |name, text: String| Catalog::load(&write_catalog(name, &text));
    let head = || entry("a", "head", "a.glb", GOOD_HASH);
    let all = "eye_left = [0.03, 0.03, 0.08], eye_right = [-0.03, 0.03, 0.08], \
               ear_left = [0.08, 0.02, -0.01], ear_right = [-0.08, 0.02, -0.01], \
               nose_bridge = [0.0, 0.03, 0.1], crown = [0.0, 0.15, 0.0]";
    // A complete, valid pair loads.
    let ok = load(
        "frame-ok",
        head()
            + "frame = { scale = 0.05, translate = [0.0, -0.04, 0.0] }\n"
            + &format!("landmarks = {{ {all} }}\n"),
    )
    .unwrap_or_else(|e| panic!("valid frame/landmarks: {e}"));
    let a = &ok.assets[0];
    assert_eq!(a.frame.map(|f| f.scale), Some(0.05));
    assert_eq!(a.landmarks.as_ref().map(|l| l.len()), Some(6));

    for (name, extra) in [
        ("scale0", "frame = { scale = 0.0 }\n".to_string()),
        ("scaleneg", "frame = { scale = -1.0 }\n".to_string()),
        ("scalenan", "frame = { scale = nan }\n".to_string()),
        (
            "transinf",
            "frame = { scale = 1.0, translate = [inf, 0.0, 0.0] }\n".to_string(),
        ),
    ] {
        let reason = expect_invalid(load(name, head() + &extra), "asset[0].frame");
        assert!(reason.contains("positive"), "{name}: {reason}");
    }
    let missing = all.replace("crown = [0.0, 0.15, 0.0]", "nose_tip = [0.0, 0.0, 0.1]");
    let reason = expect_invalid(
        load(
            "lm-unknown",
            head() + &format!("landmarks = {{ {missing} }}\n"),
        ),
        "asset[0].landmarks",
    );
    assert!(reason.contains("nose_tip"), "{reason}");
    let short = all.replace(", crown = [0.0, 0.15, 0.0]", "");
    let reason = expect_invalid(
        load(
            "lm-missing",
            head() + &format!("landmarks = {{ {short} }}\n"),
        ),
        "asset[0].landmarks",
    );
    assert!(reason.contains("crown"), "{reason}");
    let reason = expect_invalid(
        load(
            "lm-hdri",
            entry("a", "hdri", "a.hdr", GOOD_HASH) + &format!("landmarks = {{ {all} }}\n"),
        ),
        "asset[0].landmarks",
    );
    assert!(reason.contains("only heads"), "{reason}");
    // A frame key that is not scale/translate is a typo, not ignored.
    expect_invalid(
        load("frame-typo", head() + "frame = { scael = 1.0 }\n"),
        "asset[0]",
    );
}
