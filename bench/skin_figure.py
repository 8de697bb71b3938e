"""The README figure: the Lee Perry-Smith scan under two HDRIs, with the glTF Lambert + GGX
mapping it rendered with before issue 12 (top; colour map only) and with the paper's skin and
the scan's normal and specular maps (bottom).

    python bench/skin_figure.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm --out docs/skin.png

Needs Pillow (the bench venv of bench/cycles_skin.sh has it). Renders 512² (--size) at --spp,
tone-mapped by lightfarm's own --preview (exposure to the subject's mean, Reinhard), and tiles the
four previews at --tile pixels each.
"""

import argparse
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cycles_skin import REPO, make_skin_head  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--tile", type=int, default=256)
    ap.add_argument("--out", default=os.path.join(REPO, "docs/skin.png"))
    ap.add_argument("--work", default=os.path.expanduser("~/.cache/lightfarm-bench/skin_figure"))
    args = ap.parse_args()
    from PIL import Image
    os.makedirs(args.work, exist_ok=True)
    src = os.path.join(REPO, "assets/heads/LeePerrySmith_textured.glb")
    hdris = ["studio_small_03_1k.hdr", "rooitou_park_1k.hdr"]
    tiles = []
    for skin in (False, True):
        scene = os.path.join(args.work, f"head_{'skin' if skin else 'gltf'}.glb")
        make_skin_head(src, scene, skin, maps=skin)
        row = []
        for k, h in enumerate(hdris):
            png = os.path.join(args.work, f"{'skin' if skin else 'gltf'}_{k}.png")
            subprocess.run([args.lightfarm, "render", "--scene", scene,
                            "--hdri", os.path.join(REPO, "assets/hdri", h),
                            "--camera", "0.08,0.02,0.55:0,0,0:30", "--size", f"{args.size}x{args.size}",
                            "--spp", str(args.spp), "--seed", "1", "--passes", "none",
                            "--out", os.path.join(args.work, "x.exr"), "--preview", png], check=True)
            row.append(Image.open(png).convert("RGB").resize((args.tile, args.tile), Image.LANCZOS))
        tiles.append(row)
    sheet = Image.new("RGB", (2 * args.tile, 2 * args.tile))
    for r, row in enumerate(tiles):
        for c, im in enumerate(row):
            sheet.paste(im, (c * args.tile, r * args.tile))
    sheet.save(args.out, optimize=True)
    print(args.out)


if __name__ == "__main__":
    main()
