"""The README's hair figure (docs/hair.png): one head with its hair black, brown, blond and red,
each as the old camera-facing ribbons and as fibres (Chiang 2016), under two HDRIs.

    python bench/hair_figure.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm --size 192 --spp 64

Scenes come from `cargo run -p lightfarm-subject --example hair_figure_scenes` (sample 0 of
examples/dataset.toml); every tile is `lightfarm render ... --preview`, lit0 tone-mapped by the
renderer itself. Prints each render's time.
"""

import argparse
import os
import subprocess
import sys
import time

from PIL import Image, ImageDraw

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
COLOURS = ["black", "brown", "blond", "red"]
HDRIS = [("rooitou_park", "assets/hdri/rooitou_park_1k.hdr"),
         ("st_fagans_interior", "assets/hdri/st_fagans_interior_1k.hdr")]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--size", type=int, default=192)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--work", default="/tmp/lightfarm-hair-figure")
    ap.add_argument("--out", default=os.path.join(REPO, "docs", "hair.png"))
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    subprocess.run(["cargo", "run", "-q", "-p", "lightfarm-subject", "--example",
                    "hair_figure_scenes", "--", "examples/dataset.toml", "0", args.work],
                   cwd=REPO, check=True)
    s = args.size
    label_h = 16
    cols = [(h, kind) for h in HDRIS for kind in ("ribbons", "fibres")]
    sheet = Image.new("RGB", (s * len(cols), label_h + s * len(COLOURS)), (0, 0, 0))
    draw = ImageDraw.Draw(sheet)
    for j, ((hname, _), kind) in enumerate(cols):
        draw.text((j * s + 4, 2), f"{kind} | {hname}", fill=(255, 255, 255))
    for i, colour in enumerate(COLOURS):
        for j, ((hname, hpath), kind) in enumerate(cols):
            glb = os.path.join(args.work, f"{colour}_{kind}.glb")
            png = os.path.join(args.work, f"{colour}_{kind}_{hname}.png")
            t = time.time()
            subprocess.run([args.lightfarm, "render", "--scene", glb, "--hdri",
                            os.path.join(REPO, hpath), "--size", f"{s}x{s}", "--spp",
                            str(args.spp), "--passes", "none", "--out",
                            os.path.join(args.work, "tile.exr"), "--preview", png],
                           check=True, stdout=subprocess.DEVNULL)
            print(f"{colour} {kind} {hname}: {time.time() - t:.1f} s", flush=True)
            tile = Image.open(png).convert("RGB").resize((s, s))
            sheet.paste(tile, (j * s, label_h + i * s))
            draw.text((j * s + 4, label_h + i * s + 2), colour, fill=(255, 255, 0))
    sheet.save(args.out, optimize=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
