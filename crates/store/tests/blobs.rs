//! One suite, run against both blob stores, so the in-memory twin can't drift from the disk
//! store's behaviour.

use std::io::Read;
use std::path::PathBuf;

use lightfarm_store::{
    hash_hex, is_hash, BlobStore, DiskBlobStore, MemoryBlobStore, StoreError, TieredBlobStore,
};

const LIMIT: u64 = 1 << 20;

/// What the suite needs beyond the trait: how to see leftovers in a store-specific way.
trait Harness {
    type S: BlobStore;
    fn store(&self) -> &Self::S;
    /// Uploads in progress (temp files for disk; none can exist in memory).
    fn leftovers(&self) -> usize;
    /// Finished blobs.
    fn blob_count(&self) -> usize;
    /// Whether an upload in progress is visible to `leftovers`.
    fn stages_uploads(&self) -> bool;
}

struct Disk {
    _dir: tempfile::TempDir,
    store: DiskBlobStore,
}

impl Disk {
    fn new() -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = DiskBlobStore::open(&dir.path().join("blobs"), LIMIT).expect("open");
        Disk { _dir: dir, store }
    }
}

impl Harness for Disk {
    type S = DiskBlobStore;
    fn store(&self) -> &DiskBlobStore {
        &self.store
    }
    fn leftovers(&self) -> usize {
        self.store.temp_files().expect("temp files").len()
    }
    fn stages_uploads(&self) -> bool {
        true
    }
    fn blob_count(&self) -> usize {
        let mut n = 0;
        for fan in std::fs::read_dir(self.store.root()).expect("root") {
            let fan = fan.expect("entry");
            if fan.file_name() == "tmp" {
                continue;
            }
            n += std::fs::read_dir(fan.path()).expect("fan dir").count();
        }
        n
    }
}

/// Inline limit of 1000 bytes, so the suite's small payloads go inline and its large ones to
/// disk.
struct Tiered {
    _dir: tempfile::TempDir,
    _db: sled::Db,
    store: TieredBlobStore,
}

impl Tiered {
    fn new() -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let db = sled::Config::new()
            .path(dir.path().join("db"))
            .open()
            .expect("db");
        let disk = DiskBlobStore::open(&dir.path().join("blobs"), LIMIT).expect("open");
        let store = TieredBlobStore::open(&db, disk, 1000).expect("tiered");
        Tiered {
            _dir: dir,
            _db: db,
            store,
        }
    }
}

impl Harness for Tiered {
    type S = TieredBlobStore;
    fn store(&self) -> &TieredBlobStore {
        &self.store
    }
    fn leftovers(&self) -> usize {
        self.store.disk().temp_files().expect("temp files").len()
    }
    fn stages_uploads(&self) -> bool {
        false
    }
    fn blob_count(&self) -> usize {
        let mut n = self.store.inline_count();
        for fan in std::fs::read_dir(self.store.disk().root()).expect("root") {
            let fan = fan.expect("entry");
            if fan.file_name() == "tmp" {
                continue;
            }
            n += std::fs::read_dir(fan.path()).expect("fan dir").count();
        }
        n
    }
}

struct Memory(MemoryBlobStore);

impl Harness for Memory {
    type S = MemoryBlobStore;
    fn store(&self) -> &MemoryBlobStore {
        &self.0
    }
    fn leftovers(&self) -> usize {
        0
    }
    fn stages_uploads(&self) -> bool {
        false
    }
    fn blob_count(&self) -> usize {
        self.0.len()
    }
}

fn payload(n: usize, seed: u8) -> Vec<u8> {
    (0..n)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed))
        .collect()
}

fn assert_clean<H: Harness>(h: &H, blobs_before: usize) {
    assert_eq!(h.leftovers(), 0, "an unfinished upload left a temp file");
    assert_eq!(h.blob_count(), blobs_before, "a failed upload left a blob");
}

fn put_read_round_trip(h: &impl Harness) {
    let s = h.store();
    let data = payload(10_000, 1);
    let hash = s.put(&data).expect("put");
    assert!(is_hash(&hash));
    assert_eq!(hash, hash_hex(&data));
    assert!(s.contains(&hash).expect("contains"));
    assert_eq!(s.size(&hash).expect("size"), Some(data.len() as u64));
    assert_eq!(s.read(&hash).expect("read"), data);
    assert_eq!(s.read_verified(&hash).expect("read_verified"), data);
}

fn streaming_write(h: &impl Harness) {
    let s = h.store();
    let data = payload(100_003, 2);
    let mut w = s.begin().expect("begin");
    for chunk in data.chunks(4096) {
        w.write(chunk).expect("write");
    }
    assert_eq!(w.written(), data.len() as u64);
    let hash = w
        .finish(data.len() as u64, &hash_hex(&data))
        .expect("finish");
    assert_eq!(hash, hash_hex(&data));
    assert_eq!(s.read(&hash).expect("read"), data);
    assert_eq!(h.leftovers(), 0);
}

fn wrong_hash_is_rejected(h: &impl Harness) {
    let s = h.store();
    let before = h.blob_count();
    let data = payload(5000, 3);
    let declared = hash_hex(b"something else");
    let mut w = s.begin().expect("begin");
    w.write(&data).expect("write");
    let err = w
        .finish(data.len() as u64, &declared)
        .expect_err("must mismatch");
    match &err {
        StoreError::Mismatch {
            expected_blake3,
            got_blake3,
            expected_size,
            got_size,
        } => {
            assert_eq!(expected_blake3, &declared);
            assert_eq!(got_blake3, &hash_hex(&data));
            assert_eq!(*expected_size, data.len() as u64);
            assert_eq!(*got_size, data.len() as u64);
        }
        other => panic!("expected Mismatch, got {other:?}"),
    }
    let msg = err.to_string();
    assert!(
        msg.contains(&declared) && msg.contains(&hash_hex(&data)),
        "{msg}"
    );
    assert!(!s.contains(&declared).expect("contains"));
    assert!(!s.contains(&hash_hex(&data)).expect("contains"));
    assert_clean(h, before);
}

fn wrong_size_is_rejected(h: &impl Harness) {
    let s = h.store();
    let before = h.blob_count();
    let data = payload(5000, 4);
    let mut w = s.begin().expect("begin");
    w.write(&data).expect("write");
    let err = w
        .finish(data.len() as u64 + 1, &hash_hex(&data))
        .expect_err("must mismatch");
    assert!(
        matches!(
            err,
            StoreError::Mismatch {
                expected_size: 5001,
                got_size: 5000,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(!s.contains(&hash_hex(&data)).expect("contains"));
    assert_clean(h, before);
}

fn too_large_leaves_nothing(h: &impl Harness) {
    let s = h.store();
    let before = h.blob_count();
    let chunk = vec![7u8; (LIMIT / 4) as usize];
    let mut w = s.begin().expect("begin");
    for _ in 0..4 {
        w.write(&chunk).expect("within the limit");
    }
    let err = w.write(&[1]).expect_err("past the limit");
    assert!(
        matches!(err, StoreError::TooLarge { limit: LIMIT, got } if got == LIMIT + 1),
        "{err:?}"
    );
    // Even a caller that ignores the error and finishes must not get a truncated blob in.
    let mut full = vec![7u8; LIMIT as usize];
    full.push(1);
    let err = w
        .finish(LIMIT + 1, &hash_hex(&full))
        .expect_err("finish after overflow");
    assert!(matches!(err, StoreError::TooLarge { .. }), "{err:?}");
    assert_clean(h, before);
    // put goes through the same limit.
    let err = s.put(&full).expect_err("put past the limit");
    assert!(matches!(err, StoreError::TooLarge { .. }), "{err:?}");
    assert_clean(h, before);
}

fn dropped_writer_leaves_nothing(h: &impl Harness) {
    let s = h.store();
    let before = h.blob_count();
    let data = payload(20_000, 5);
    let mut w = s.begin().expect("begin");
    w.write(&data[..10_000]).expect("write");
    if h.stages_uploads() {
        // The upload really is staged until dropped, so the check below means something.
        assert_eq!(h.leftovers(), 1);
    }
    drop(w);
    assert!(!s.contains(&hash_hex(&data)).expect("contains"));
    assert!(!s.contains(&hash_hex(&data[..10_000])).expect("contains"));
    assert_clean(h, before);
}

fn put_is_idempotent(h: &impl Harness) {
    let s = h.store();
    let data = payload(3000, 6);
    let a = s.put(&data).expect("put");
    let count = h.blob_count();
    let b = s.put(&data).expect("put again");
    assert_eq!(a, b);
    assert_eq!(h.blob_count(), count);
    // A streamed upload of content already present succeeds too.
    let mut w = s.begin().expect("begin");
    w.write(&data).expect("write");
    assert_eq!(w.finish(data.len() as u64, &a).expect("finish"), a);
    assert_eq!(h.blob_count(), count);
    assert_eq!(s.read(&a).expect("read"), data);
    assert_eq!(h.leftovers(), 0);
}

fn open_streams_same_bytes(h: &impl Harness) {
    let s = h.store();
    let data = payload(300_000, 7);
    let hash = s.put(&data).expect("put");
    let mut r = s.open(&hash).expect("open");
    let mut got = Vec::new();
    let mut buf = [0u8; 7919];
    loop {
        let n = r.read(&mut buf).expect("read");
        if n == 0 {
            break;
        }
        got.extend_from_slice(&buf[..n]);
    }
    assert_eq!(got, data);
}

fn missing_is_not_found(h: &impl Harness) {
    let s = h.store();
    let hash = hash_hex(b"never stored");
    assert!(matches!(s.read(&hash), Err(StoreError::NotFound { hash: ref h }) if *h == hash));
    assert!(matches!(s.open(&hash), Err(StoreError::NotFound { .. })));
    assert_eq!(s.size(&hash).expect("size"), None);
    assert!(!s.contains(&hash).expect("contains"));
}

fn malformed_hashes_are_refused(h: &impl Harness) {
    let s = h.store();
    let valid = hash_hex(b"x");
    let bad = [
        "../etc/passwd".to_owned(),
        "zz".to_owned(),
        valid[..63].to_owned(),
        format!("{valid}0"),
        valid.to_uppercase(),
        format!("../{}", &valid[3..]),
        String::new(),
    ];
    for b in &bad {
        assert!(!is_hash(b), "{b:?}");
        assert!(
            matches!(s.read(b), Err(StoreError::InvalidHash { .. })),
            "read {b:?}"
        );
        assert!(
            matches!(s.open(b), Err(StoreError::InvalidHash { .. })),
            "open {b:?}"
        );
        assert!(
            matches!(s.contains(b), Err(StoreError::InvalidHash { .. })),
            "contains {b:?}"
        );
        assert!(
            matches!(s.size(b), Err(StoreError::InvalidHash { .. })),
            "size {b:?}"
        );
    }
}

fn put_file_imports(h: &impl Harness) {
    let s = h.store();
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("asset.glb");
    let data = payload(700_000, 8);
    std::fs::write(&path, &data).expect("write asset");
    let hash = s.put_file(&path).expect("put_file");
    assert_eq!(hash, hash_hex(&data));
    assert_eq!(s.read(&hash).expect("read"), data);
    let count = h.blob_count();
    assert_eq!(s.put_file(&path).expect("again"), hash);
    assert_eq!(h.blob_count(), count);
    let missing = dir.path().join("missing.glb");
    let err = s.put_file(&missing).expect_err("missing file");
    assert!(
        matches!(&err, StoreError::Io { path, .. } if *path == missing),
        "{err:?}"
    );
    assert_eq!(h.leftovers(), 0);
}

/// Runs every case of the suite as its own test against one store kind.
macro_rules! blob_suite {
    ($module:ident, $make:expr) => {
        mod $module {
            use super::*;
            blob_suite!(@cases $make;
                put_read_round_trip,
                streaming_write,
                wrong_hash_is_rejected,
                wrong_size_is_rejected,
                too_large_leaves_nothing,
                dropped_writer_leaves_nothing,
                put_is_idempotent,
                open_streams_same_bytes,
                missing_is_not_found,
                malformed_hashes_are_refused,
                put_file_imports);
        }
    };
    (@cases $make:expr; $($case:ident),*) => {
        $(
            #[test]
            fn $case() {
                super::$case(&$make);
            }
        )*
    };
}

blob_suite!(disk, Disk::new());
blob_suite!(memory, Memory(MemoryBlobStore::new(LIMIT)));
blob_suite!(tiered, Tiered::new());

#[test]
fn disk_malformed_hash_never_touches_outside_root() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = dir.path().join("blobs");
    let store = DiskBlobStore::open(&root, LIMIT).expect("open");
    // A file right outside the root that a traversal would reach.
    std::fs::write(dir.path().join("secret"), b"top secret").expect("write");
    for bad in ["../secret", "..", "zz", "/etc/passwd"] {
        assert!(matches!(
            store.blob_path(bad),
            Err(StoreError::InvalidHash { .. })
        ));
        assert!(matches!(
            store.read(bad),
            Err(StoreError::InvalidHash { .. })
        ));
    }
    let good = hash_hex(b"a");
    let p: PathBuf = store.blob_path(&good).expect("path");
    assert!(p.starts_with(&root), "{}", p.display());
}

#[test]
fn disk_stale_temp_files_are_removed_at_open() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = dir.path().join("blobs");
    let kept;
    {
        let store = DiskBlobStore::open(&root, LIMIT).expect("open");
        kept = store.put(b"survives").expect("put");
        let mut w = store.begin().expect("begin");
        w.write(b"half an upload").expect("write");
        assert_eq!(store.temp_files().expect("tmp").len(), 1);
        // kill -9 runs no destructors.
        std::mem::forget(w);
        std::fs::write(root.join("tmp").join("upload-99999-0"), b"older leftover").expect("write");
        assert_eq!(store.temp_files().expect("tmp").len(), 2);
    }
    let store = DiskBlobStore::open(&root, LIMIT).expect("reopen");
    assert!(store.temp_files().expect("tmp").is_empty());
    assert_eq!(
        store.read(&kept).expect("blob survives reopen"),
        b"survives"
    );
    // Uploads still work after the cleanup.
    let h = store.put(b"after").expect("put");
    assert_eq!(store.read(&h).expect("read"), b"after");
}

#[test]
fn disk_blob_layout_fans_out() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = dir.path().join("blobs");
    let store = DiskBlobStore::open(&root, LIMIT).expect("open");
    let h = store.put(b"layout").expect("put");
    let expected = root.join(&h[..2]).join(&h);
    assert!(expected.is_file(), "{}", expected.display());
}
