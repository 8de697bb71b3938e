"""The README's eyelash figure (docs/eyelashes.png): close-ups of the eyes of assembled samples,
their lashes grown as fibres on the lid margins (crates/subject/src/eyelids.rs).

    python bench/eyelash_figure.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm --spp 64

Each sample is exported with `lightfarm spec glb` and rendered with `lightfarm render --camera`
aimed at the middle of its `eyelashes` fibres (read from the .glb's accessor bounds), from 16 cm
in front. Prints each render's time.
"""

import argparse
import json
import os
import struct
import subprocess
import sys
import time

from PIL import Image, ImageDraw

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HDRI = "assets/hdri/rooitou_park_1k.hdr"


def lash_centre(glb):
    with open(glb, "rb") as f:
        data = f.read()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + jlen])
    for mesh in doc["meshes"]:
        if mesh.get("name") == "eyelashes":
            acc = doc["accessors"][mesh["primitives"][0]["attributes"]["POSITION"]]
            return [(a + b) / 2 for a, b in zip(acc["min"], acc["max"])]
    sys.exit(f"{glb} has no eyelashes mesh (a head without eyeballs?)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--spec", default=os.path.join(REPO, "examples/dataset.toml"))
    ap.add_argument("--indices", default="0,3", help="sample indices, one row each")
    ap.add_argument("--width", type=int, default=384)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--work", default="/tmp/lightfarm-eyelash-figure")
    ap.add_argument("--out", default=os.path.join(REPO, "docs", "eyelashes.png"))
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    w, h = args.width, args.width // 2
    rows = [int(i) for i in args.indices.split(",")]
    sheet = Image.new("RGB", (w, h * len(rows)))
    draw = ImageDraw.Draw(sheet)
    for r, index in enumerate(rows):
        glb = os.path.join(args.work, f"sample{index}.glb")
        subprocess.run([args.lightfarm, "spec", "glb", args.spec, "--index", str(index),
                        "--out", glb], check=True, stdout=subprocess.DEVNULL)
        x, y, z = lash_centre(glb)
        camera = f"{x + 0.02},{y + 0.01},{z + 0.16}:{x},{y},{z}:26"
        png = os.path.join(args.work, f"sample{index}.png")
        t = time.time()
        subprocess.run([args.lightfarm, "render", "--scene", glb, "--hdri",
                        os.path.join(REPO, HDRI), "--camera", camera, "--size", f"{w}x{h}",
                        "--spp", str(args.spp), "--passes", "none", "--out",
                        os.path.join(args.work, "tile.exr"), "--preview", png],
                       check=True, stdout=subprocess.DEVNULL)
        print(f"sample {index}: {time.time() - t:.1f} s", flush=True)
        sheet.paste(Image.open(png).convert("RGB").resize((w, h)), (0, r * h))
        draw.text((4, r * h + 2), f"sample {index}", fill=(255, 255, 0))
    sheet.save(args.out, optimize=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
