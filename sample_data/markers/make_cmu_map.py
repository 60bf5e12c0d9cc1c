#!/usr/bin/env python3
"""Writes cmu_finalbasemesh_map.json: the CMU marker set (subject 01, 41 markers) placed on
FinalBaseMesh.obj (../shared/data/meshes/dengnantianjie__3dcoursework/bunny/data/, y up, facing
+z, the subject's left at +x, height 20.7 units). Each marker is the vertex that reaches
furthest along an outward direction inside an anatomical box (template units), chosen by hand
from cross-sections of the mesh and checked on a render (docs/performance_capture.md).
Markers on the arms are left out of the first-frame alignment ("align": false): the template
is in an A-pose and the take starts with the left arm raised.
Usage: make_cmu_map.py FinalBaseMesh.obj > cmu_finalbasemesh_map.json"""
import json
import sys

V = [tuple(map(float, l.split()[1:4])) for l in open(sys.argv[1]) if l.startswith('v ')]

# name: (x range, y range, z range, outward direction, used for the alignment)
L = {
    'FHD': ((0.15, 0.9), (19.2, 20.4), (-9, 9), (0.5, 0.3, 1.0), True),
    'BHD': ((0.15, 0.9), (19.2, 20.4), (-9, 9), (0.5, 0.3, -1.0), True),
    'SHO': ((1.6, 2.9), (15.8, 17.2), (-9, 9), (0.3, 1.0, 0.0), True),
    'UPA': ((3.1, 4.3), (13.7, 15.1), (-9, 9), (0.9, 0.4, -0.4), False),
    'ELB': ((3.8, 4.9), (12.0, 13.1), (-9, 9), (0.8, 0.3, -0.6), False),
    'FRM': ((4.4, 5.4), (10.8, 11.8), (-9, 9), (0.9, 0.3, -0.3), False),
    'WRA': ((4.9, 5.8), (9.8, 10.5), (-9, 9), (0.0, 0.0, 1.0), False),
    'WRB': ((4.9, 5.8), (9.8, 10.5), (-9, 9), (0.0, 0.0, -1.0), False),
    'FIN': ((5.1, 6.0), (8.9, 9.6), (-9, 9), (1.0, -0.4, 0.0), False),
    'FWT': ((0.7, 1.7), (10.3, 11.1), (-9, 9), (0.3, 0.0, 1.0), True),
    'BWT': ((0.3, 1.3), (10.3, 11.1), (-9, 9), (0.0, 0.0, -1.0), True),
    'THI': ((1.5, 2.5), (7.0, 7.8), (-9, 9), (1.0, 0.0, 0.3), True),
    'KNE': ((1.7, 2.6), (5.2, 5.9), (-9, 9), (1.0, 0.0, 0.0), True),
    'SHN': ((1.3, 2.3), (3.0, 3.7), (-9, 9), (0.3, 0.0, 1.0), True),
    'ANK': ((1.7, 2.6), (0.8, 1.3), (-9, 9), (1.0, 0.0, -0.2), True),
    'HEE': ((1.3, 2.5), (0.2, 0.9), (-9, 9), (0.0, 0.0, -1.0), True),
    'TOE': ((1.3, 2.5), (0.2, 0.9), (1.0, 9), (0.0, 0.3, 1.0), True),
    'MT5': ((1.9, 2.8), (0.0, 0.6), (0.0, 1.3), (1.0, 0.0, 0.0), True),
}
C = {  # on the midline or one side only
    'C7': ((-0.5, 0.5), (16.8, 17.8), (-9, 9), (0.0, 0.3, -1.0), True),
    'T10': ((-0.5, 0.5), (13.0, 14.0), (-9, 9), (0.0, 0.0, -1.0), True),
    'CLAV': ((-0.4, 0.4), (16.3, 17.0), (-9, 9), (0.0, 0.0, 1.0), True),
    'STRN': ((-0.4, 0.4), (14.0, 14.6), (-9, 9), (0.0, 0.0, 1.0), True),
    'RBAC': ((-1.6, -0.8), (14.5, 15.5), (-9, 9), (0.0, 0.0, -1.0), True),
}


def pick(box):
    (x0, x1), (y0, y1), (z0, z1), d, _ = box
    best, arg = None, -1
    for i, (x, y, z) in enumerate(V):
        if x0 <= x <= x1 and y0 <= y <= y1 and z0 <= z <= z1:
            s = d[0] * x + d[1] * y + d[2] * z
            if best is None or s > best:
                best, arg = s, i
    if arg < 0:
        sys.exit('no vertex in the box of ' + repr(box))
    return arg


out = []
for side, sx in (('L', 1), ('R', -1)):
    for name, ((x0, x1), yr, zr, (dx, dy, dz), al) in L.items():
        xr = (x0, x1) if sx > 0 else (-x1, -x0)
        out.append({'marker': side + name, 'vertex': pick((xr, yr, zr, (sx * dx, dy, dz), al)), 'align': al})
for name, box in C.items():
    out.append({'marker': name, 'vertex': pick(box), 'align': box[4]})
json.dump({'template': 'FinalBaseMesh.obj', 'markers': out}, sys.stdout, indent=1)
print()
