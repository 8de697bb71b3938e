"""`StreamingDataset`: a `torch.utils.data.IterableDataset` over a job's samples (a running
job's stream, or an export), sharded across DataLoader workers and distributed ranks so that
every sample is yielded exactly once per epoch, with an optional local cache of the EXRs."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable, Iterable, Optional

import torch
from torch.utils.data import IterableDataset, get_worker_info

from .client import Client
from .sample import Sample, check_passes
from .stream import SampleStream


def shard_of(index: int, shards: int) -> int:
    """The shard a sample belongs to: by its index, so the split does not depend on the order
    samples were committed or on which process sees them first."""
    return index % shards


def current_shard(rank: Optional[int] = None, world_size: Optional[int] = None):
    """(this process's shard, shard count): distributed rank × DataLoader worker."""
    if rank is None or world_size is None:
        if torch.distributed.is_available() and torch.distributed.is_initialized():
            rank, world_size = torch.distributed.get_rank(), torch.distributed.get_world_size()
        else:
            rank = int(os.environ.get("RANK", 0)) if rank is None else rank
            world_size = int(os.environ.get("WORLD_SIZE", 1)) if world_size is None else world_size
    info = get_worker_info()
    worker, workers = (info.id, info.num_workers) if info is not None else (0, 1)
    return rank * workers + worker, world_size * workers


def to_tensors(sample: Sample) -> dict:
    """A sample as a dict of CHW float tensors (the mask 1×H×W), its `index`, and `metadata`
    as JSON text (so that the DataLoader's default collate batches it as a list)."""
    out = {}
    for name, a in sample.arrays.items():
        t = torch.from_numpy(a)
        out[name] = t.permute(2, 0, 1).contiguous() if t.ndim == 3 else t.unsqueeze(0)
    out["index"] = sample.index
    out["metadata"] = json.dumps(sample.metadata)
    return out


class StreamingDataset(IterableDataset):
    """The samples of `job` on the coordinator at `address` (split "train", "test" or ""), or of
    an export (`export=` a folder or WebDataset shards), as dicts of tensors (`transform`
    replaces `to_tensors`).

    Each (rank, DataLoader worker) pair reads the whole stream's metadata but decodes only the
    samples of its shard (index mod shards). With `follow`, an epoch lasts until the job ends.
    `cache_dir` keeps each EXR (by its BLAKE3) so later epochs read the disk, not the network.
    Ranks come from torch.distributed when initialised, else `RANK`/`WORLD_SIZE`, else the
    `rank`/`world_size` arguments.
    """

    def __init__(
        self,
        address: Optional[str] = None,
        job: Optional[str] = None,
        token: Optional[str] = None,
        split: str = "train",
        passes: Optional[Iterable[str]] = None,
        follow: bool = True,
        tls_ca: Optional[str] = None,
        cache_dir: Optional[str] = None,
        export: Optional[str] = None,
        rank: Optional[int] = None,
        world_size: Optional[int] = None,
        transform: Optional[Callable[[Sample], object]] = None,
    ):
        super().__init__()
        if (export is None) == (job is None):
            raise ValueError("give either job= (with address=) or export=")
        self.address, self.job, self.token, self.tls_ca = address, job, token, tls_ca
        self.split, self.passes, self.follow = split, check_passes(passes), follow
        self.cache_dir = Path(cache_dir) if cache_dir else None
        self.export = export
        self.rank, self.world_size = rank, world_size
        self.transform = transform or to_tensors

    def _from_export(self, shard: int, shards: int):
        from .export import read_folder, read_webdataset

        p = Path(self.export)
        reader = read_folder if (p / "manifest.jsonl").is_file() else read_webdataset
        for s in reader(p, split=self.split, passes=self.passes):
            if shard_of(s.index, shards) == shard:
                yield s

    def _cached(self, info, fetch) -> bytes:
        if self.cache_dir is None:
            return fetch()
        path = self.cache_dir / info.blake3[:2] / f"{info.blake3}.exr"
        if path.is_file():
            data = path.read_bytes()
            if len(data) == info.size:
                return data
        data = fetch()
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        os.replace(tmp, path)
        return data

    def _from_stream(self, shard: int, shards: int):
        client = Client(self.address, self.token, self.tls_ca)
        try:
            # Metadata only; the EXRs of this shard's samples are fetched (or read from the
            # cache) one by one.
            stream = SampleStream(client, self.job, self.split, passes=(), follow=self.follow)
            for info in stream.infos():
                if shard_of(info.index, shards) != shard:
                    continue
                data = self._cached(info, lambda: client.get_sample(info.job_id, info.index)[1])
                yield Sample.from_record(info, data, self.passes)
        finally:
            client.close()

    def __iter__(self):
        shard, shards = current_shard(self.rank, self.world_size)
        samples = self._from_export(shard, shards) if self.export else self._from_stream(shard, shards)
        for s in samples:
            yield self.transform(s)
