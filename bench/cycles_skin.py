"""Cross-check of the skin material against Blender Cycles on the same scenes.

A skin sphere, and the Lee Perry-Smith head with the same skin, are rendered by lightfarm (the
`skin` model of extras.lightfarm, see README "Materials") and by Cycles (Principled BSDF, Random
Walk subsurface with the same radius, scale and IOR, the same specular, coat and sheen) under
the same HDRI, from the same camera. The script prints each image's mean over the subject and a
per-block comparison as a markdown table (BENCHMARKS.md, "Skin against Cycles").

Run with a Python 3.11 that has `bpy==5.0.1` and `OpenEXR` (bench/cycles_skin.sh sets it up):
    python bench/cycles_skin.py --lightfarm $CARGO_TARGET_DIR/release/lightfarm --size 128 --spp 256

Conventions: lightfarm is +Y up, metres; Blender +Z up. The glTF importer maps (x, y, z) to
(x, −z, y) for the mesh; the camera is placed in Blender coordinates by the same map, and the
world texture is rotated by 90° about Z so that both renderers see the HDRI the same way
(lightfarm u = atan2(x, −z)/2π; see bench/test_envmap_convention.py).
"""

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import time

METHOD = ["RANDOM_WALK"]
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SKIN = {
    # The paper's appendix (README "Materials", preset `skin`); the base colour is constant
    # so that both renderers see the same subsurface colour.
    "base_color": [0.80, 0.52, 0.42],
    "subsurface": 0.95,
    "subsurface_radius": [1.0, 0.35, 0.2],
    "subsurface_scale": 0.00225,
    "specular_color": 0.82,
    "specular_roughness": 0.4,
    "specular_IOR": 1.5,
    "coat": 0.1,
    "coat_roughness": 0.25,
    "coat_IOR": 1.5,
    "sheen": 0.1,
    "sheen_roughness": 0.3,
}


def icosphere(subdiv):
    t = (1.0 + 5 ** 0.5) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdiv):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = [(verts[a][k] + verts[b][k]) / 2 for k in range(3)]
                n = math.sqrt(sum(x * x for x in m))
                verts.append(tuple(x / n for x in m))
                cache[key] = len(verts) - 1
            return cache[key]

        nf = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = nf
    return verts, faces


def write_sphere_gltf(path, radius):
    verts, faces = icosphere(5)
    pos = b"".join(struct.pack("<3f", *(c * radius for c in v)) for v in verts)
    nrm = b"".join(struct.pack("<3f", *v) for v in verts)
    idx = b"".join(struct.pack("<3I", *f) for f in faces)
    blob = pos + nrm + idx
    lf = {"model": "skin"}
    lf.update({k: v for k, v in SKIN.items() if k != "base_color"})
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": 0}]}],
        "materials": [{
            "name": "skin",
            "pbrMetallicRoughness": {"baseColorFactor": SKIN["base_color"] + [1.0], "metallicFactor": 0.0},
            "extras": {"lightfarm": lf},
        }],
        "buffers": [{"byteLength": len(blob), "uri": os.path.basename(path) + ".bin"}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
            {"buffer": 0, "byteOffset": len(pos), "byteLength": len(nrm)},
            {"buffer": 0, "byteOffset": len(pos) + len(nrm), "byteLength": len(idx)},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(verts), "type": "VEC3",
             "min": [-radius] * 3, "max": [radius] * 3},
            {"bufferView": 1, "componentType": 5126, "count": len(verts), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5125, "count": 3 * len(faces), "type": "SCALAR"},
        ],
    }
    with open(path + ".bin", "wb") as f:
        f.write(blob)
    with open(path, "w") as f:
        json.dump(doc, f)


def read_exr_rgb(path, layer):
    """(rgb, coverage) of a lightfarm layer (`lit0` with `mask.A`) or of Cycles' RGBA."""
    import numpy as np
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


def render_lightfarm(lf, scene, hdri, camera, size, spp, out):
    t0 = time.time()
    subprocess.run([lf, "render", "--scene", scene, "--hdri", hdri, "--camera", camera,
                    "--size", f"{size}x{size}", "--spp", str(spp), "--max-depth", "8",
                    "--passes", "none", "--out", out, "--stats", out + ".json"], check=True)
    return time.time() - t0


def render_cycles(scene_path, hdri, eye, target, fov_deg, size, spp, out, skin_head):
    import bpy
    import mathutils
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=scene_path)
    sc = bpy.context.scene
    # The principled skin, on every imported material (the sphere has one; the head one).
    for mat in bpy.data.materials:
        mat.use_nodes = True
        nt = mat.node_tree
        bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")

        class Inputs:
            # Sockets a Blender version lacks are reported, not fatal.
            def __getitem__(self, name):
                if name in bsdf.inputs:
                    return bsdf.inputs[name]
                print(f"note: this Principled BSDF has no input {name!r}", file=sys.stderr)
                return type("Unused", (), {"default_value": None, "links": []})()
        inputs = Inputs()
        if not skin_head:
            for link in list(inputs["Base Color"].links):
                nt.links.remove(link)
            inputs["Base Color"].default_value = SKIN["base_color"] + [1.0]
        bsdf.subsurface_method = METHOD[0]
        inputs["Metallic"].default_value = 0.0
        inputs["Roughness"].default_value = SKIN["specular_roughness"]
        inputs["IOR"].default_value = SKIN["specular_IOR"]
        inputs["Specular IOR Level"].default_value = 0.5
        inputs["Specular Tint"].default_value = [SKIN["specular_color"]] * 3 + [1.0]
        inputs["Subsurface Weight"].default_value = SKIN["subsurface"]
        inputs["Subsurface Radius"].default_value = SKIN["subsurface_radius"]
        inputs["Subsurface Scale"].default_value = SKIN["subsurface_scale"]
        inputs["Subsurface IOR"].default_value = SKIN["specular_IOR"]
        inputs["Subsurface Anisotropy"].default_value = 0.0
        inputs["Coat Weight"].default_value = SKIN["coat"]
        inputs["Coat Roughness"].default_value = SKIN["coat_roughness"]
        inputs["Coat IOR"].default_value = SKIN["coat_IOR"]
        inputs["Sheen Weight"].default_value = SKIN["sheen"]
        inputs["Sheen Roughness"].default_value = SKIN["sheen_roughness"]
        inputs["Sheen Tint"].default_value = [1.0, 1.0, 1.0, 1.0]
    # Camera: lightfarm (x, y, z) -> Blender (x, -z, y).
    to_b = lambda v: mathutils.Vector((v[0], -v[2], v[1]))
    cam_data = bpy.data.cameras.new("cam")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(fov_deg)
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
    sc.cycles.samples = spp
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 8
    sc.cycles.diffuse_bounces = 8
    sc.cycles.glossy_bounces = 8
    sc.cycles.transmission_bounces = 8
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.filter_width = 1.0
    sc.cycles.sample_clamp_indirect = 0.0
    sc.cycles.sample_clamp_direct = 0.0
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
    bpy.ops.render.render(write_still=True)
    return time.time() - t0


def compare(name, lf_exr, cy_exr, blocks, seconds):
    import numpy as np
    a, am = read_exr_rgb(lf_exr, "lit0")
    b, bm = read_exr_rgb(cy_exr, None)
    # Cycles' transparent film premultiplies by coverage, as lightfarm's background 0 does.
    mask = (am > 0.99) & (bm > 0.99)
    ma = a[mask].mean(axis=0)
    mb = b[mask].mean(axis=0)
    h, w = mask.shape
    diffs = []
    for by in range(blocks):
        for bx in range(blocks):
            sl = (slice(by * h // blocks, (by + 1) * h // blocks), slice(bx * w // blocks, (bx + 1) * w // blocks))
            m = mask[sl]
            if m.sum() < 0.5 * m.size:
                continue
            la = a[sl][m].mean(axis=0)
            lb = b[sl][m].mean(axis=0)
            diffs.append((la - lb) / np.maximum(lb, 1e-6))
    diffs = np.array(diffs)
    return {
        "scene": name,
        "lightfarm_mean": ma.tolist(),
        "cycles_mean": mb.tolist(),
        "ratio": (ma / mb).tolist(),
        "blocks": len(diffs),
        "block_rel_diff_median": np.median(diffs, axis=0).tolist(),
        "block_rel_diff_abs_p90": np.percentile(np.abs(diffs), 90, axis=0).tolist(),
        "seconds": seconds,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lightfarm", required=True)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--hdri", default=os.path.join(REPO, "assets/hdri/studio_small_03_1k.hdr"))
    ap.add_argument("--out", default=os.path.expanduser("~/.cache/lightfarm-bench/cycles_skin"))
    ap.add_argument("--only", choices=["sphere", "head"], default=None)
    ap.add_argument("--method", choices=["RANDOM_WALK", "RANDOM_WALK_SKIN"], default="RANDOM_WALK",
                    help="Cycles' subsurface method (Skin refracts into the medium with the IOR, as lightfarm does)")
    args = ap.parse_args()
    METHOD[0] = args.method
    os.makedirs(args.out, exist_ok=True)
    results = []
    if args.only in (None, "sphere"):
        sphere = os.path.join(args.out, "skin_sphere.gltf")
        write_sphere_gltf(sphere, 0.05)
        eye, target, fov = (0.0, 0.0, 0.3), (0.0, 0.0, 0.0), 25.0
        cam = f"{eye[0]},{eye[1]},{eye[2]}:{target[0]},{target[1]},{target[2]}:{fov}"
        lf_exr = os.path.join(args.out, "sphere_lightfarm.exr")
        cy_exr = os.path.join(args.out, "sphere_cycles.exr")
        t_lf = render_lightfarm(args.lightfarm, sphere, args.hdri, cam, args.size, args.spp, lf_exr)
        t_cy = render_cycles(sphere, args.hdri, eye, target, fov, args.size, args.spp, cy_exr, False)
        results.append(compare("skin sphere", lf_exr, cy_exr, 8, (t_lf, t_cy)))
    if args.only in (None, "head"):
        # The scan with the skin model: extras are added by a copy of its glTF JSON.
        head = os.path.join(args.out, "head.glb")
        make_skin_head(os.path.join(REPO, "assets/heads/LeePerrySmith_textured.glb"), head)
        eye, target, fov = (0.0, 0.0, 0.6), (0.0, 0.0, 0.0), 30.0
        cam = f"{eye[0]},{eye[1]},{eye[2]}:{target[0]},{target[1]},{target[2]}:{fov}"
        lf_exr = os.path.join(args.out, "head_lightfarm.exr")
        cy_exr = os.path.join(args.out, "head_cycles.exr")
        t_lf = render_lightfarm(args.lightfarm, head, args.hdri, cam, args.size, args.spp, lf_exr)
        t_cy = render_cycles(head, args.hdri, eye, target, fov, args.size, args.spp, cy_exr, True)
        results.append(compare("LeePerrySmith head", lf_exr, cy_exr, 8, (t_lf, t_cy)))
    print("| scene | lightfarm mean RGB | Cycles mean RGB | ratio RGB | blocks | median block diff RGB | p90 abs block diff RGB |")
    print("|---|---|---|---|---|---|---|")
    f = lambda v: " ".join(f"{x:.4f}" for x in v)
    p = lambda v: " ".join(f"{100 * x:+.1f}%" for x in v)
    for r in results:
        print(f"| {r['scene']} | {f(r['lightfarm_mean'])} | {f(r['cycles_mean'])} | {f(r['ratio'])} | "
              f"{r['blocks']} | {p(r['block_rel_diff_median'])} | {p(r['block_rel_diff_abs_p90'])} |")
    print(json.dumps(results), file=sys.stderr)


def make_skin_head(src, dst, skin=True, maps=False):
    """The scan's GLB with `extras.lightfarm = {model: skin}` on its material (or as it is, the
    glTF Lambert + GGX mapping, when `skin` is false), scaled to metres (0.046 m per unit, as
    the catalog's frame) and centred. Without `maps` the normal and specular maps are dropped
    (the Cycles scene has neither, and the head rendered with neither before issue 12)."""
    data = open(src, "rb").read()
    jlen = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20:20 + jlen])
    rest = data[20 + jlen:]
    for m in doc["materials"]:
        if skin:
            m["extras"] = {"lightfarm": {"model": "skin"}}
        if not maps:
            m.pop("normalTexture", None)
            m.pop("extensions", None)
    bmin, bmax = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["min"], \
        doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["max"]
    s = 0.046
    centre = [(bmin[k] + bmax[k]) / 2 for k in range(3)]
    doc["nodes"] = [{"mesh": 0, "scale": [s, s, s], "translation": [-centre[0] * s, -centre[1] * s, -centre[2] * s]}]
    doc["scenes"] = [{"nodes": [0]}]
    doc["scene"] = 0
    j = json.dumps(doc).encode()
    j += b" " * ((4 - len(j) % 4) % 4)
    total = 12 + 8 + len(j) + len(rest)
    with open(dst, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, total))
        f.write(struct.pack("<II", len(j), 0x4E4F534A))
        f.write(j)
        f.write(rest)


if __name__ == "__main__":
    main()
