use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

use lightfarm_store::{
    export, hash_hex, read_export, BlobStore, DiskBlobStore, ExportFormat, SampleIndex, StoreError,
};

const JOB: &str = "job-a";

struct Farm {
    dir: tempfile::TempDir,
    blobs: DiskBlobStore,
    index: SampleIndex,
    _db: sled::Db,
}

fn fake_exr(index: u64) -> Vec<u8> {
    // Distinct sizes and contents per sample, so a mix-up between samples shows.
    let mut b = b"v/1\x01fake-exr".to_vec();
    b.extend((0..(1000 + index * 37)).map(|i| (i as u8) ^ (index as u8)));
    b
}

fn split_of(index: u64) -> &'static str {
    if index % 3 == 2 {
        "val"
    } else {
        "train"
    }
}

fn farm() -> Farm {
    let dir = tempfile::tempdir().expect("tempdir");
    let blobs = DiskBlobStore::open(&dir.path().join("blobs"), 1 << 20).expect("blobs");
    let db = sled::Config::new()
        .path(dir.path().join("db"))
        .open()
        .expect("db");
    let index = SampleIndex::open(&db).expect("index");
    // Commit out of index order: exports must still come out in index order.
    for i in [3u64, 0, 4, 1, 2] {
        let exr = fake_exr(i);
        let hash = blobs.put(&exr).expect("put");
        let meta = format!(r#"{{"sample":{{"seed":{}}},"worker":"w{i}"}}"#, i * 11);
        index
            .commit(
                JOB,
                i,
                split_of(i),
                &hash,
                exr.len() as u64,
                &meta,
                1_700_000_000.5,
            )
            .expect("commit");
    }
    // Another job's sample must not leak into the export.
    let other = blobs.put(b"other job").expect("put");
    index
        .commit("job-b", 0, "train", &other, 9, "{}", 1.0)
        .expect("commit");
    Farm {
        dir,
        blobs,
        index,
        _db: db,
    }
}

impl Farm {
    fn out(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn export(
        &self,
        format: &ExportFormat,
        out: &Path,
    ) -> Result<lightfarm_store::ExportReport, StoreError> {
        let mut calls = Vec::new();
        let r = export(
            &self.index,
            &self.blobs,
            JOB,
            format,
            out,
            &mut |done, total| calls.push((done, total)),
        );
        if r.is_ok() {
            assert_eq!(calls, (1..=5).map(|d| (d, 5)).collect::<Vec<_>>());
        }
        r
    }

    fn corrupt(&self, index: u64) -> Vec<u8> {
        let rec = self.index.get(JOB, index).expect("get").expect("committed");
        let path = self.blobs.blob_path(&rec.blake3).expect("path");
        let original = fs::read(&path).expect("read blob");
        let mut bad = original.clone();
        bad[20] ^= 0xff; // same size, different bytes: only a re-hash can tell
        fs::write(&path, &bad).expect("overwrite blob");
        original
    }

    fn restore(&self, index: u64, original: &[u8]) {
        let rec = self.index.get(JOB, index).expect("get").expect("committed");
        fs::write(self.blobs.blob_path(&rec.blake3).expect("path"), original).expect("restore");
    }
}

fn check_samples(samples: &[lightfarm_store::ExportedSample]) {
    let indices: Vec<u64> = samples.iter().map(|s| s.index).collect();
    assert_eq!(indices, vec![0, 1, 2, 3, 4]);
    for s in samples {
        assert_eq!(s.exr, fake_exr(s.index), "sample {}", s.index);
        assert_eq!(s.json["index"], s.index);
        assert_eq!(s.json["job_id"], JOB);
        assert_eq!(s.json["split"], split_of(s.index));
        assert_eq!(s.json["blake3"], hash_hex(&fake_exr(s.index)));
        assert_eq!(s.json["size"], fake_exr(s.index).len() as u64);
        // The committed metadata survives as it was.
        assert_eq!(s.json["sample"]["seed"], s.index * 11);
        assert_eq!(s.json["worker"], format!("w{}", s.index));
    }
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .expect("read_dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn tar_members(path: &Path) -> Vec<String> {
    let mut archive = tar::Archive::new(fs::File::open(path).expect("open shard"));
    archive
        .entries()
        .expect("entries")
        .map(|e| {
            let e = e.expect("entry");
            assert_eq!(e.header().entry_type(), tar::EntryType::Regular);
            e.path().expect("path").to_string_lossy().into_owned()
        })
        .collect()
}

#[test]
fn folder_export_round_trips() {
    let f = farm();
    let out = f.out("folder/nested"); // created when missing
    let report = f.export(&ExportFormat::Folder, &out).expect("export");
    assert_eq!(report.samples, 5);
    assert_eq!(report.files.len(), 11);
    assert_eq!(
        report.files.last().expect("files"),
        &out.join("manifest.jsonl")
    );
    let on_disk: u64 = report
        .files
        .iter()
        .map(|p| fs::metadata(p).expect("meta").len())
        .sum();
    assert_eq!(report.bytes, on_disk);
    for i in 0..5 {
        assert!(out.join(format!("{i:08}.exr")).is_file());
        assert!(out.join(format!("{i:08}.json")).is_file());
    }
    let manifest = fs::read_to_string(out.join("manifest.jsonl")).expect("manifest");
    let lines: Vec<serde_json::Value> = manifest
        .lines()
        .map(|l| serde_json::from_str(l).expect("manifest line"))
        .collect();
    assert_eq!(lines.len(), 5);
    assert_eq!(lines[2]["index"], 2);
    assert_eq!(lines[2]["split"], "val");
    assert_eq!(
        lines[2]["files"],
        serde_json::json!(["00000002.exr", "00000002.json"])
    );
    check_samples(&read_export(&out).expect("read back"));
    assert!(names_in(&out).iter().all(|n| !n.ends_with(".partial")));
}

#[test]
fn webdataset_export_round_trips() {
    let f = farm();
    let out = f.out("wds");
    let report = f
        .export(
            &ExportFormat::WebDataset {
                samples_per_shard: 2,
            },
            &out,
        )
        .expect("export");
    assert_eq!(report.samples, 5);
    let shards: Vec<PathBuf> = (0..3)
        .map(|s| out.join(format!("{JOB}-{s:06}.tar")))
        .collect();
    let mut expected_files = shards.clone();
    expected_files.push(out.join("manifest.jsonl"));
    assert_eq!(report.files, expected_files);
    let on_disk: u64 = report
        .files
        .iter()
        .map(|p| fs::metadata(p).expect("meta").len())
        .sum();
    assert_eq!(report.bytes, on_disk);

    // Members of a sample share a basename and are adjacent; samples are in index order.
    let members: Vec<String> = shards.iter().flat_map(|s| tar_members(s)).collect();
    let expected: Vec<String> = (0..5u64)
        .flat_map(|i| [format!("{i:08}.exr"), format!("{i:08}.json")])
        .collect();
    assert_eq!(members, expected);
    assert_eq!(
        tar_members(&shards[2]),
        vec!["00000004.exr", "00000004.json"]
    );

    // Raw member bytes are the blob, not a re-encoding.
    let mut archive = tar::Archive::new(fs::File::open(&shards[0]).expect("open"));
    let mut first = archive
        .entries()
        .expect("entries")
        .next()
        .expect("member")
        .expect("entry");
    let mut bytes = Vec::new();
    first.read_to_end(&mut bytes).expect("read member");
    assert_eq!(bytes, fake_exr(0));

    check_samples(&read_export(&out).expect("read dir back"));
    let one = read_export(&shards[1]).expect("read one shard");
    assert_eq!(one.iter().map(|s| s.index).collect::<Vec<_>>(), vec![2, 3]);
    assert!(names_in(&out).iter().all(|n| !n.ends_with(".partial")));
}

#[test]
fn corrupted_blob_is_not_exported() {
    let f = farm();
    let original = f.corrupt(2);
    for (name, format) in [
        ("folder", ExportFormat::Folder),
        (
            "wds",
            ExportFormat::WebDataset {
                samples_per_shard: 10,
            },
        ),
    ] {
        let out = f.out(name);
        let err = f
            .export(&format, &out)
            .expect_err("corrupt blob must fail the export");
        let msg = err.to_string();
        assert!(matches!(err, StoreError::Export(_)), "{err:?}");
        assert!(
            msg.contains("sample 2") && msg.contains(JOB) && msg.contains("corrupt"),
            "{msg}"
        );
        let names = names_in(&out);
        assert!(!names.contains(&"manifest.jsonl".to_owned()), "{names:?}");
        assert!(
            !names
                .iter()
                .any(|n| n.ends_with(".partial") || n.ends_with(".tar")),
            "{names:?}"
        );
        assert!(!names.contains(&"00000002.exr".to_owned()), "{names:?}");
    }
    // Once the blob is repaired, the same directories can be exported into again.
    f.restore(2, &original);
    f.export(&ExportFormat::Folder, &f.out("folder"))
        .expect("redo folder");
    check_samples(&read_export(&f.out("folder")).expect("read back"));
    f.export(
        &ExportFormat::WebDataset {
            samples_per_shard: 10,
        },
        &f.out("wds"),
    )
    .expect("redo wds");
    check_samples(&read_export(&f.out("wds")).expect("read back"));
}

#[test]
fn missing_blob_names_the_sample() {
    let f = farm();
    let rec = f.index.get(JOB, 4).expect("get").expect("committed");
    fs::remove_file(f.blobs.blob_path(&rec.blake3).expect("path")).expect("remove");
    let err = f
        .export(&ExportFormat::Folder, &f.out("x"))
        .expect_err("missing blob");
    let msg = err.to_string();
    assert!(msg.contains("sample 4") && msg.contains("missing"), "{msg}");
}

#[test]
fn re_export_of_the_same_job_overwrites() {
    let f = farm();
    let out = f.out("again");
    f.export(&ExportFormat::Folder, &out).expect("first");
    f.export(&ExportFormat::Folder, &out)
        .expect("second into the same folder");
    check_samples(&read_export(&out).expect("read back"));
    // Switching format replaces the previous export's files instead of mixing them.
    f.export(
        &ExportFormat::WebDataset {
            samples_per_shard: 3,
        },
        &out,
    )
    .expect("webdataset over the folder export");
    let names = names_in(&out);
    assert!(
        !names
            .iter()
            .any(|n| n.ends_with(".exr") || n.ends_with(".json") && n != ".lightfarm-export.json"),
        "{names:?}"
    );
    assert!(names.contains(&format!("{JOB}-000001.tar")), "{names:?}");
    check_samples(&read_export(&out).expect("read back"));
    // And fewer, larger shards leave no stale shard behind.
    f.export(
        &ExportFormat::WebDataset {
            samples_per_shard: 100,
        },
        &out,
    )
    .expect("one shard");
    assert!(!out.join(format!("{JOB}-000001.tar")).exists());
    check_samples(&read_export(&out).expect("read back"));
}

#[test]
fn foreign_directories_are_refused() {
    let f = farm();
    let foreign = f.out("foreign");
    fs::create_dir_all(&foreign).expect("mkdir");
    fs::write(foreign.join("notes.txt"), b"mine").expect("write");
    let err = f
        .export(&ExportFormat::Folder, &foreign)
        .expect_err("non-empty foreign dir");
    let msg = err.to_string();
    assert!(
        msg.contains(&foreign.display().to_string()) && msg.contains("not empty"),
        "{msg}"
    );
    assert_eq!(
        names_in(&foreign),
        vec!["notes.txt"],
        "nothing may be written into it"
    );

    // A directory holding another job's export is refused too, naming that job.
    let other = f.out("other");
    export(
        &f.index,
        &f.blobs,
        "job-b",
        &ExportFormat::Folder,
        &other,
        &mut |_, _| {},
    )
    .expect("export job-b");
    let before = names_in(&other);
    let err = f
        .export(&ExportFormat::Folder, &other)
        .expect_err("other job's export");
    assert!(err.to_string().contains("job-b"), "{err}");
    assert_eq!(names_in(&other), before);

    let err = f
        .export(
            &ExportFormat::WebDataset {
                samples_per_shard: 0,
            },
            &f.out("zero"),
        )
        .expect_err("zero samples per shard");
    assert!(err.to_string().contains("samples_per_shard"), "{err}");
}

#[test]
fn read_export_rejects_non_adjacent_members() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.tar");
    let mut b = tar::Builder::new(fs::File::create(&path).expect("create"));
    for name in [
        "00000000.exr",
        "00000001.exr",
        "00000000.json",
        "00000001.json",
    ] {
        let mut h = tar::Header::new_ustar();
        h.set_size(2);
        h.set_mode(0o644);
        b.append_data(&mut h, name, &b"{}"[..]).expect("append");
    }
    b.finish().expect("finish");
    drop(b);
    let err = read_export(&path).expect_err("non-adjacent");
    assert!(err.to_string().contains("not adjacent"), "{err}");
}
