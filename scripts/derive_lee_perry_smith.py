#!/usr/bin/env python3
"""Derives assets/heads/LeePerrySmith_textured.glb: the scan with all three of its maps.

Input: the shared staging's LeePerrySmith folder (three.js examples/models/gltf/LeePerrySmith,
CC BY 3.0): LeePerrySmith_textured.glb (TEXCOORD_0 already flipped to the glTF convention,
Map-COL.jpg embedded as the base colour), Map-SPEC.jpg (the specular-intensity map, grey) and
Infinite-Level_02_Tangent_SmoothUV.jpg (the tangent-space normal map, +Y up as glTF's). All three
maps share one UV layout, so the flip that fixed the colour map fixes the other two.

What it adds: the normal map as the material's normalTexture (the JPEG as it is), and the
specular map as KHR_materials_specular.specularTexture. glTF reads that texture's A channel, so
the map is stored as a grey + alpha PNG with the grey in both. Geometry and the colour map are
unchanged.

usage: derive_lee_perry_smith.py SRC_DIR OUT_GLB   (needs pillow)
"""
import io
import json
import struct
import sys
from pathlib import Path

from PIL import Image


def read_glb(path):
    data = Path(path).read_bytes()
    magic, version, _ = struct.unpack_from("<III", data, 0)
    if magic != 0x46546C67 or version != 2:
        sys.exit(f"{path}: not a glTF 2.0 binary")
    json_len, json_type = struct.unpack_from("<II", data, 12)
    if json_type != 0x4E4F534A:
        sys.exit(f"{path}: the first chunk is not JSON")
    doc = json.loads(data[20:20 + json_len])
    off = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, off)
    if bin_type != 0x004E4942:
        sys.exit(f"{path}: the second chunk is not BIN")
    return doc, bytearray(data[off + 8:off + 8 + bin_len])


def write_glb(path, doc, blob):
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    blob = bytes(blob) + b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    out = struct.pack("<III", 0x46546C67, 2, total)
    out += struct.pack("<II", len(text), 0x4E4F534A) + text
    out += struct.pack("<II", len(blob), 0x004E4942) + blob
    Path(path).write_bytes(out)


def add_image(doc, blob, name, mime, payload):
    blob.extend(b"\0" * (-len(blob) % 4))
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(payload)})
    blob.extend(payload)
    doc["images"].append({"bufferView": len(doc["bufferViews"]) - 1, "mimeType": mime, "name": name})
    doc["textures"].append({"source": len(doc["images"]) - 1, "sampler": 0})
    return len(doc["textures"]) - 1


def main(src, out):
    src = Path(src)
    doc, blob = read_glb(src / "LeePerrySmith_textured.glb")
    if len(doc["images"]) != 1:
        sys.exit("expected the staging GLB with the colour map only")
    normal = (src / "Infinite-Level_02_Tangent_SmoothUV.jpg").read_bytes()
    grey = Image.open(src / "Map-SPEC.jpg").convert("L")
    png = io.BytesIO()
    Image.merge("LA", (grey, grey)).save(png, format="PNG", optimize=True)
    n = add_image(doc, blob, "Infinite-Level_02_Tangent_SmoothUV", "image/jpeg", normal)
    s = add_image(doc, blob, "Map-SPEC", "image/png", png.getvalue())
    material = doc["materials"][0]
    material["normalTexture"] = {"index": n}
    material["extensions"] = {"KHR_materials_specular": {"specularFactor": 1.0, "specularTexture": {"index": s}}}
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {"KHR_materials_specular"})
    doc["buffers"][0]["byteLength"] = len(blob) + (-len(blob) % 4)
    doc["asset"]["extras"]["modification"] += (
        " Infinite-Level_02_Tangent_SmoothUV.jpg embedded as normalTexture; Map-SPEC.jpg embedded as"
        " KHR_materials_specular.specularTexture (grey + alpha PNG, the map in both: glTF reads A)"
        " by lightfarm scripts/derive_lee_perry_smith.py."
    )
    write_glb(out, doc, blob)
    print(f"wrote {out}: {Path(out).stat().st_size} bytes")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
