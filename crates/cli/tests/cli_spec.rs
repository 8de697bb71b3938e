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
    let o = run(&["spec", "expand", &example(), "--index", "1000"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--index"));
    let o = run(&["spec", "expand", "/no/such/spec.toml", "--index", "0"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("/no/such/spec.toml"));
}

#[test]
fn builtin_assets_verify() {
    let o = run(&["assets", "verify"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
