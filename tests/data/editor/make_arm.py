"""Wrote tests/data/editor/arm_*.stl: three plates of a planar arm in millimetres, in the
assembly frame (as CAD exports an assembly's parts). Needs shapely and mapbox_earcut, which
mexone does not: run once by hand (PYTHONPATH with both), the STLs are committed."""
import numpy as np
import trimesh
from shapely.geometry import LineString, Point


def plate(ends, r, holes, y0, t=20.0):
    outline = LineString(ends).buffer(r, quad_segs=8) if len(ends) > 1 else Point(ends[0]).buffer(r, quad_segs=8)
    for h in holes:
        outline = outline.difference(Point(h).buffer(5.0, quad_segs=8))
    m = trimesh.creation.extrude_polygon(outline, t)
    rot = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    m.apply_transform(rot)  # (u, v, w) -> (u, -w, v)
    m.apply_translation([0, y0 + t, 0])
    assert m.is_watertight and m.volume > 0
    return m
base = plate([(0, 0), (0, 100)], 20, [(0, 100)], -10)
upper = plate([(0, 100), (150, 100)], 20, [(0, 100), (150, 100)], 10)
fore = plate([(150, 100), (270, 100)], 15, [(150, 100)], -10)
for name, m in (("base", base), ("upper", upper), ("fore", fore)):
    m.export(f"tests/data/editor/arm_{name}.stl")
    print(name, len(m.faces), m.bounds.tolist(), m.volume)
