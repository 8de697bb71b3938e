"""Reads a folder export and WebDataset shards with the client's readers and writes each
sample's arrays as OUT/{folder,webdataset}/INDEX/PASS.npy, for tests/python_client.rs to
compare with what the stream gave. Usage: export_check.py FOLDER SHARDS_DIR OUT"""

import sys
from pathlib import Path

import numpy as np

import lightfarm

folder, shards, out = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
for name, samples in (("folder", lightfarm.read_folder(folder, split="")),
                      ("webdataset", lightfarm.read_webdataset(shards, split=""))):
    count = 0
    for s in samples:
        d = out / name / str(s.index)
        d.mkdir(parents=True, exist_ok=True)
        assert s.metadata["sample"]["index"] == s.index
        for p, a in s.arrays.items():
            np.save(d / f"{p}.npy", a)
        count += 1
    print(f"{name}: {count} samples", flush=True)
