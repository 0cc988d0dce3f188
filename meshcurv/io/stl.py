"""STL (binary or ASCII): read a mesh, its unshared triangle corners merged by exact position in
order of first appearance (as MeshLab does on import), so that triangles share vertices."""

import re
from collections import Counter

import numpy as np

from ..weld import coincident_vertices
from .data import MeshData, MeshFileError
from .parse import is_number

__all__ = ["read_stl", "readers"]

_STL_FACET = re.compile(
    rb"facet\s+normal\s+\S+\s+\S+\s+\S+\s+outer\s+loop\s+"
    rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)\s+vertex\s+(\S+)\s+(\S+)\s+(\S+)\s+"
    rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)\s+endloop\s+endfacet", re.IGNORECASE)


def _stl_corners(raw):
    """(3 m, 3) float64 triangle corners of a binary or ASCII STL, in file order."""
    if len(raw) >= 84:
        m = int(np.frombuffer(raw, "<u4", 1, 80)[0])
        if len(raw) == 84 + 50 * m:  # binary, whatever the header text says
            record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)),
                               ("attribute", "<u2")])
            tris = np.frombuffer(raw, record, m, 84)["corners"]
            return tris.reshape(-1, 3).astype(np.float64)
    if raw.lstrip()[:5].lower() != b"solid" or b"\0" in raw:  # SolidWorks: binary "solid.."
        if len(raw) < 84:
            raise ValueError(f"{len(raw)} bytes: too short for a binary STL, and not ASCII "
                             "(no 'solid' line)")
        raise ValueError(f"the binary header declares {m} triangles ({84 + 50 * m} bytes), "
                         f"but the file has {len(raw)} bytes (truncated or corrupt)")
    corners = _STL_FACET.findall(raw)
    rest = _STL_FACET.sub(b"\n", raw)
    words = Counter()
    for line in rest.splitlines():
        word = line.split()[:1]
        if word and word[0].lower() not in (b"solid", b"endsolid"):
            raise ValueError(f"incomplete or malformed ASCII facet near "
                             f"{line.strip()[:40].decode('latin-1')!r}")
        words.update(w.lower() for w in word)
    if words[b"solid"] != words[b"endsolid"]:
        raise ValueError("ASCII file without its 'endsolid' line (truncated)")
    try:
        return np.array(corners, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        bad = next(t for c in corners for t in c if not is_number(t))
        raise ValueError(f"ASCII vertex coordinate {bad[:20].decode('latin-1')!r} is not "
                         "a number") from None


def _merge_exact(vertices, faces):
    """Merge (n, 3) ``vertices`` with identical coordinates, keeping the order of first
    appearance (:func:`meshcurv.weld.coincident_vertices`); returns the merged (k, 3)
    vertices and ``faces`` ((m, 3) int) renumbered."""
    welding = coincident_vertices(vertices)
    if welding is None:
        return vertices, faces
    return vertices[welding.keep], welding.index[faces]


def read_stl(path):
    """Read a binary or ASCII STL mesh.

    STL stores three unshared corners per triangle; they are merged by exact position in order
    of first appearance (see the module docstring). Facet normals are ignored. A binary file
    must be exactly as long as its triangle count says; an ASCII file must hold only complete
    facets.
    """
    with open(path, "rb") as fh:
        raw = fh.read()
    try:
        corners = _stl_corners(raw)
    except ValueError as exc:
        raise MeshFileError(f"{path}: corrupt STL: {exc}") from None
    faces = np.arange(len(corners), dtype=np.int64).reshape(-1, 3)
    if len(corners):
        corners, faces = _merge_exact(corners, faces)
    return MeshData(vertices=corners, faces=faces if len(faces) else None, path=path)


readers = {".stl": read_stl}
