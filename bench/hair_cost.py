"""What fibres cost: one assembled sample rendered with its hair and eyebrows and without them
(the same .glb with the LINES meshes' nodes removed), same camera, HDRI, size and spp.

    python bench/hair_cost.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm --spec examples/dataset.toml \
        --index 0 --size 256 --spp 16

Prints, per variant, the renderer's own --stats: seconds, samples/s, rays/s, fibre segments,
geometry bytes on the device and the BVH build time.
"""

import argparse
import json
import os
import struct
import subprocess
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def strip_lines(src, dst):
    with open(src, "rb") as f:
        data = f.read()
    magic, version, _ = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67, f"{src} is not a .glb"
    jlen, jtype = struct.unpack_from("<II", data, 12)
    doc = json.loads(data[20:20 + jlen])
    rest = data[20 + jlen:]
    lines = {i for i, m in enumerate(doc.get("meshes", []))
             if any(p.get("mode", 4) in (1, 3) for p in m["primitives"])}
    keep = [i for i, n in enumerate(doc["nodes"]) if n.get("mesh") not in lines]
    for s in doc["scenes"]:
        s["nodes"] = [n for n in s["nodes"] if n in keep]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    out = struct.pack("<III", magic, version, 12 + 8 + len(text) + len(rest))
    out += struct.pack("<II", len(text), jtype) + text + rest
    with open(dst, "wb") as f:
        f.write(out)


def render(lf, glb, args, work):
    stats = os.path.join(work, "stats.json")
    subprocess.run([lf, "render", "--scene", glb, "--hdri",
                    os.path.join(REPO, "assets/hdri/rooitou_park_1k.hdr"), "--size",
                    f"{args.size}x{args.size}", "--spp", str(args.spp), "--passes", "none",
                    "--out", os.path.join(work, "out.exr"), "--stats", stats],
                   check=True, stdout=subprocess.DEVNULL)
    with open(stats) as f:
        return json.load(f)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--spec", default=os.path.join(REPO, "examples/dataset.toml"))
    ap.add_argument("--index", type=int, default=0)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as work:
        full = os.path.join(work, "sample.glb")
        bald = os.path.join(work, "bald.glb")
        subprocess.run([args.lightfarm, "spec", "glb", args.spec, "--index", str(args.index),
                        "--out", full], check=True)
        strip_lines(full, bald)
        print("| variant | seconds | M samples/s | M rays/s | fibre segments | geometry MiB | BVH build s |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for name, glb in (("with hair", full), ("without hair", bald)):
            s = render(args.lightfarm, glb, args, work)
            print(f"| {name} | {s['seconds']:.1f} | {s['samples_per_second'] / 1e6:.4f} | "
                  f"{s['rays_per_second'] / 1e6:.3f} | {s['curve_segments']} | "
                  f"{s['geometry_bytes'] / 2**20:.1f} | {s['bvh_build_seconds']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
