//! `lightfarm spec expand|check` and `lightfarm assets verify` through the real binary.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lightfarm"))
        .args(args)
        .output()
        .expect("run lightfarm")
}

fn example() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/dataset.toml")
        .display()
        .to_string()
}

#[test]
fn expand_is_a_pure_function_of_spec_and_index() {
    let spec = example();
    let a = run(&["spec", "expand", &spec, "--index", "17"]);
    let b = run(&["spec", "expand", &spec, "--index", "17"]);
    let c = run(&["spec", "expand", &spec, "--index", "18"]);
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    assert_eq!(a.stdout, b.stdout, "two processes, same JSON");
    assert_ne!(a.stdout, c.stdout, "another index, another sample");
    let v: serde_json::Value = serde_json::from_slice(&a.stdout).expect("JSON");
    assert_eq!(v["index"], 17);
    assert_eq!(v["head"]["blake3"].as_str().map(str::len), Some(64));
    assert_eq!(v["lighting"].as_array().map(Vec::len), Some(2));
}

#[test]
fn bad_specs_and_indices_name_the_key() {
    let dir = std::env::temp_dir().join(format!("lightfarm-cli-spec-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(example()).unwrap();
    let cases: [(&str, &str, &str); 3] = [
        (
            "glasses_probability = 0.2",
            "glasses_probability = 1.5",
            "subject.glasses_probability",
        ),
        ("count = 1000 ", "count = -3 ", "count"),
        (
            "heads = [\"*\"]",
            "heads = [\"no_such_head\"]",
            "assets.heads",
        ),
    ];
    for (from, to, key) in cases {
        assert!(
            base.contains(from),
            "examples/dataset.toml no longer contains `{from}`"
        );
        let path: PathBuf = dir.join(format!("{}.toml", key.replace('.', "_")));
        std::fs::write(&path, base.replace(from, to)).unwrap();
        let o = run(&["spec", "expand", path.to_str().unwrap(), "--index", "0"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{key}: {err}");
        assert!(
            err.contains(key) && !err.contains("panicked"),
            "{key}: {err}"
        );
    }
    for (args, needle) in [
        (
            vec!["spec", "expand", &example(), "--index", "1000"],
            "--index",
        ),
        (
            vec!["spec", "expand", "/no/such/spec.toml", "--index", "0"],
            "/no/such/spec.toml",
        ),
    ] {
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(o.stdout.is_empty(), "{args:?} printed a sample");
        assert!(
            err.contains(needle) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn builtin_assets_verify() {
    let o = run(&["assets", "verify"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("assets verified"), "{text}");
}

/// A copy of the catalog whose files are links to the built-in ones except one, which is a
/// copy with a single byte changed: verification must fail and name that asset.
#[test]
fn assets_verify_refuses_a_corrupted_copy() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let dir = tempfile::tempdir().expect("tmp");
    std::fs::copy(repo.join("catalog.toml"), dir.path().join("catalog.toml")).expect("copy");
    let catalog: toml::Value =
        toml::from_str(&std::fs::read_to_string(repo.join("catalog.toml")).expect("read"))
            .expect("catalog TOML");
    let paths: Vec<&str> = catalog["asset"]
        .as_array()
        .expect("[[asset]] tables")
        .iter()
        .map(|a| a["path"].as_str().expect("path"))
        .collect();
    let victim = "hdri/venice_sunset_1k.hdr";
    assert!(
        paths.contains(&victim),
        "{victim} is no longer in the catalog"
    );
    for rel in &paths {
        let (from, to) = (repo.join(rel), dir.path().join(rel));
        std::fs::create_dir_all(to.parent().expect("parent")).expect("mkdir");
        if *rel == victim {
            let mut bytes = std::fs::read(&from).expect("read");
            let mid = bytes.len() / 2;
            bytes[mid] ^= 0x01;
            std::fs::write(&to, bytes).expect("write");
        } else {
            std::os::unix::fs::symlink(&from, &to).expect("link");
        }
    }
    let cat = dir.path().join("catalog.toml");
    let good = run(&["assets", "list", "--catalog", cat.to_str().expect("utf8")]);
    assert!(
        good.status.success(),
        "{}",
        String::from_utf8_lossy(&good.stderr)
    );
    let o = run(&["assets", "verify", "--catalog", cat.to_str().expect("utf8")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("venice_sunset") && !err.contains("panicked"),
        "the error must name the corrupted asset: {err}"
    );
}
