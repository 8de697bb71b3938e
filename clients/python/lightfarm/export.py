"""Readers of `lightfarm export` output with the stream's output: the same `Sample`s from a
folder export (`manifest.jsonl` + `NNNNNNNN.exr` + `.json`) or WebDataset tar shards, so code
written against `SampleStream` runs on an export."""

from __future__ import annotations

import json
import tarfile
from pathlib import Path
from typing import Iterable, Iterator, Optional

from .sample import Sample, check_passes, decode_exr


def _sample(meta: dict, data: bytes, passes, where: str) -> Sample:
    return Sample(
        job_id=meta.get("job_id", ""),
        index=int(meta.get("index", 0)),
        split=meta.get("split", ""),
        sequence=int(meta.get("sequence", 0)),
        blake3=meta.get("blake3", ""),
        arrays=decode_exr(data, passes, name=where),
        metadata=meta,
    )


def read_folder(path, split: str = "", passes: Optional[Iterable[str]] = None) -> Iterator[Sample]:
    """The samples of a folder export, in its manifest's order."""
    root = Path(path)
    passes = check_passes(passes)
    manifest = root / "manifest.jsonl"
    if not manifest.is_file():
        raise FileNotFoundError(f"{root}: no manifest.jsonl; is it a `lightfarm export --format folder` folder?")
    for n, line in enumerate(manifest.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
            exr_name, json_name = entry["files"][0], entry["files"][1]
        except (ValueError, KeyError, IndexError) as e:
            raise ValueError(f"{manifest}:{n}: not a manifest entry ({e})") from None
        if split and entry.get("split") != split:
            continue
        meta = json.loads((root / json_name).read_text())
        yield _sample(meta, (root / exr_name).read_bytes(), passes, str(root / exr_name))


def read_webdataset(paths, split: str = "", passes: Optional[Iterable[str]] = None) -> Iterator[Sample]:
    """The samples of WebDataset shards (a shard path, a folder of `*.tar`, or a list)."""
    passes = check_passes(passes)
    if isinstance(paths, (str, Path)):
        p = Path(paths)
        paths = sorted(p.glob("*.tar")) if p.is_dir() else [p]
    for shard in paths:
        pending = {}
        with tarfile.open(shard) as tar:
            for member in tar:
                if not member.isfile():
                    continue
                key, _, ext = member.name.rpartition(".")
                f = tar.extractfile(member)
                pending.setdefault(key, {})[ext] = f.read() if f else b""
                entry = pending[key]
                if "exr" in entry and "json" in entry:
                    del pending[key]
                    meta = json.loads(entry["json"])
                    if split and meta.get("split") != split:
                        continue
                    yield _sample(meta, entry["exr"], passes, f"{shard}:{key}.exr")
        if pending:
            raise ValueError(f"{shard}: {sorted(pending)[0]} lacks its .exr or .json")
