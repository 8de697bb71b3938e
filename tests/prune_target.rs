//! `scripts/prune-target.sh` on made-up target dirs. It deletes files in a directory that
//! holds every build of the suite, so what it keeps matters as much as what it frees: a test
//! whose executable it took by mistake would be rebuilt on every CI run.

use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime};

/// Writes `name` in `deps` with `len` bytes, mode `exec`, modified `age_s` seconds ago, and a
/// dep-info file naming `root` as the target's root source when there is one.
fn artifact(deps: &Path, name: &str, len: usize, exec: bool, age_s: u64, root: Option<&str>) {
    let path = deps.join(name);
    fs::write(&path, vec![0u8; len]).unwrap();
    let mode = if exec { 0o755 } else { 0o644 };
    fs::set_permissions(&path, fs::Permissions::from_mode(mode)).unwrap();
    let when = SystemTime::now() - Duration::from_secs(age_s);
    let file = fs::File::options().write(true).open(&path).unwrap();
    file.set_modified(when).unwrap();
    if let Some(root) = root {
        let d = format!("{}: {root} /w/crates/x/src/other.rs\n", path.display());
        fs::write(deps.join(format!("{name}.d")), d).unwrap();
    }
}

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/prune-target.sh")
}

/// Runs the script on `dir` and returns what it printed; it must succeed.
fn prune(dir: &Path) -> String {
    let out = Command::new("bash")
        .arg(script())
        .arg(dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    stdout
}

#[test]
fn superseded_executables_and_incremental_caches_go_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    // The first run on an empty dir records the profiles, as before a CI run's cold build.
    prune(dir.path());
    let deps = dir.path().join("debug/deps");
    fs::create_dir_all(&deps).unwrap();
    let cache = dir.path().join("debug/incremental/render-1");
    fs::create_dir_all(&cache).unwrap();
    fs::write(cache.join("q.bin"), vec![0u8; 4 << 20]).unwrap();
    // (name, bytes, executable, age in seconds, root source in the dep-info)
    let artifacts: [(&str, usize, bool, u64, Option<&str>); 9] = [
        // The same test built twice (the older in another clone): the older goes.
        (
            "traversal-00000000000000aa",
            3 << 20,
            true,
            7200,
            Some("/old/clone/crates/render/tests/traversal.rs"),
        ),
        (
            "traversal-00000000000000bb",
            1 << 20,
            true,
            60,
            Some("/a/crates/render/tests/traversal.rs"),
        ),
        // A test of the same name in another crate stays.
        (
            "traversal-00000000000000cc",
            1 << 20,
            true,
            7200,
            Some("/a/crates/scene/tests/traversal.rs"),
        ),
        // A crate's lib and bin unit tests share a name; both stay.
        (
            "lightfarm-00000000000000dd",
            1 << 10,
            true,
            7200,
            Some("/a/crates/cli/src/lib.rs"),
        ),
        (
            "lightfarm-00000000000000ee",
            1 << 10,
            true,
            60,
            Some("/a/crates/cli/src/main.rs"),
        ),
        // Libraries of one crate built twice (build scripts and target) stay, as do shared objects.
        ("libserde-00000000000000aa.rlib", 1 << 10, false, 7200, None),
        ("libserde-00000000000000bb.rlib", 1 << 10, false, 60, None),
        (
            "libserde_derive-00000000000000aa.so",
            1 << 10,
            true,
            7200,
            None,
        ),
        (
            "libserde_derive-00000000000000bb.so",
            1 << 10,
            true,
            60,
            None,
        ),
    ];
    for (name, len, exec, age_s, root) in artifacts {
        artifact(&deps, name, len, exec, age_s, root);
    }

    let stdout = prune(dir.path());
    // 3 MiB of the old executable and 4 MiB of incremental cache.
    assert!(stdout.contains("freed 7 MiB"), "{stdout}");
    let mut left: Vec<String> = fs::read_dir(&deps)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        [
            "libserde-00000000000000aa.rlib",
            "libserde-00000000000000bb.rlib",
            "libserde_derive-00000000000000aa.so",
            "libserde_derive-00000000000000bb.so",
            "lightfarm-00000000000000dd",
            "lightfarm-00000000000000dd.d",
            "lightfarm-00000000000000ee",
            "lightfarm-00000000000000ee.d",
            "traversal-00000000000000bb",
            "traversal-00000000000000bb.d",
            "traversal-00000000000000cc",
            "traversal-00000000000000cc.d",
        ]
    );
    assert!(!dir.path().join("debug/incremental").exists());
    // A second run finds nothing more to free.
    assert!(prune(dir.path()).contains("freed 0 MiB"));
}

#[test]
fn a_build_under_other_profiles_goes_whole() {
    for stamp in [None, Some("a hash of other profiles\n")] {
        let dir = tempfile::tempdir().unwrap();
        let deps = dir.path().join("debug/deps");
        fs::create_dir_all(&deps).unwrap();
        artifact(
            &deps,
            "libserde-00000000000000aa.rlib",
            2 << 20,
            false,
            60,
            None,
        );
        if let Some(stamp) = stamp {
            fs::write(dir.path().join(".lightfarm-profiles"), stamp).unwrap();
        }
        let stdout = prune(dir.path());
        assert!(stdout.contains("profiles changed"), "{stdout}");
        assert!(stdout.contains("freed 2 MiB"), "{stdout}");
        assert!(!dir.path().join("debug").exists());
        // Built again under these profiles, it stays.
        fs::create_dir_all(&deps).unwrap();
        artifact(
            &deps,
            "libserde-00000000000000bb.rlib",
            1 << 10,
            false,
            60,
            None,
        );
        assert!(!prune(dir.path()).contains("profiles changed"));
        assert!(deps.join("libserde-00000000000000bb.rlib").exists());
    }
}

#[test]
fn a_target_dir_that_does_not_exist_yet_is_made_not_refused() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("fresh");
    prune(&target);
    assert!(target.is_dir());
}
