"""The README's figure of generated people (docs/people.jpg): 24 synthetic identities of a
frontal spec (bench/people.toml) in a grid, and below them a row of the built-in heads under
the same camera, each the lit0 tile of `lightfarm preview`.

    python bench/people_figure.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm --size 512 --spp 8 --tile 192

Runs `lightfarm preview` twice (synthetic and built-in heads) and crops the lit0 column out of
its contact sheets (layout of crates/cli/src/sheet.rs: a 12 px title line, then per sample a
12 px caption line and the tiles, 2 px gaps). Prints each preview's time.
"""

import argparse
import os
import subprocess
import time

from PIL import Image

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LINE_H, GAP = 12, 2


def lit0_tiles(sheet_png, rows, size):
    im = Image.open(sheet_png).convert("RGB")
    tiles = []
    for r in range(rows):
        y = LINE_H + r * (LINE_H + size + GAP) + LINE_H
        tiles.append(im.crop((GAP, y, GAP + size, y + size)))
    return tiles


def preview(lightfarm, spec, count, size, spp, out):
    t = time.time()
    subprocess.run([lightfarm, "preview", spec, "--count", str(count), "--size", str(size),
                    "--spp", str(spp), "--out", out], check=True)
    print(f"{spec}: {count} samples at {size}² x {spp} spp in {time.time() - t:.0f} s")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--size", type=int, default=192)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--tile", type=int, default=0, help="tile size on the sheet (default size/2)")
    ap.add_argument("--people", type=int, default=24)
    ap.add_argument("--scans", type=int, default=8, help="built-in head samples in the last row")
    ap.add_argument("--work", default="/tmp/lightfarm-people-figure")
    ap.add_argument("--out", default=os.path.join(REPO, "docs", "people.jpg"))
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    spec = os.path.join(REPO, "bench", "people.toml")
    scans = os.path.join(a.work, "scans.toml")
    with open(spec) as f:
        text = f.read()
    with open(scans, "w") as f:
        f.write(text.replace('heads = ["synthetic"]', 'heads = ["*"]'))
    preview(a.lightfarm, spec, a.people, a.size, a.spp, os.path.join(a.work, "people.png"))
    preview(a.lightfarm, scans, a.scans, a.size, a.spp, os.path.join(a.work, "scans.png"))
    people = lit0_tiles(os.path.join(a.work, "people.png"), a.people, a.size)
    built_in = lit0_tiles(os.path.join(a.work, "scans.png"), a.scans, a.size)
    cols = 8
    rows = (len(people) + cols - 1) // cols
    s = a.tile or a.size // 2
    sheet = Image.new("RGB", (cols * s, (rows + 1) * s + 8), (24, 24, 24))
    for i, t in enumerate(people):
        sheet.paste(t.resize((s, s), Image.LANCZOS), ((i % cols) * s, (i // cols) * s))
    for i, t in enumerate(built_in[:cols]):
        sheet.paste(t.resize((s, s), Image.LANCZOS), (i * s, rows * s + 8))
    # JPEG: at a few spp the tiles are noisy, which PNG stores at 6x the size.
    if a.out.lower().endswith((".jpg", ".jpeg")):
        sheet.save(a.out, quality=88, optimize=True)
    else:
        sheet.save(a.out)
    print(a.out)


if __name__ == "__main__":
    main()
