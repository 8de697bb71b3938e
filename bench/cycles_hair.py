"""Cross-check of lightfarm's hair fibres against Blender Cycles on the same strand patch.

A patch of wavy fibres (by default 1200 strands of 32 points in 4 sheets that never touch,
radius tapering 55 → 40 µm root to tip, over 4 cm × 4.7 cm) is written once as a .glb in
lightfarm's fibre input format: a mesh primitive of mode LINES with POSITION and `_RADIUS` per
vertex, the first point of each strand its root, and `extras.lightfarm = {model: hair, melanin,
melanin_redness, longitudinal_roughness, azimuthal_roughness, cuticle_tilt (degrees),
specular_IOR}` on its material. lightfarm renders that file; the Cycles scene is built from the
SAME file, parsed here (JSON and BIN chunks, no glTF importer): a Curves object of POLY curves
with a `radius` attribute per point, rendered as Cycles' thick linear curves (round cones, as
lightfarm's), material Principled Hair BSDF in Chiang mode with melanin parametrization
(melanin, melanin redness, tint white, roughness = βm, radial roughness = βn, coat 0, IOR,
offset = cuticle tilt in radians, random colour and roughness 0). Both renderers see the same
HDRI from the same camera; neither records the background (lightfarm's radiance is 0 where no
fibre is hit, Cycles renders a transparent film, premultiplied), so what is compared is
premultiplied radiance and coverage (alpha).

The patch is by default a strip of a cylinder of radius 3 cm about the X axis (from 60° above
+Z at the roots, the top of the image, to 30° below at the tips), bulging towards the camera
(+Z), so that, as on a head, a highlight band crosses it at the height where the fibres' tangent
mirrors the light (`--shape flat` lays it in the XY plane). The cuticle tilt moves that band
along the fibres; the row-band table and the highlight row show where each renderer puts it.

Printed (markdown), per melanin setting: both renderers' coverage and mean premultiplied RGB
over the patch (pixels either covers), the ratio, the per-block relative differences (8 × 8
tiles that both cover at least half), the seed-to-seed p90 block difference of each renderer
alone (the noise level: with images averaged over two seeds, a cross p90 of about 1/√2 of it
is noise), and the highlight row (the centre of the brightest rows); then a row-band profile
(lightfarm / Cycles luminance, top to bottom). A JSON dump of everything goes to stderr; PNG
previews (lightfarm | Cycles | 4×|diff|) go next to the EXRs.

Diagnostics: `--hdri white` (a furnace of radiance 1) and `--hdri spot:X,Y,Z` (one 2° light
towards that lightfarm direction) instead of an HDRI; `--max-depth 1` for direct light only;
`--fov 0.5` for a close-up where each fibre is ~20 pixels wide (the near field: which side of
a fibre lights up); `--strands 100 --layers 1` for a sparse sheet (fibres 0.4 mm apart);
`--placement random` for interpenetrating fibres; `--cycles-offset-sign -1` to give Cycles
the negated cuticle tilt.

Run with a Python 3.11 that has `bpy==5.0.1` and `OpenEXR` (bench/cycles_hair.sh sets it up):
    python bench/cycles_hair.py --lightfarm $CARGO_TARGET_DIR/debug/lightfarm --size 128 --spp 128

Conventions (as bench/cycles_skin.py): lightfarm is +Y up, metres; Blender +Z up. Points and
the camera map (x, y, z) -> (x, −z, y); the world texture is rotated 90° about Z so that both
renderers see the HDRI the same way (lightfarm u = atan2(x, −z)/2π). Path length: lightfarm's
--max-depth D counts scattering events (camera hit = 1); Cycles' max_bounces counts bounces after
the first hit (0 = direct light only), so Cycles gets D − 1. Cycles' glossy filter is off.
"""

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import time
import zlib

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# name: (melanin, melanin redness); all: βm = βn = 0.3, IOR 1.55, cuticle tilt --tilt (2°), or
# the degrees after an @ in --settings (e.g. black@-8,black@0,black@8 is the tilt test).
SETTINGS = {
    "black": (0.95, 0.25),
    "brown": (0.5, 0.25),
    "blond": (0.15, 0.25),
    "red": (0.5, 0.9),
}
DEFAULT_SETTINGS = ["black", "brown", "blond", "red"]


# ---------------------------------------------------------------------------------------------
# The patch and its .glb


R_ROOT, R_TIP = 55e-6, 40e-6  # fibre radius, tapering linearly root to tip


def make_patch(strands, points, shape, arc=(-30.0, 60.0), placement="layered", layers=4, seed=1):
    """List of (positions (n, 3), radii (n,)) in lightfarm coordinates, metres; root first.

    `layered` (default): `layers` sheets 0.13 mm apart in depth, each with strands / layers
    fibres at an even spacing in x (jittered by ±5 µm, the sheets offset against each other),
    all waving alike (a 0.3 mm sine across, 12 mm long, its phase drifting slowly with x), so
    that no two fibres touch (checked). `random`: every fibre at a uniform random x and depth
    (0 to 0.8 mm) with its own wave, so fibres interpenetrate (a 30-40% volume fraction); that
    is a stress test of where secondary rays start, not a comparison of the fibre model.
    """
    rng = np.random.default_rng(seed)
    half = 0.02  # the patch spans x in [-2, 2] cm
    rc = 0.03  # cylinder radius (arc shape), its angles from +Z towards +Y in `arc` (degrees)
    th_lo, th_hi = math.radians(arc[0]), math.radians(arc[1])
    s = np.linspace(0.0, 1.0, points)
    radius = (R_ROOT + (R_TIP - R_ROOT) * s).astype(np.float32)

    def strand(x0, depth, wave_a, wave_l, phase, wobble=0.0, phase2=0.0, stretch=1.0):
        # The length along the strand runs root (top) to tip (bottom).
        if shape == "arc":
            th = th_hi + (th_lo - th_hi) * s * stretch
            length = rc * th
            r = rc - depth + wobble * np.sin(2.0 * math.pi * length / (0.7 * wave_l) + phase2)
            y, z = r * np.sin(th), r * np.cos(th) - rc
        else:
            y = 0.02 * (1.0 - 2.0 * s) * stretch
            length = y
            z = -depth + wobble * np.sin(2.0 * math.pi * length / (0.7 * wave_l) + phase2)
        x = x0 + wave_a * np.sin(2.0 * math.pi * length / wave_l + phase)
        return np.stack([x, y, z], axis=1).astype(np.float32)

    out = []
    if placement == "random":
        for _ in range(strands):
            out.append((strand(rng.uniform(-half, half), rng.uniform(0.0, 0.0008), rng.uniform(0.0002, 0.0006),
                               rng.uniform(0.008, 0.016), rng.uniform(0.0, 2.0 * math.pi),
                               rng.uniform(0.0, 0.0002), rng.uniform(0.0, 2.0 * math.pi),
                               1.0 + 0.05 * rng.uniform(-1.0, 1.0)), radius))
        return out
    per_layer = strands // layers
    spacing = 2.0 * half / per_layer
    layer_dz = 0.13e-3
    assert layer_dz > 2.0 * R_ROOT, "sheets must not touch"
    clearance = math.inf
    for k in range(layers):
        x0 = -half + spacing * (np.arange(per_layer) + (0.5 + 0.37 * k) % 1.0)
        x0 = x0 + rng.uniform(-5e-6, 5e-6, per_layer)
        layer = [strand(x, k * layer_dz, 0.0003, 0.012, 2.0 * math.pi * x / 0.04 + 1.3 * k) for x in x0]
        xs = np.stack([p[:, 0] for p in layer])  # (strands, points): same y, z at the same s
        clearance = min(clearance, float((np.diff(xs, axis=0) - 2.0 * radius[None, :]).min()))
        out += [(p, radius) for p in layer]
    assert clearance > 0.0, f"fibres touch (clearance {clearance * 1e6:.1f} µm): fewer strands"
    print(f"patch: {len(out)} fibres in {layers} sheets, {spacing * 1e3:.3f} mm apart, "
          f"closest {clearance * 1e6:.1f} µm between fibre walls", file=sys.stderr)
    return out


def hair_extras(melanin, redness, bm, bn, tilt_deg, ior):
    return {"lightfarm": {
        "model": "hair",
        "melanin": melanin,
        "melanin_redness": redness,
        "longitudinal_roughness": bm,
        "azimuthal_roughness": bn,
        "cuticle_tilt": tilt_deg,
        "specular_IOR": ior,
    }}


def write_fibre_glb(path, patch, extras):
    """lightfarm's fibre format: one primitive of mode LINES (1), u32 indices, POSITION and
    `_RADIUS` per vertex; each strand is a chain of index pairs sharing endpoints."""
    pos = np.concatenate([p for p, _ in patch]).astype("<f4")
    rad = np.concatenate([r for _, r in patch]).astype("<f4")
    idx = []
    base = 0
    for p, _ in patch:
        n = len(p)
        seg = np.arange(base, base + n - 1, dtype=np.uint32)
        idx.append(np.stack([seg, seg + 1], axis=1).ravel())
        base += n
    idx = np.concatenate(idx).astype("<u4")
    blobs = [pos.tobytes(), rad.tobytes(), idx.tobytes()]
    views, off = [], 0
    for b in blobs:
        views.append({"buffer": 0, "byteOffset": off, "byteLength": len(b)})
        off += len(b)
        off += (4 - off % 4) % 4
    blob = b"".join(b + b"\0" * ((4 - len(b) % 4) % 4) for b in blobs)
    doc = {
        "asset": {"version": "2.0", "generator": "lightfarm bench/cycles_hair.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "hair_patch"}],
        "meshes": [{"name": "hair_patch", "primitives": [{
            "attributes": {"POSITION": 0, "_RADIUS": 1}, "indices": 2, "mode": 1, "material": 0}]}],
        "materials": [{"name": "hair", "extras": extras}],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
             "min": pos.min(axis=0).tolist(), "max": pos.max(axis=0).tolist()},
            {"bufferView": 1, "componentType": 5126, "count": len(rad), "type": "SCALAR"},
            {"bufferView": 2, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
        ],
    }
    j = json.dumps(doc).encode()
    j += b" " * ((4 - len(j) % 4) % 4)
    total = 12 + 8 + len(j) + 8 + len(blob)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, total))
        f.write(struct.pack("<II", len(j), 0x4E4F534A))
        f.write(j)
        f.write(struct.pack("<II", len(blob), 0x004E4942))
        f.write(blob)


# ---------------------------------------------------------------------------------------------
# Reading the .glb back (for Cycles), without Blender's importer


def read_glb(path):
    data = open(path, "rb").read()
    magic, version, _ = struct.unpack("<III", data[:12])
    assert magic == 0x46546C67 and version == 2, f"{path}: not a glTF 2 binary"
    off, doc, bin_chunk = 12, None, b""
    while off < len(data):
        n, kind = struct.unpack("<II", data[off:off + 8])
        chunk = data[off + 8:off + 8 + n]
        if kind == 0x4E4F534A:
            doc = json.loads(chunk)
        elif kind == 0x004E4942:
            bin_chunk = chunk
        off += 8 + n
    return doc, bin_chunk


COMPONENTS = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def accessor(doc, bin_chunk, i):
    a = doc["accessors"][i]
    v = doc["bufferViews"][a["bufferView"]]
    assert v.get("buffer", 0) == 0 and "uri" not in doc["buffers"][0], "only the GLB's own buffer"
    dt = np.dtype(COMPONENTS[a["componentType"]])
    k = WIDTH[a["type"]]
    start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = v.get("byteStride", dt.itemsize * k)
    raw = np.frombuffer(bin_chunk, dtype=np.uint8, count=stride * (a["count"] - 1) + dt.itemsize * k,
                        offset=start)
    rows = np.lib.stride_tricks.as_strided(raw, shape=(a["count"], dt.itemsize * k), strides=(stride, 1))
    out = np.ascontiguousarray(rows).view(dt).reshape(a["count"], k)
    return out[:, 0] if k == 1 else out


def node_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    t = np.array(node.get("translation", [0, 0, 0]), dtype=np.float64)
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    s = np.array(node.get("scale", [1, 1, 1]), dtype=np.float64)
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def fibres_of_glb(path):
    """(strands [(positions (n, 3), radii (n,))] in lightfarm world space, material extras)."""
    doc, bin_chunk = read_glb(path)
    strands, extras = [], None
    stack = [(n, np.eye(4)) for n in doc["scenes"][doc.get("scene", 0)]["nodes"]]
    while stack:
        ni, parent = stack.pop()
        node = doc["nodes"][ni]
        m = parent @ node_matrix(node)
        stack += [(c, m) for c in node.get("children", [])]
        if "mesh" not in node:
            continue
        scale = abs(np.linalg.det(m[:3, :3])) ** (1.0 / 3.0)
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            mode = prim.get("mode", 4)
            if mode not in (1, 3) or "_RADIUS" not in prim["attributes"]:
                continue
            pos = accessor(doc, bin_chunk, prim["attributes"]["POSITION"]).astype(np.float64)
            pos = pos @ m[:3, :3].T + m[:3, 3]
            rad = accessor(doc, bin_chunk, prim["attributes"]["_RADIUS"]).astype(np.float64) * scale
            if "indices" in prim:
                idx = accessor(doc, bin_chunk, prim["indices"]).astype(np.int64)
            else:
                idx = np.arange(len(pos))
            chains = []
            if mode == 3:
                chains.append(list(idx))
            else:
                for a, b in idx.reshape(-1, 2):
                    if chains and chains[-1][-1] == a:
                        chains[-1].append(b)
                    else:
                        chains.append([a, b])
            for c in chains:
                strands.append((pos[c], rad[c]))
            if "material" in prim:
                extras = doc["materials"][prim["material"]].get("extras", {}).get("lightfarm")
    return strands, extras


# ---------------------------------------------------------------------------------------------
# Renders


def render_lightfarm(lf, scene, hdri, camera, size, spp, depth, seed, out):
    t0 = time.time()
    subprocess.run([lf, "render", "--scene", scene, "--hdri", hdri, "--camera", camera,
                    "--size", f"{size}x{size}", "--spp", str(spp), "--max-depth", str(depth),
                    "--seed", str(seed), "--passes", "none", "--out", out, "--stats", out + ".json"],
                   check=True)
    return time.time() - t0


def render_cycles(scene_path, hdri, eye, target, fov_deg, size, spp, depth, seed, out, threads,
                  offset_sign=1.0):
    import bpy
    import mathutils
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    strands, lf = fibres_of_glb(scene_path)
    assert strands and lf and lf.get("model") == "hair", f"{scene_path}: no hair fibres"
    # Curves: POLY (linear) strands, root first, lightfarm (x, y, z) -> Blender (x, -z, y).
    curves = bpy.data.hair_curves.new("hair_patch")
    curves.add_curves([len(p) for p, _ in strands])
    curves.set_types(type="POLY")
    pos = np.concatenate([p for p, _ in strands])
    pos_b = np.stack([pos[:, 0], -pos[:, 2], pos[:, 1]], axis=1).astype(np.float32)
    curves.attributes["position"].data.foreach_set("vector", pos_b.ravel())
    if "radius" not in curves.attributes:
        curves.attributes.new("radius", "FLOAT", "POINT")
    curves.attributes["radius"].data.foreach_set(
        "value", np.concatenate([r for _, r in strands]).astype(np.float32))
    obj = bpy.data.objects.new("hair_patch", curves)
    sc.collection.objects.link(obj)
    # Principled Hair BSDF, Chiang, melanin parametrization, from the same extras.
    mat = bpy.data.materials.new("hair")
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    hair = nt.nodes.new("ShaderNodeBsdfHairPrincipled")
    hair.model = "CHIANG"
    hair.parametrization = "MELANIN"
    inp = hair.inputs
    inp["Melanin"].default_value = lf["melanin"]
    inp["Melanin Redness"].default_value = lf["melanin_redness"]
    inp["Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
    inp["Roughness"].default_value = lf["longitudinal_roughness"]
    inp["Radial Roughness"].default_value = lf["azimuthal_roughness"]
    inp["Coat"].default_value = 0.0
    inp["IOR"].default_value = lf.get("specular_IOR", 1.55)
    # Radians. `offset_sign` -1 is a diagnostic (--cycles-offset-sign): Cycles negates the
    # offset in bsdf_hair_chiang_setup (`bsdf->alpha = -bsdf->alpha`), pbrt-v3 does not.
    inp["Offset"].default_value = offset_sign * math.radians(lf["cuticle_tilt"])
    inp["Random Color"].default_value = 0.0
    inp["Random Roughness"].default_value = 0.0
    outp = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(hair.outputs["BSDF"], outp.inputs["Surface"])
    curves.materials.append(mat)
    # Camera: lightfarm (x, y, z) -> Blender (x, -z, y).
    to_b = lambda v: mathutils.Vector((v[0], -v[2], v[1]))
    cam_data = bpy.data.cameras.new("cam")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(fov_deg)
    cam_data.clip_start = 0.001
    cam = bpy.data.objects.new("cam", cam_data)
    sc.collection.objects.link(cam)
    e, t = to_b(eye), to_b(target)
    cam.location = e
    cam.rotation_euler = (t - e).to_track_quat("-Z", "Z").to_euler()
    sc.camera = cam
    # World: the HDRI, rotated 90° about Z to match lightfarm's lat-long convention.
    world = bpy.data.worlds.new("world")
    sc.world = world
    world.use_nodes = True
    wn = world.node_tree
    bg = wn.nodes["Background"]
    env = wn.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(hdri)
    mapping = wn.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(90.0))
    coord = wn.nodes.new("ShaderNodeTexCoord")
    wn.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    wn.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    wn.links.new(env.outputs["Color"], bg.inputs["Color"])
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles_curves.shape = "THICK_LINEAR"  # round cones, lightfarm's fibre geometry
    sc.cycles.samples = spp
    sc.cycles.seed = seed
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    bounces = max(depth - 1, 0)
    sc.cycles.max_bounces = bounces
    sc.cycles.diffuse_bounces = bounces
    sc.cycles.glossy_bounces = bounces
    sc.cycles.transmission_bounces = bounces
    sc.cycles.transparent_max_bounces = bounces
    sc.cycles.blur_glossy = 0.0
    sc.cycles.caustics_reflective = True
    sc.cycles.caustics_refractive = True
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.filter_width = 1.0
    sc.cycles.sample_clamp_indirect = 0.0
    sc.cycles.sample_clamp_direct = 0.0
    if threads:
        sc.render.threads_mode = "FIXED"
        sc.render.threads = threads
    sc.render.film_transparent = True
    sc.render.resolution_x = size
    sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.image_settings.color_mode = "RGBA"
    sc.view_settings.view_transform = "Standard"
    sc.render.filepath = out
    t0 = time.time()
    # Blender's progress lines go to stderr, so that stdout is the table alone.
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
    return time.time() - t0


# ---------------------------------------------------------------------------------------------
# Comparison


def read_exr_rgb(path, layer):
    """(rgb, coverage) of a lightfarm layer (`lit0` with `mask.A`) or of Cycles' RGBA."""
    import OpenEXR
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if layer:
            rgb = ch[layer].pixels[..., :3]
            alpha = ch["mask.A"].pixels
        else:
            px = ch["RGBA"].pixels
            rgb, alpha = px[..., :3], px[..., 3]
    return np.asarray(rgb, dtype=np.float64), np.asarray(alpha, dtype=np.float64)


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def block_diffs(a, am, b, bm, blocks):
    """Relative differences of block means of a against b over tiles both cover ≥ half."""
    h, w = am.shape
    out = []
    for by in range(blocks):
        for bx in range(blocks):
            sl = (slice(by * h // blocks, (by + 1) * h // blocks), slice(bx * w // blocks, (bx + 1) * w // blocks))
            if am[sl].mean() < 0.5 or bm[sl].mean() < 0.5:
                continue
            la = a[sl].reshape(-1, 3).mean(axis=0)
            lb = b[sl].reshape(-1, 3).mean(axis=0)
            out.append((la - lb) / np.maximum(lb, 1e-6))
    return np.array(out).reshape(-1, 3)


def highlight_row(img):
    """Where the highlight band is: the luminance-weighted mean row of the contiguous run of
    rows around the brightest one (3-row-smoothed row means over the central half of the
    columns) that stay above half of its brightness."""
    h, w = img.shape[:2]
    prof = luminance(img[:, w // 4:3 * w // 4]).mean(axis=1)
    prof = np.convolve(prof, np.ones(3) / 3, mode="same")
    peak = int(np.argmax(prof))
    lo = hi = peak
    while lo > 0 and prof[lo - 1] > 0.5 * prof[peak]:
        lo -= 1
    while hi < h - 1 and prof[hi + 1] > 0.5 * prof[peak]:
        hi += 1
    rows = np.arange(lo, hi + 1)
    return float((rows * prof[lo:hi + 1]).sum() / prof[lo:hi + 1].sum())


def compare(name, lf, cy, blocks, bands, seconds):
    """`lf`, `cy`: lists of (rgb, coverage), one per seed."""
    a = np.mean([x for x, _ in lf], axis=0)
    am = np.mean([m for _, m in lf], axis=0)
    b = np.mean([x for x, _ in cy], axis=0)
    bm = np.mean([m for _, m in cy], axis=0)
    patch = (am > 0.02) | (bm > 0.02)
    ma, mb = a[patch].mean(axis=0), b[patch].mean(axis=0)
    d = block_diffs(a, am, b, bm, blocks)
    r = {
        "setting": name,
        "pixels": int(patch.sum()),
        "lightfarm_coverage": float(am[patch].mean()),
        "cycles_coverage": float(bm[patch].mean()),
        "lightfarm_mean": ma.tolist(),
        "cycles_mean": mb.tolist(),
        "ratio": (ma / np.maximum(mb, 1e-9)).tolist(),
        "blocks": len(d),
        "block_rel_diff_median": np.median(d, axis=0).tolist() if len(d) else [math.nan] * 3,
        "block_rel_diff_abs_p90": np.percentile(np.abs(d), 90, axis=0).tolist() if len(d) else [math.nan] * 3,
        "highlight_row": [highlight_row(a), highlight_row(b)],
        "seconds": seconds,
    }
    # Noise: seed 0 against seed 1 of each renderer alone.
    for key, runs in (("lightfarm", lf), ("cycles", cy)):
        if len(runs) >= 2:
            (x0, m0), (x1, m1) = runs[0], runs[1]
            dn = block_diffs(x0, m0, x1, m1, blocks)
            r[key + "_seed_p90"] = np.percentile(np.abs(dn), 90, axis=0).tolist() if len(dn) else [math.nan] * 3
            r[key + "_seed_mean_diff"] = (x0[patch].mean(axis=0) / np.maximum(x1[patch].mean(axis=0), 1e-9) - 1).tolist()
    h = a.shape[0]
    prof = []
    for k in range(bands):
        sl = slice(k * h // bands, (k + 1) * h // bands)
        la, lb = luminance(a[sl]).mean(), luminance(b[sl]).mean()
        prof.append([float(la), float(lb)])
    r["bands"] = prof
    return r, (a, b)


def write_png(path, img):
    """8-bit sRGB PNG of a linear RGB image (clamped)."""
    x = np.clip(img, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    x = (x * 255.0 + 0.5).astype(np.uint8)
    h, w = x.shape[:2]
    raw = b"".join(b"\0" + x[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lightfarm", help="the lightfarm binary (without it, or with --cycles-only, Cycles only)")
    ap.add_argument("--cycles-only", action="store_true", help="render and summarise Cycles alone")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--seeds", type=int, default=2, help="renders per renderer and setting (noise estimate)")
    ap.add_argument("--max-depth", type=int, default=16, help="lightfarm's; Cycles gets one bounce less")
    ap.add_argument("--strands", type=int, default=1200)
    ap.add_argument("--placement", choices=["layered", "random"], default="layered",
                    help="layered: sheets of fibres that never touch; random: interpenetrating fibres")
    ap.add_argument("--layers", type=int, default=4, help="sheets of the layered placement")
    ap.add_argument("--points", type=int, default=32)
    ap.add_argument("--shape", choices=["arc", "flat"], default="arc")
    ap.add_argument("--arc-from", type=float, default=-30.0,
                    help="the arc's tip end, degrees from +Z towards +Y about the cylinder's axis (X)")
    ap.add_argument("--arc-to", type=float, default=60.0, help="the arc's root end, degrees")
    ap.add_argument("--fov", type=float, default=18.0,
                    help="vertical field of view, degrees, from 15 cm (0.5: a close-up of a few fibres, "
                         "each ~20 pixels wide at 128², the fibre's near field)")
    ap.add_argument("--roughness", type=float, default=0.3, help="longitudinal βm")
    ap.add_argument("--radial-roughness", type=float, default=0.3, help="azimuthal βn")
    ap.add_argument("--tilt", type=float, default=2.0, help="cuticle tilt, degrees (unless a setting has its own)")
    ap.add_argument("--ior", type=float, default=1.55)
    ap.add_argument("--settings", default=",".join(DEFAULT_SETTINGS),
                    help=f"comma-separated, of: {', '.join(SETTINGS)}; NAME@DEG sets the cuticle tilt")
    ap.add_argument("--hdri", default=os.path.join(REPO, "assets/hdri/studio_small_03_1k.hdr"),
                    help='a lat-long .hdr or .exr; "white" for a uniform environment of radiance 1; '
                         '"spot:X,Y,Z" for one small light towards lightfarm direction (X, Y, Z)')
    ap.add_argument("--cycles-offset-sign", type=float, default=1.0, choices=[1.0, -1.0],
                    help="diagnostic: -1 gives Cycles the negated cuticle tilt (pbrt-v3's sign)")
    ap.add_argument("--threads", type=int, default=0, help="Cycles threads (0: all)")
    ap.add_argument("--out", default="/tmp/lightfarm-bench/cycles_hair")
    args = ap.parse_args()
    use_lf = bool(args.lightfarm) and not args.cycles_only
    os.makedirs(args.out, exist_ok=True)
    if args.hdri == "white":
        # A furnace: radiance 1 from every direction (a 64 × 32 EXR of ones).
        import OpenEXR
        args.hdri = os.path.join(args.out, "white.exr")
        px = np.ones((32, 64, 3), dtype=np.float32)
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     {"RGB": px}).write(args.hdri)
    elif args.hdri.startswith("spot:"):
        # One small light (a 2°-radius disc of radiance 1000) towards lightfarm direction x, y, z,
        # nothing else: where the highlights sit tells the conventions apart.
        import OpenEXR
        d = np.array([float(c) for c in args.hdri[5:].split(",")])
        d /= np.linalg.norm(d)
        h, w = 512, 1024
        v = (np.arange(h) + 0.5) / h
        u = (np.arange(w) + 0.5) / w
        th, ph = np.meshgrid(v * math.pi, u * 2.0 * math.pi, indexing="ij")
        # lightfarm: u = atan2(x, -z) / 2π, v = acos(y) / π (row 0 is +Y).
        dirs = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], axis=-1)
        on = dirs @ d > math.cos(math.radians(2.0))
        px = np.zeros((h, w, 3), dtype=np.float32)
        px[on] = 1000.0
        args.hdri = os.path.join(args.out, "spot.exr")
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     {"RGB": px}).write(args.hdri)
    patch = make_patch(args.strands, args.points, args.shape, (args.arc_from, args.arc_to), args.placement,
                       args.layers)
    # Looking along -Z at the middle of the patch's bounds, from 15 cm.
    pts = np.concatenate([p for p, _ in patch])
    mid = (pts.min(axis=0) + pts.max(axis=0)) / 2
    target = (0.0, round(float(mid[1]), 4), round(float(mid[2]), 4))
    eye, fov = (0.0, target[1], target[2] + 0.15), args.fov
    cam = f"{eye[0]},{eye[1]},{eye[2]}:{target[0]},{target[1]},{target[2]}:{fov}"
    results = []
    for name in args.settings.split(","):
        base, _, at = name.partition("@")
        m, red = SETTINGS[base]
        tilt = float(at) if at else args.tilt
        name = base + (f"_tilt{tilt:+g}" if at else "")
        glb = os.path.join(args.out, f"hair_{name}.glb")
        write_fibre_glb(glb, patch, hair_extras(m, red, args.roughness, args.radial_roughness, tilt, args.ior))
        lf_runs, cy_runs, t_lf, t_cy = [], [], 0.0, 0.0
        for seed in range(args.seeds):
            cy_exr = os.path.join(args.out, f"{name}_cycles_s{seed}.exr")
            t_cy += render_cycles(glb, args.hdri, eye, target, fov, args.size, args.spp, args.max_depth,
                                  seed, cy_exr, args.threads, args.cycles_offset_sign)
            cy_runs.append(cy_exr)
            if use_lf:
                lf_exr = os.path.join(args.out, f"{name}_lightfarm_s{seed}.exr")
                t_lf += render_lightfarm(args.lightfarm, glb, args.hdri, cam, args.size, args.spp,
                                         args.max_depth, seed, lf_exr)
                lf_runs.append(lf_exr)
        label = f"{name} (m {m}, r {red}, tilt {tilt:g}°)"
        if args.cycles_offset_sign < 0:
            label += ", Cycles offset negated"
        cy_img = [read_exr_rgb(x, None) for x in cy_runs]
        lf_img = [read_exr_rgb(x, "lit0") for x in lf_runs] or cy_img
        r, (a, b) = compare(label, lf_img, cy_img, 8, 8, (t_lf, t_cy))
        results.append(r)
        side = [a, b, 4.0 * np.abs(a - b)] if use_lf else [b]
        write_png(os.path.join(args.out, f"{name}.png"), np.concatenate(side, axis=1))
        print(f"{label}: lightfarm {t_lf:.1f} s, Cycles {t_cy:.1f} s", file=sys.stderr, flush=True)
    f = lambda v: " ".join(f"{x:.4f}" for x in v)
    p = lambda v: " ".join(f"{100 * x:+.1f}%" for x in v)
    q = lambda v: " ".join(f"{100 * x:.1f}%" for x in v)
    print(f"\n{len(patch)} strands × {args.points} points ({args.shape}, {args.placement}), {args.size}², {args.spp} spp × "
          f"{args.seeds} seeds, lightfarm max-depth {args.max_depth} (Cycles {args.max_depth - 1} bounces), "
          f"βm {args.roughness}, βn {args.radial_roughness}, IOR {args.ior}, {os.path.basename(args.hdri)}\n")
    if not use_lf:
        print("| setting | Cycles coverage | Cycles mean RGB | Cycles seed p90 block diff RGB | highlight row |")
        print("|---|---|---|---|---|")
        for r in results:
            print(f"| {r['setting']} | {r['cycles_coverage']:.3f} | {f(r['cycles_mean'])} | "
                  f"{q(r.get('cycles_seed_p90', [math.nan] * 3))} | {r['highlight_row'][1]:.1f} |")
    else:
        print("| setting | coverage lf / Cy | lightfarm mean RGB | Cycles mean RGB | ratio RGB | blocks | "
              "median block diff RGB | p90 \\|block diff\\| RGB | lightfarm seed p90 | Cycles seed p90 | "
              "highlight row lf / Cy |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in results:
            print(f"| {r['setting']} | {r['lightfarm_coverage']:.3f} / {r['cycles_coverage']:.3f} | "
                  f"{f(r['lightfarm_mean'])} | {f(r['cycles_mean'])} | {f(r['ratio'])} | {r['blocks']} | "
                  f"{p(r['block_rel_diff_median'])} | {q(r['block_rel_diff_abs_p90'])} | "
                  f"{q(r.get('lightfarm_seed_p90', [math.nan] * 3))} | {q(r.get('cycles_seed_p90', [math.nan] * 3))} | "
                  f"{r['highlight_row'][0]:.1f} / {r['highlight_row'][1]:.1f} |")
        print("\nRow bands, top (root) to bottom (tip): luminance lightfarm / Cycles (ratio)\n")
        nb = len(results[0]["bands"])
        print("| setting | " + " | ".join(f"band {k}" for k in range(nb)) + " |")
        print("|---|" + "---|" * nb)
        for r in results:
            cells = [f"{la:.3f} / {lb:.3f} ({la / lb if lb > 0 else math.nan:.2f})" for la, lb in r["bands"]]
            print(f"| {r['setting']} | " + " | ".join(cells) + " |")
    print(json.dumps(results), file=sys.stderr)


if __name__ == "__main__":
    main()
