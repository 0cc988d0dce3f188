"""OFF (and COFF, NOFF, STOFF ...): read an ASCII OFF mesh, in file order."""

import re

import numpy as np

from .data import MeshData
from .parse import parse_coordinates, read_text, triangulate

__all__ = ["read_off", "readers"]

_OFF_KEYWORD = re.compile(r"(ST)?C?N?(4)?(n)?OFF")


def _off_counts(lines):
    """``(nv, nf, rows)`` of the OFF file split into word lists ``lines`` (comments and blank
    lines removed): the declared vertex and face counts and the rows after the header."""
    if not lines:
        raise ValueError("empty file")
    head = lines[0]
    match = _OFF_KEYWORD.fullmatch(head[0])
    glued = re.fullmatch(r"((?:ST)?C?N?OFF)(\d+)", head[0])
    if match is None and glued:
        # the vertex count written against the keyword ("OFF2562 5120 0": ModelNet's files)
        head = [glued.group(1), glued.group(2)] + head[1:]
        match = _OFF_KEYWORD.fullmatch(head[0])
    if match is None:
        raise ValueError(f"starts with {head[0][:20]!r}, not OFF")
    if match.group(2) or match.group(3):
        raise ValueError(f"{head[0]}: only 3-D OFF files are supported")
    counts, rest = head[1:], lines[1:]
    if counts and counts[0].upper() == "BINARY":
        raise ValueError("binary OFF is not supported; save it as ASCII OFF or PLY")
    if not counts:
        if not rest:
            raise ValueError("no vertex and face counts after the OFF line")
        counts, rest = rest[0], rest[1:]
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise ValueError(f"the counts line {' '.join(counts)[:40]!r} is not 'vertices faces "
                         "edges'") from None
    if nv < 0 or nf < 0:
        raise ValueError(f"negative counts ({nv} vertices, {nf} faces)")
    return nv, nf, rest


def _off_faces(frows, nv):
    """(m, 3) int64 triangles of the face rows ``frows`` (word lists ``n i1 .. in [colour]``)
    of a file with ``nv`` vertices; polygons are fan-triangulated."""
    if all(len(r) == 4 and r[0] == "3" for r in frows):  # triangles without colour: at once
        try:
            faces = np.array([r[1:] for r in frows], dtype=np.int64).reshape(-1, 3)
        except ValueError:
            faces = None
        if faces is not None and (not faces.size or (faces.min() >= 0 and faces.max() < nv)):
            return faces
    polygons = []
    for k, r in enumerate(frows):
        try:
            n = int(r[0])
            corners = [int(t) for t in r[1:n + 1]]
        except ValueError:
            raise ValueError(f"face {k}: {' '.join(r)[:40]!r} is not 'n i1 .. in'") from None
        if n < 0 or len(corners) < n or len(r) > n + 5:  # at most 4 colour values after
            raise ValueError(f"face {k}: {' '.join(r)[:40]!r} is not 'n i1 .. in "
                             "[colour]'")
        if corners and (min(corners) < 0 or max(corners) >= nv):
            raise ValueError(f"face {k}: vertex indices outside 0..{nv - 1}")
        polygons.append(corners)
    return triangulate(polygons)


def read_off(path):
    """Read an ASCII OFF mesh (also COFF, NOFF, STOFF ...: colours, normals and texture
    coordinates are ignored), one row per vertex line, in file order.

    The counts of the header must match the data: exactly one line per declared vertex and
    face. Polygons are fan-triangulated.
    """
    lines = []
    for line in read_text(path, "OFF").splitlines():
        if "#" in line:
            line = line.split("#", 1)[0]
        parts = line.split()
        if parts:
            lines.append(parts)
    nv, nf, rest = _off_counts(lines)
    if len(rest) != nv + nf:
        raise ValueError(f"the header declares {nv} vertices and {nf} faces, but "
                         f"{len(rest)} lines follow instead of {nv + nf} (truncated file or "
                         f"wrong counts)")
    vrows = rest[:nv]
    for k, r in enumerate(vrows):
        if len(r) < 3:
            raise ValueError(f"vertex {k}: {' '.join(r)!r} is not x y z")
    vertices = parse_coordinates(vrows, "vertex")
    faces = _off_faces(rest[nv:], nv)
    return MeshData(vertices=vertices, faces=faces if len(faces) else None, path=path)


readers = {".off": read_off}
