"""Writes facemesh_astronaut.txt: TensorFlow Lite's own output of MediaPipe's face mesh on a
192x192 window of the astronaut photo, the reference tests/face_mesh.rs holds lightfarm's
TFLite interpreter to. Needs numpy, pillow and ai-edge-litert (pip), and
./scripts/fetch-models.sh to have run:

    python3 crates/face/tests/data/facemesh_reference.py
"""
import pathlib

import numpy as np
from ai_edge_litert.interpreter import Interpreter
from PIL import Image

ROOT = pathlib.Path(__file__).resolve().parents[4]
# (left, top) of the window; tests/face_mesh.rs uses the same.
LEFT, TOP, SIDE = 114, 14, 192

photo = np.asarray(Image.open(ROOT / "assets/photos/astronaut.png").convert("RGB"))
window = photo[TOP:TOP + SIDE, LEFT:LEFT + SIDE].astype(np.float32) / 255.0
net = Interpreter(model_path=str(ROOT / "assets/models/mediapipe/face_landmark.tflite"))
net.allocate_tensors()
net.set_tensor(net.get_input_details()[0]["index"], window[None])
net.invoke()
out = {d["name"]: net.get_tensor(d["index"]).ravel() for d in net.get_output_details()}
mesh, presence = out["conv2d_21"], out["conv2d_31"]
with open(pathlib.Path(__file__).with_name("facemesh_astronaut.txt"), "w") as fh:
    fh.write(f"# TFLite (ai-edge-litert) face mesh of astronaut.png[{TOP}:{TOP + SIDE}, "
             f"{LEFT}:{LEFT + SIDE}]: presence logit, then 468 x y z in window pixels\n")
    fh.write(f"{presence[0]:.6f}\n")
    for p in mesh.reshape(-1, 3):
        fh.write(" ".join(f"{v:.5f}" for v in p) + "\n")

# `--time N`: also the median of N invocations of TFLite's interpreter on that window (one
# 192² crop; BENCHMARKS.md, "Faces", compares lightfarm's per-crop time against it).
if __name__ == "__main__":
    import sys
    import time
    if len(sys.argv) == 3 and sys.argv[1] == "--time":
        times = []
        for _ in range(int(sys.argv[2]) + 1):
            t = time.perf_counter()
            net.invoke()
            times.append((time.perf_counter() - t) * 1e3)
        times = sorted(times[1:])
        print(f"TFLite face mesh, one 192² crop: median {times[len(times) // 2]:.2f} ms")
