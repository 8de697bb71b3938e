#!/usr/bin/env python3
"""Convert a binary glTF (.glb) to a binary little-endian PLY for Mitsuba 3.

Pure Python + numpy (struct, json). Flattens the default scene: every triangle primitive of every
mesh node is transformed to world space (node matrices / TRS composed down the hierarchy; normals
by the inverse transpose) and merged into one PLY with per-vertex positions, normals and uvs
(TEXCOORD_0, stored unchanged: glTF's v points down the image, which is also how Mitsuba's
`bitmap` texture indexes uvs, so no flip is needed).

Also extracts the first material's base-colour texture (embedded JPEG/PNG) next to the PLY and
writes a JSON sidecar describing the material and the world bounding box:

    python3 bench/glb_to_ply.py in.glb out.ply
    -> out.ply, out.json, out_basecolor.jpg (if the material has a base-colour texture)
"""
import json
import os
import struct
import sys

import numpy as np

_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
              5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORM_DIV = {np.int8: 127.0, np.uint8: 255.0, np.int16: 32767.0, np.uint16: 65535.0}


class Glb:
    def __init__(self, path):
        with open(path, "rb") as f:
            data = f.read()
        magic, version, length = struct.unpack_from("<4sII", data, 0)
        if magic != b"glTF" or version != 2:
            raise ValueError(f"{path}: not a glTF 2.0 binary (magic {magic!r}, version {version})")
        self.json = None
        self.bin = b""
        off = 12
        while off + 8 <= min(length, len(data)):
            clen, ctype = struct.unpack_from("<I4s", data, off)
            chunk = data[off + 8: off + 8 + clen]
            if ctype == b"JSON":
                self.json = json.loads(chunk.decode("utf-8"))
            elif ctype == b"BIN\x00" and not self.bin:
                self.bin = chunk
            off += 8 + clen
        if self.json is None:
            raise ValueError(f"{path}: no JSON chunk")
        for b in self.json.get("buffers", []):
            if "uri" in b:
                raise ValueError("external buffers are not supported (glb with embedded BIN only)")

    def buffer_view(self, idx):
        bv = self.json["bufferViews"][idx]
        start = bv.get("byteOffset", 0)
        return self.bin[start: start + bv["byteLength"]], bv.get("byteStride")

    def accessor(self, idx):
        acc = self.json["accessors"][idx]
        dtype = np.dtype(_COMPONENT[acc["componentType"]]).newbyteorder("<")
        ncomp = _NCOMP[acc["type"]]
        count = acc["count"]
        if "bufferView" in acc:
            raw, stride = self.buffer_view(acc["bufferView"])
            off = acc.get("byteOffset", 0)
            elem = dtype.itemsize * ncomp
            stride = stride or elem
            buf = np.frombuffer(raw, dtype=np.uint8)
            rows = np.lib.stride_tricks.as_strided(
                buf[off:], shape=(count, elem), strides=(stride, 1)) if count else buf[:0].reshape(0, elem)
            out = np.ascontiguousarray(rows).view(dtype).reshape(count, ncomp)
        else:
            out = np.zeros((count, ncomp), dtype=dtype)
        if "sparse" in acc:
            sp = acc["sparse"]
            idt = np.dtype(_COMPONENT[sp["indices"]["componentType"]]).newbyteorder("<")
            iraw, _ = self.buffer_view(sp["indices"]["bufferView"])
            ioff = sp["indices"].get("byteOffset", 0)
            ind = np.frombuffer(iraw, dtype=idt, count=sp["count"], offset=ioff)
            vraw, _ = self.buffer_view(sp["values"]["bufferView"])
            voff = sp["values"].get("byteOffset", 0)
            vals = np.frombuffer(vraw, dtype=dtype, count=sp["count"] * ncomp, offset=voff)
            out = out.copy()
            out[ind.astype(np.int64)] = vals.reshape(-1, ncomp)
        if acc.get("normalized") and dtype.type in _NORM_DIV:
            out = np.maximum(out.astype(np.float64) / _NORM_DIV[dtype.type], -1.0)
        return out

    def image_bytes(self, image_idx):
        img = self.json["images"][image_idx]
        if "bufferView" not in img:
            return None, None
        raw, _ = self.buffer_view(img["bufferView"])
        mime = img.get("mimeType", "")
        ext = {"image/jpeg": ".jpg", "image/png": ".png"}.get(mime)
        if ext is None:
            ext = ".png" if raw[:4] == b"\x89PNG" else ".jpg"
        return bytes(raw), ext


def _quat_to_mat3(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def node_local_matrix(node):
    if "matrix" in node:
        # glTF stores column-major.
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    t = node.get("translation", [0, 0, 0])
    r = node.get("rotation", [0, 0, 0, 1])
    s = node.get("scale", [1, 1, 1])
    m[:3, :3] = _quat_to_mat3(r) @ np.diag(s)
    m[:3, 3] = t
    return m


def _vertex_normals(pos, tri):
    n = np.zeros_like(pos)
    fn = np.cross(pos[tri[:, 1]] - pos[tri[:, 0]], pos[tri[:, 2]] - pos[tri[:, 0]])
    for k in range(3):
        np.add.at(n, tri[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1)


def _triangles(mode, idx):
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:  # strip
        t = [(idx[i], idx[i + 1], idx[i + 2]) if i % 2 == 0 else (idx[i + 1], idx[i], idx[i + 2])
             for i in range(len(idx) - 2)]
        return np.array(t, dtype=np.int64).reshape(-1, 3)
    if mode == 6:  # fan
        t = [(idx[0], idx[i], idx[i + 1]) for i in range(1, len(idx) - 1)]
        return np.array(t, dtype=np.int64).reshape(-1, 3)
    return None  # points / lines: skipped


def flatten(glb):
    """Return (positions, normals, uvs, triangles, material indices used) in world space."""
    j = glb.json
    scene_idx = j.get("scene", 0)
    scenes = j.get("scenes") or [{"nodes": list(range(len(j.get("nodes", []))))}]
    roots = scenes[scene_idx].get("nodes", [])
    P, N, UV, T, mats = [], [], [], [], []
    base = 0
    stack = [(r, np.eye(4)) for r in roots]
    while stack:
        ni, parent = stack.pop()
        node = j["nodes"][ni]
        world = parent @ node_local_matrix(node)
        for c in node.get("children", []):
            stack.append((c, world))
        if "mesh" not in node:
            continue
        lin = world[:3, :3]
        nrm_m = np.linalg.inv(lin).T
        flip = np.linalg.det(lin) < 0
        for prim in j["meshes"][node["mesh"]]["primitives"]:
            attrs = prim["attributes"]
            if "POSITION" not in attrs:
                continue
            pos = glb.accessor(attrs["POSITION"]).astype(np.float64)
            idx = (glb.accessor(prim["indices"]).reshape(-1).astype(np.int64)
                   if "indices" in prim else np.arange(len(pos), dtype=np.int64))
            tri = _triangles(prim.get("mode", 4), idx)
            if tri is None or len(tri) == 0:
                continue
            if flip:
                tri = tri[:, [0, 2, 1]]
            wpos = pos @ lin.T + world[:3, 3]
            if "NORMAL" in attrs:
                n = glb.accessor(attrs["NORMAL"]).astype(np.float64) @ nrm_m.T
                ln = np.linalg.norm(n, axis=1, keepdims=True)
                n = n / np.where(ln > 0, ln, 1)
            else:
                n = _vertex_normals(wpos, tri)
            uv = (glb.accessor(attrs["TEXCOORD_0"]).astype(np.float64)
                  if "TEXCOORD_0" in attrs else np.zeros((len(pos), 2)))
            P.append(wpos)
            N.append(n)
            UV.append(uv)
            T.append(tri + base)
            base += len(pos)
            mats.append(prim.get("material"))
    if not P:
        raise ValueError("no triangle geometry in the default scene")
    return (np.concatenate(P), np.concatenate(N), np.concatenate(UV), np.concatenate(T), mats)


def write_ply(path, pos, nrm, uv, tri):
    nv, nf = len(pos), len(tri)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment lightfarm bench/glb_to_ply.py\n"
        f"element vertex {nv}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property float u\nproperty float v\n"
        f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    vert = np.concatenate([pos, nrm, uv], axis=1).astype("<f4")
    face = np.zeros(nf, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face["n"] = 3
    face["i"] = tri.astype(np.int32)
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(vert.tobytes())
        f.write(face.tobytes())


def convert(glb_path, ply_path):
    glb = Glb(glb_path)
    pos, nrm, uv, tri, mats = flatten(glb)
    write_ply(ply_path, pos, nrm, uv, tri)
    stem = os.path.splitext(ply_path)[0]
    info = {
        "source": os.path.abspath(glb_path),
        "ply": os.path.abspath(ply_path),
        "vertices": int(len(pos)),
        "triangles": int(len(tri)),
        "bbox_min": pos.min(axis=0).tolist(),
        "bbox_max": pos.max(axis=0).tolist(),
        "base_color_factor": [1.0, 1.0, 1.0, 1.0],
        "roughness": 1.0,
        "metallic": 1.0,
        "base_color_texture": None,
    }
    used = [m for m in mats if m is not None]
    if len(set(used)) > 1:
        print(f"warning: {len(set(used))} materials; only material {used[0]} is exported",
              file=sys.stderr)
    if used:
        mat = glb.json["materials"][used[0]]
        info["material_name"] = mat.get("name")
        pbr = mat.get("pbrMetallicRoughness", {})
        info["base_color_factor"] = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
        info["roughness"] = pbr.get("roughnessFactor", 1.0)
        info["metallic"] = pbr.get("metallicFactor", 1.0)
        tex = pbr.get("baseColorTexture")
        if tex is not None:
            if tex.get("texCoord", 0) != 0:
                print("warning: base-colour texture uses TEXCOORD_%d; exported uvs are TEXCOORD_0"
                      % tex["texCoord"], file=sys.stderr)
            src = glb.json["textures"][tex["index"]].get("source")
            if src is not None:
                raw, ext = glb.image_bytes(src)
                if raw is not None:
                    tpath = stem + "_basecolor" + ext
                    with open(tpath, "wb") as f:
                        f.write(raw)
                    info["base_color_texture"] = os.path.abspath(tpath)
    with open(stem + ".json", "w") as f:
        json.dump(info, f, indent=2)
    return info


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    info = convert(argv[1], argv[2])
    print(json.dumps(info))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
