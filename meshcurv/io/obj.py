"""Wavefront OBJ: read the vertices (``v``) and faces (``f``) of a mesh, in file order."""

import numpy as np

from .data import MeshData
from .parse import parse_coordinates, read_text, triangulate

__all__ = ["read_obj", "readers"]


def _face_corners(tokens, n_before, lineno):
    """0-based vertex indices of the corners ``tokens`` (``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``)
    of the ``f`` line ``lineno``, after ``n_before`` vertices; negative indices count back
    from the last of them."""
    corners = []
    for token in tokens:
        try:
            i = int(token.split("/", 1)[0])
        except ValueError:
            raise ValueError(f"line {lineno}: {token!r} is not a vertex index") from None
        if i == 0:
            raise ValueError(f"line {lineno}: vertex index 0 (OBJ counts from 1)")
        if i < 0:  # relative to the vertices read so far
            if -i > n_before:
                raise ValueError(f"line {lineno}: relative index {i} but only "
                                 f"{n_before} vertices before it")
            i += n_before + 1
        corners.append(i - 1)
    return corners


def read_obj(path):
    """Read a Wavefront OBJ mesh: one row per ``v`` line, in file order.

    Faces (``f``) may use ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` corners and negative
    (relative) indices; polygons are fan-triangulated. Texture coordinates and normals are
    ignored, so vertices are never split by them (unlike trimesh's loader); lines, points,
    groups and materials are ignored too.
    """
    text = read_text(path, "OBJ").replace("\\\r\n", " ").replace("\\\n", " ")
    rows, polygons = [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        if "#" in line:
            line = line.split("#", 1)[0]
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            if len(parts) < 4:
                raise ValueError(f"line {lineno}: a vertex needs x y z")
            rows.append(parts[1:4])
        elif parts[0] == "f":
            polygons.append(_face_corners(parts[1:], len(rows), lineno))
    vertices = parse_coordinates(rows, "vertex")
    if all(len(p) == 3 for p in polygons):
        faces = np.array(polygons, dtype=np.int64).reshape(-1, 3)
    else:
        faces = triangulate(polygons)
    if faces.size and faces.max() >= len(vertices):
        raise ValueError(f"a face uses vertex {faces.max() + 1} of {len(vertices)}")
    return MeshData(vertices=vertices, faces=faces if len(faces) else None, path=path)


readers = {".obj": read_obj}
