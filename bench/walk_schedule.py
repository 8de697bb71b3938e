"""Megakernel against the walk dispatch (issue 12): the Lee Perry-Smith scan with the paper's skin
and its maps, rendered with `lightfarm render --walk megakernel` and `--walk dispatch`, taking
turns, and the ratio of their rates measured in the same run.

    python bench/walk_schedule.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm

Times are the renderer's own (`--stats` seconds: pipeline creation and file writing excluded).
The two schedules cast the same rays (crates/render/tests/walk_schedule.rs), so rays/s and
samples/s compare alike. Standard library only.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cycles_skin import REPO, make_skin_head  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--hdri", default="studio_small_03_1k.hdr")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--work", default=os.path.expanduser("~/.cache/lightfarm-bench/walk_schedule"))
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    scene = os.path.join(args.work, "head_skin.glb")
    make_skin_head(os.path.join(REPO, "assets/heads/LeePerrySmith_textured.glb"), scene, True, maps=True)
    rates = {"megakernel": [], "dispatch": []}
    rays = {}
    for run in range(args.runs):
        for walk in rates:
            stats = os.path.join(args.work, f"{walk}.json")
            subprocess.run([args.lightfarm, "render", "--scene", scene,
                            "--hdri", os.path.join(REPO, "assets/hdri", args.hdri),
                            "--camera", "0.08,0.02,0.55:0,0,0:30",
                            "--size", f"{args.size}x{args.size}", "--spp", str(args.spp),
                            "--seed", "1", "--passes", "diffuse,specular,sss,coat,sheen,shadow,id",
                            "--device", args.device, "--walk", walk,
                            "--out", os.path.join(args.work, f"{walk}.exr"), "--stats", stats],
                           check=True, stdout=subprocess.DEVNULL)
            s = json.load(open(stats))
            rates[walk].append(s["samples_per_second"] / 1e6)
            rays[walk] = s["rays"]
            print(f"run {run} {walk}: {s['seconds']:.2f} s, {s['samples_per_second'] / 1e6:.4f} M samples/s, "
                  f"{s['rays_per_second'] / 1e6:.3f} M rays/s ({s['device']})", flush=True)
    med = {k: statistics.median(v) for k, v in rates.items()}
    print(f"\n{args.size}², {args.spp} spp, every pass, {args.hdri}; rays cast: {rays}")
    print("| schedule | M samples/s (median of %d; min–max) |" % args.runs)
    print("|---|---|")
    for k, v in rates.items():
        print(f"| {k} | {med[k]:.4f} ({min(v):.4f}–{max(v):.4f}) |")
    print(f"dispatch / megakernel: {med['dispatch'] / med['megakernel']:.3f}x")


if __name__ == "__main__":
    main()
