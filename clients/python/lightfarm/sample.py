"""A rendered sample as numpy arrays, decoded from its OpenEXR file exactly as the Rust
trainer decodes it (`services/trainer/src/sample.rs`): non-finite values become 0, the mask is
clamped to [0, 1], and pixels without a lens normal take the normal."""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from typing import Dict, Iterable, Optional

import numpy as np

#: Every pass a sample holds, as `passes=` takes them.
PASSES = ("lit0", "lit1", "albedo", "normal", "normal_lens", "mask")

#: The EXR header attribute the render worker writes (sample spec, materials, id table).
SAMPLE_ATTRIBUTE = "lightfarm.sample"

_CHANNELS = {
    "lit0": ("R", "G", "B"),
    "lit1": ("R", "G", "B"),
    "albedo": ("R", "G", "B"),
    "normal": ("X", "Y", "Z"),
    "normal_lens": ("X", "Y", "Z"),
}


@dataclasses.dataclass
class Sample:
    """One committed sample: its place in the job, its passes and its metadata.

    `arrays` maps pass names to float32 arrays, (H, W, 3) for colours and normals and (H, W)
    for the mask. `metadata` is the sample's record: `sample` (the spec of this index, as
    `lightfarm spec expand` prints it), `stats` (render statistics) and `worker`.
    """

    job_id: str
    index: int
    split: str
    sequence: int
    blake3: str
    arrays: Dict[str, np.ndarray]
    metadata: dict

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]

    @classmethod
    def from_record(cls, info, data: bytes, passes) -> "Sample":
        """A sample from its index record (SampleInfo) and its EXR's bytes."""
        return cls(
            job_id=info.job_id,
            index=info.index,
            split=info.split,
            sequence=info.sequence,
            blake3=info.blake3,
            arrays=decode_exr(data, passes, name=f"sample {info.index} of {info.job_id}"),
            metadata=json.loads(info.metadata_json or "{}"),
        )


def check_passes(passes: Optional[Iterable[str]]) -> tuple:
    """The passes asked for, checked; None means all of them."""
    if passes is None:
        return PASSES
    passes = tuple(passes)
    unknown = [p for p in passes if p not in PASSES]
    if unknown:
        raise ValueError(f"unknown pass {unknown[0]!r}: choose from {', '.join(PASSES)}")
    return passes


def _finite(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float32)
    return np.where(np.isfinite(a), a, np.float32(0.0)).astype(np.float32)


def decode_exr(data: bytes, passes: Optional[Iterable[str]] = None, name: str = "sample") -> Dict[str, np.ndarray]:
    """The passes of a sample EXR (its bytes); `name` is what errors mention."""
    import OpenEXR

    passes = check_passes(passes)
    # OpenEXR's Python binding reads files only.
    fd, path = tempfile.mkstemp(suffix=".exr")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        try:
            part = OpenEXR.File(path, separate_channels=True).parts[0]
        except Exception as e:  # the binding raises plain RuntimeErrors
            raise ValueError(f"{name}: not a readable OpenEXR file ({e})") from None
    finally:
        os.unlink(path)
    channels = part.channels

    def channel(n: str) -> np.ndarray:
        if n not in channels:
            raise ValueError(f"{name}: has no channel {n}; is it a lightfarm sample?")
        return _finite(channels[n].pixels)

    need = set(passes)
    if "normal_lens" in need:
        need.add("normal")
    out: Dict[str, np.ndarray] = {}
    for p in PASSES:
        if p not in need:
            continue
        if p == "mask":
            out[p] = np.clip(channel("mask.A"), 0.0, 1.0).astype(np.float32)
        else:
            out[p] = np.stack([channel(f"{p}.{c}") for c in _CHANNELS[p]], axis=-1)
    if "normal_lens" in out:
        lens = out["normal_lens"]
        off = np.all(lens == 0.0, axis=-1)
        lens[off] = out["normal"][off]
    return {p: out[p] for p in passes}


def header_of(data: bytes) -> dict:
    """The sample EXR's `lightfarm.sample` header attribute as a dict ({} without one)."""
    import OpenEXR

    fd, path = tempfile.mkstemp(suffix=".exr")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        header = OpenEXR.File(path, header_only=True).header()
    finally:
        os.unlink(path)
    text = header.get(SAMPLE_ATTRIBUTE)
    return json.loads(text) if isinstance(text, str) else {}
