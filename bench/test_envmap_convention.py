#!/usr/bin/env python3
"""Empirical check that Mitsuba 3's `envmap` (identity to_world) follows lightfarm's convention:
Y up, u = atan2(x, -z)/2π, v = acos(y)/π; u = 0 -> -Z, u = 0.25 -> +X, u = 0.5 -> +Z, v = 0 -> +Y.

1. Direct lookups: for each axis direction, a 64x32 EXR (written with Mitsuba's Bitmap) with a hot
   2x2 texel block at that direction's (u, v); emitter.eval along all six axes must be hot only
   along that one.
2. Render: a white diffuse sphere seen from +Z (the benchmark's camera) under a map whose only
   light is the hot block at u = 0.25, v = 0.5: the image's right (+X) half must be the bright one.
   A small sphere placed at +X under a constant map checks the camera puts +X on the right.

Exit status 0 on success; prints one line per check. Usage:
    python3 bench/test_envmap_convention.py [--variant llvm_ad_rgb]
"""
import argparse
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import mitsuba_ref  # noqa: E402  (variant selection / libLLVM discovery)

W, H = 64, 32
HOT = 1000.0
# direction, (u, v) in lightfarm's convention
AXES = {
    "+X": ((1, 0, 0), (0.25, 0.5)),
    "-X": ((-1, 0, 0), (0.75, 0.5)),
    "+Z": ((0, 0, 1), (0.5, 0.5)),
    "-Z": ((0, 0, -1), (0.0, 0.5)),
    "+Y": ((0, 1, 0), (0.5, 0.0)),
    "-Y": ((0, -1, 0), (0.5, 1.0)),
}


def hot_map(np, u, v):
    img = np.zeros((H, W, 3), np.float32)
    if v <= 0.0:
        img[0, :, :] = HOT  # the pole row: every u is the same direction
    elif v >= 1.0:
        img[H - 1, :, :] = HOT
    else:
        # (u, v) sits on the corner shared by 4 texels: light all four (columns wrap).
        x, y = u * W, v * H
        for dx in (-1, 0):
            for dy in (-1, 0):
                img[int(round(y)) + dy, (int(round(x)) + dx) % W, :] = HOT
    return img


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--variant", default="llvm_ad_rgb")
    args = ap.parse_args()
    variant = mitsuba_ref.choose_variant(args.variant)
    import drjit as dr
    import mitsuba as mi
    import numpy as np
    mi.set_variant(variant)
    tmp = tempfile.mkdtemp(prefix="lf_envtest_")
    failures = 0

    def check(ok, msg):
        nonlocal failures
        print(("PASS " if ok else "FAIL ") + msg)
        failures += 0 if ok else 1

    # 1. Direct emitter lookups.
    for name, (_, (u, v)) in AXES.items():
        path = os.path.join(tmp, f"hot_{name[0] == '+' and 'p' or 'm'}{name[1]}.exr")
        mi.Bitmap(hot_map(np, u, v)).write(path)
        em = mi.load_dict({"type": "envmap", "filename": path})
        vals = {}
        for other, (d, _) in AXES.items():
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = -mi.Vector3f(d)  # envmap.eval looks up the direction -wi
            vals[other] = float(np.array(em.eval(si)).reshape(-1)[0])
        others = [vals[o] for o in AXES if o != name]
        check(vals[name] > 0.5 * HOT and max(others) < 1e-3 * HOT,
              f"envmap hot at (u={u}, v={v}) is seen along {name} only: "
              + ", ".join(f"{k}={vals[k]:.3g}" for k in AXES))

    def render(scene_dict, spp=64):
        img = mi.render(mi.load_dict(scene_dict), spp=spp)
        return np.array(img, dtype=np.float64)

    def camera(res=64):
        return {"type": "perspective", "fov_axis": "y", "fov": 30.0,
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0],
                                                           up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "rgba",
                         "rfilter": {"type": "box"}}}

    # 2a. Camera handedness: a small sphere at +X lands on the image's right.
    const = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}
    img = render({"type": "scene", "integrator": {"type": "path", "hide_emitters": True},
                  "sensor": camera(), "env": const,
                  "s": {"type": "sphere", "center": [0.5, 0, 0], "radius": 0.15}}, spp=4)
    alpha = img[..., 3]
    left, right = alpha[:, :32].sum(), alpha[:, 32:].sum()
    check(right > 0 and left == 0, f"sphere at +X appears on the image's right "
          f"(coverage left={left:.1f} right={right:.1f})")
    img = render({"type": "scene", "integrator": {"type": "path", "hide_emitters": True},
                  "sensor": camera(), "env": const,
                  "s": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.15}}, spp=4)
    alpha = img[..., 3]
    top, bottom = alpha[:32].sum(), alpha[32:].sum()
    check(top > 0 and bottom == 0, f"sphere at +Y appears at the image's top "
          f"(coverage top={top:.1f} bottom={bottom:.1f})")

    # 2b. White diffuse sphere lit by the hot texel at u = 0.25 (+X): right half bright.
    path = os.path.join(tmp, "hot_u025.exr")
    mi.Bitmap(hot_map(np, 0.25, 0.5)).write(path)
    img = render({"type": "scene", "integrator": {"type": "path", "hide_emitters": True,
                                                  "max_depth": 8, "rr_depth": 5},
                  "sensor": camera(),
                  "env": {"type": "envmap", "filename": path},
                  "s": {"type": "sphere", "radius": 0.5,
                        "bsdf": {"type": "diffuse",
                                 "reflectance": {"type": "rgb", "value": 1.0}}}}, spp=64)
    lum = img[..., :3].mean(axis=2)
    left, right = lum[:, :32].mean(), lum[:, 32:].mean()
    check(right > 20 * max(left, 1e-9),
          f"white sphere under a hot texel at u=0.25 is bright on +X/right "
          f"(mean left={left:.4g} right={right:.4g})")

    print(f"variant {variant}: {failures} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
