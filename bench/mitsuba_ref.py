#!/usr/bin/env python3
"""Mitsuba 3 reference renders for lightfarm's benchmark.

Renders one scene with Mitsuba's `path` integrator and prints ONE JSON line on stdout:

  {"renderer": "mitsuba", "variant": ..., "scene": ..., "width": .., "height": .., "spp": ..,
   "seconds": .., "first_seconds": .., "samples_per_second": width*height*spp/seconds,
   "mean": [r, g, b], ...}

`seconds` times the second of two identical `mi.render` calls (the first JIT-compiles the kernels
on LLVM variants and is reported as `first_seconds`); both are forced to completion
(`dr.eval` + `dr.sync_thread`) inside the timed region. Scene loading, the env-map sampling
tables and the coverage pass are outside it.

Conventions matched to lightfarm:
  * Env map: Y up, u = atan2(x, -z)/2π, v = acos(y)/π (u = 0 looks towards -Z, u = 0.25 towards
    +X, v = 0 is +Y). Mitsuba 3's `envmap` uses exactly this mapping with an identity to_world;
    bench/test_envmap_convention.py checks it (direct emitter lookups along the axes and a render
    of a white sphere under a one-texel light), so ENV_TO_WORLD below is the identity.
  * Background: lightfarm records 0 where no surface is hit, so the emitter is hidden from camera
    rays by default (`--show-background` to see it). `mean` is over all pixels (background 0);
    `coverage` is the mean hit fraction and `mean_object` = mean / coverage.
  * Path length: --max-depth is lightfarm's (scattering events, default 8) and goes to Mitsuba as
    max_depth + 1; --rr-depth (default 5) means the same in both (roulette after that many
    scattering events). Roulette probabilities differ (Mitsuba min(max throughput, 0.95),
    lightfarm clamp(max throughput, 0.05, 1)): both unbiased, noise differs slightly.
  * Pixel filter: box (one sample = one uniformly jittered ray in its pixel).
  * Camera: pinhole, vertical fov; +X on the image's right when looking down -Z with +Y up.

Scenes:
  sphere  diffuse sphere (reflectance 0.8, Mitsuba `diffuse`), radius 0.5 at the origin, under
          rooitou_park_1k.hdr; camera at (0,0,3) looking at the origin, vertical fov 30°.
  head    LeePerrySmith_textured.glb converted to PLY (bench/glb_to_ply.py, cached), base-colour
          texture from the glb; `principled` (roughness/metallic from the glTF material) or
          `diffuse` (--head-bsdf); under studio_small_03_1k.hdr. Camera: lightfarm's default
          framing (Camera::frame_bounds): from +Z towards the bbox centre at
          distance = (bbox diagonal / 2) / sin(half the narrower fov), vertical fov 30°.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# The repository's built-in asset pack (the same files lightfarm renders).
ASSETS = os.environ.get("LIGHTFARM_ASSETS", os.path.join(HERE, "..", "assets"))
BENCH_DIR = os.environ.get("LIGHTFARM_BENCH_DIR", os.path.expanduser("~/.cache/lightfarm-bench"))

SCENE_DEFAULTS = {
    "sphere": {"env": "hdri/rooitou_park_1k.hdr"},
    "head": {"env": "hdri/studio_small_03_1k.hdr",
             "mesh": "heads/LeePerrySmith_textured.glb"},
}
FOV_DEG = 30.0
# Mitsuba's envmap already uses lightfarm's lat-long convention (see module docstring), so no
# rotation is needed. Kept as a named constant so a future convention change has one place to go.
ENV_TO_WORLD = None  # identity


def warn(msg):
    print(f"mitsuba_ref: warning: {msg}", file=sys.stderr)


def find_libllvm19():
    root = os.path.join(BENCH_DIR, "llvm19")
    for dirpath, _, files in os.walk(root):
        for f in sorted(files):
            if f.startswith("libLLVM.so.19"):
                return os.path.join(dirpath, f)
    return None


def llvm_variant_works(variant):
    """Probe in a subprocess: a Dr.Jit that picks up an old libLLVM can crash the process."""
    code = ("import mitsuba as mi, drjit as dr; mi.set_variant(%r); "
            "x = dr.sum(dr.arange(mi.Float, 8) * 2); dr.eval(x); print(x)" % variant)
    try:
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return False, "probe timed out"
    if r.returncode != 0:
        return False, (r.stderr.strip().splitlines() or ["exit %d" % r.returncode])[-1]
    return True, ""


def choose_variant(requested):
    if requested.startswith("llvm") and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        lib = find_libllvm19()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
    if requested.startswith(("llvm", "cuda")):
        ok, why = llvm_variant_works(requested)
        if not ok:
            warn(f"variant {requested} unavailable ({why}); falling back to scalar_rgb "
                 "(run bench/setup_mitsuba.sh and set DRJIT_LIBLLVM_PATH to a libLLVM >= 19)")
            return "scalar_rgb"
    return requested


def asset(rel):
    return rel if os.path.isabs(rel) else os.path.join(ASSETS, rel)


def head_mesh(glb_path, cache_dir):
    """Convert (once) the glb to PLY + texture; returns glb_to_ply's info dict."""
    sys.path.insert(0, HERE)
    import glb_to_ply
    os.makedirs(cache_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(glb_path))[0]
    ply = os.path.join(cache_dir, stem + ".ply")
    meta = os.path.join(cache_dir, stem + ".json")
    if (os.path.exists(ply) and os.path.exists(meta)
            and os.path.getmtime(ply) >= os.path.getmtime(glb_path)
            and os.path.getmtime(ply) >= os.path.getmtime(glb_to_ply.__file__)):
        with open(meta) as f:
            return json.load(f)
    return glb_to_ply.convert(glb_path, ply)


def frame_bounds(bmin, bmax, aspect):
    """lightfarm's Camera::frame_bounds: returns (origin, target)."""
    centre = [(a + b) * 0.5 for a, b in zip(bmin, bmax)]
    radius = max(math.dist(bmin, bmax) * 0.5, 1e-3)
    half_v = math.radians(FOV_DEG * 0.5)
    half_h = math.atan(math.tan(half_v) * aspect)
    distance = radius / math.sin(min(half_v, half_h))
    return [centre[0], centre[1], centre[2] + distance], centre


def build_scene(mi, args):
    T = mi.ScalarTransform4f
    aspect = args.width / args.height
    if args.scene == "sphere":
        origin, target = [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]
        diffuse = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.8}}
        if args.sphere_mesh:
            # The same triangle mesh lightfarm renders (bench/compare.sh writes it), so both
            # renderers trace the same geometry rather than an analytic sphere against a BVH.
            info = head_mesh(args.sphere_mesh, args.cache_dir)
            shape = {"type": "ply", "filename": info["ply"], "face_normals": False, "bsdf": diffuse}
            extra = {"mesh_triangles": info["triangles"]}
        else:
            shape = {"type": "sphere", "center": [0, 0, 0], "radius": 0.5, "bsdf": diffuse}
            extra = {"analytic_sphere": True}
    else:
        info = head_mesh(asset(args.mesh or SCENE_DEFAULTS["head"]["mesh"]), args.cache_dir)
        origin, target = frame_bounds(info["bbox_min"], info["bbox_max"], aspect)
        bcf = info["base_color_factor"][:3]
        tex = info.get("base_color_texture")
        if tex:
            base = {"type": "bitmap", "filename": tex}
            if any(abs(c - 1.0) > 1e-6 for c in bcf):
                warn("base colour factor %s is ignored (texture used alone)" % bcf)
        else:
            base = {"type": "rgb", "value": bcf}
        if args.head_bsdf == "principled":
            bsdf = {"type": "principled", "base_color": base,
                    "roughness": float(info["roughness"]), "metallic": float(info["metallic"])}
        else:
            bsdf = {"type": "diffuse", "reflectance": base}
        # glTF materials are single-sided by default but the scan is closed enough; use twosided
        # so back faces don't render black in either renderer's convention.
        shape = {"type": "ply", "filename": info["ply"], "face_normals": False,
                 "bsdf": {"type": "twosided", "material": bsdf}}
        extra = {"mesh_vertices": info["vertices"], "mesh_triangles": info["triangles"],
                 "texture": bool(tex), "bsdf": args.head_bsdf}
    if args.env == "white":  # white furnace: an albedo-a convex object gives exactly a
        env = {"type": "constant", "radiance": {"type": "rgb", "value": args.env_scale}}
    else:
        env = {"type": "envmap", "filename": asset(args.env or SCENE_DEFAULTS[args.scene]["env"]),
               "scale": args.env_scale}
        if ENV_TO_WORLD is not None:
            env["to_world"] = ENV_TO_WORLD
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": mitsuba_max_depth(args.max_depth),
                       "rr_depth": args.rr_depth,
                       "hide_emitters": not args.show_background},
        "sensor": {
            "type": "perspective", "fov_axis": "y", "fov": FOV_DEG,
            "to_world": T().look_at(origin=origin, target=target, up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": args.spp},
            "film": {"type": "hdrfilm", "width": args.width, "height": args.height,
                     "pixel_format": "rgba", "rfilter": {"type": "box"}},
        },
        "subject": shape,
        "env": env,
    }
    extra["camera_origin"] = origin
    extra["camera_target"] = target
    return scene, extra


def mitsuba_max_depth(lightfarm_max_depth):
    """lightfarm counts scattering events (1 = direct lighting); Mitsuba counts path vertices
    after the camera (2 = direct lighting). -1 (unbounded) passes through."""
    return -1 if lightfarm_max_depth < 0 else lightfarm_max_depth + 1


def timed_render(mi, dr, scene, spp, seed):
    t0 = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return img, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", choices=sorted(SCENE_DEFAULTS), default="sphere")
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--max-depth", type=int, default=8,
                    help="lightfarm's max_depth: most scattering events on a path (default 8); "
                         "passed to Mitsuba as max_depth = this + 1 (Mitsuba counts the camera "
                         "vertex: its max_depth 2 is direct lighting only)")
    ap.add_argument("--rr-depth", type=int, default=5,
                    help="Russian roulette after this many scattering events (same meaning in "
                         "lightfarm and Mitsuba: passed through unchanged)")
    ap.add_argument("--variant", default="llvm_ad_rgb",
                    help="Mitsuba variant (default llvm_ad_rgb; falls back to scalar_rgb)")
    ap.add_argument("--env", help="override the scene's env map (path, or relative to assets/; "
                                  "'white' = constant radiance --env-scale, a furnace test)")
    ap.add_argument("--env-scale", type=float, default=1.0)
    ap.add_argument("--sphere-mesh", help="sphere scene: render this .glb (lightfarm's icosphere) "
                    "instead of Mitsuba's analytic sphere")
    ap.add_argument("--mesh", help="head scene: another .glb (path or relative to assets/)")
    ap.add_argument("--head-bsdf", choices=["principled", "diffuse"], default="principled")
    ap.add_argument("--show-background", action="store_true",
                    help="let camera rays see the env map (lightfarm records 0 there)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=0, help="Dr.Jit worker threads (0 = default)")
    ap.add_argument("--no-warmup", action="store_true",
                    help="render once and report it as both first_seconds and seconds")
    ap.add_argument("--out", help="write the timed image here (.exr)")
    ap.add_argument("--cache-dir", default=os.path.join(BENCH_DIR, "cache"))
    args = ap.parse_args(argv)

    variant = choose_variant(args.variant)
    import drjit as dr
    import mitsuba as mi
    import numpy as np
    mi.set_variant(variant)
    if args.threads > 0:
        dr.set_thread_count(args.threads)

    scene_dict, extra = build_scene(mi, args)
    t_load = time.perf_counter()
    scene = mi.load_dict(scene_dict)
    load_seconds = time.perf_counter() - t_load

    img, first = timed_render(mi, dr, scene, args.spp, args.seed)
    if args.no_warmup:
        seconds = first
    else:
        img, seconds = timed_render(mi, dr, scene, args.spp, args.seed)

    a = np.array(img, dtype=np.float64)  # H x W x 4 (rgba)
    rgb, alpha = a[..., :3], a[..., 3]
    mean = rgb.reshape(-1, 3).mean(axis=0)
    coverage = float(alpha.mean())
    if args.out:
        mi.Bitmap(np.ascontiguousarray(a, dtype=np.float32),
                  pixel_format=mi.Bitmap.PixelFormat.RGBA).write(args.out)

    samples = args.width * args.height * args.spp
    out = {
        "renderer": "mitsuba",
        "mitsuba_version": mi.__version__,
        "variant": variant,
        "scene": args.scene,
        "width": args.width,
        "height": args.height,
        "spp": args.spp,
        "max_depth": args.max_depth,
        "rr_depth": args.rr_depth,
        "mitsuba_max_depth": mitsuba_max_depth(args.max_depth),
        "seconds": round(seconds, 4),
        "first_seconds": round(first, 4),
        "load_seconds": round(load_seconds, 4),
        "samples_per_second": samples / seconds,
        "mean": [round(float(c), 6) for c in mean],
        "coverage": round(coverage, 6),
        "mean_object": [round(float(c) / coverage, 6) for c in mean] if coverage > 0 else None,
        "background": "env" if args.show_background else "black",
        "threads": dr.thread_count() if hasattr(dr, "thread_count") else None,
        "cpus": os.cpu_count(),
    }
    if variant.startswith("llvm"):
        out["libllvm"] = os.environ.get("DRJIT_LIBLLVM_PATH")
    out.update(extra)
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
