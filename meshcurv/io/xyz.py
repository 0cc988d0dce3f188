"""Text point clouds (.xyz, Leica .pts): whitespace- or comma-separated columns."""

from collections import Counter

import numpy as np

from .data import MeshData
from .parse import is_number, read_text

__all__ = ["read_xyz", "readers"]

# The UTF-8 byte-order mark as :func:`meshcurv.io.parse.read_text` (latin-1) decodes it.
_UTF8_BOM = "\ufeff".encode("utf-8").decode("latin-1")


def read_xyz(path):
    """Read a whitespace- or comma-separated text point cloud (.xyz, .pts).

    Columns: 3 = ``x y z``; 6 = ``x y z nx ny nz``, or ``x y z r g b`` where those three are
    whole numbers 0-255 (CloudCompare's export of a coloured cloud); 9 = ``x y z r g b nx ny
    nz`` in either order (the colours the whole-number triple 0-255, else the one that is not
    of unit length); 4 or 7 = ``x y z intensity
    [r g b]`` (Leica PTS). Colours and intensity are kept in ``fields``. A first line holding a
    single integer is the point count (PTS) and must match the number of rows; a first line of
    words is a column header (``//X Y Z R G B``) and skipped; ``#`` comments are skipped.
    """
    text = read_text(path, "XYZ")
    if text.startswith(_UTF8_BOM):            # a byte-order mark (Windows tools), as latin-1
        text = text[len(_UTF8_BOM):]
    lines = [ln.split("#", 1)[0].replace(",", " ").split() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if lines and not any(is_number(t) for t in lines[0]):
        lines = lines[1:]
    if lines and len(lines[0]) == 1 and lines[0][0].isdigit():
        declared = int(lines[0][0])
        lines = lines[1:]
        if declared != len(lines):
            raise ValueError(f"the first line declares {declared} points, but {len(lines)} "
                             "rows follow (truncated file or wrong count)")
    if not lines:
        return MeshData(vertices=np.zeros((0, 3)), path=path)
    widths = Counter(len(ln) for ln in lines)
    if len(widths) != 1:
        usual = widths.most_common(1)[0][0]
        odd = next(k for k, ln in enumerate(lines) if len(ln) != usual)
        raise ValueError(f"rows have different numbers of columns: row {odd + 1} has "
                         f"{len(lines[odd])}, {widths[usual]} of {len(lines)} rows have {usual}")
    ncol = len(lines[0])
    if ncol not in (3, 4, 6, 7, 9):
        raise ValueError(f"expected 3 (x y z), 6 (x y z nx ny nz or x y z r g b), 9 (x y z r g b "
                         f"nx ny nz), 4 or 7 (PTS) columns, got {ncol}")
    table = np.array(lines, dtype=np.float64)
    data = MeshData(vertices=np.ascontiguousarray(table[:, :3]), path=path)
    if ncol in (6, 9):
        triples = [table[:, 3:6], table[:, 6:9]] if ncol == 9 else [table[:, 3:6]]
        colour = next((k for k, t in enumerate(triples) if _colours(t)), None)
        if colour is None and ncol == 9:
            # colours in 0-1: the triple that is not of unit length
            unit = [_unit_length(t) for t in triples]
            if unit[0] == unit[1]:
                raise ValueError("9 columns, but neither x y z r g b nx ny nz nor x y z nx ny "
                                 "nz r g b: no 0-255 colours and no unit normals to tell them "
                                 "apart")
            colour = unit.index(False)
        if colour is not None:
            for i, c in enumerate(("red", "green", "blue")):
                data.fields[c] = triples[colour][:, i]
            del triples[colour]
        if triples:
            data.normals = np.ascontiguousarray(triples[0])
    elif ncol >= 4:
        data.fields["intensity"] = table[:, 3]
        if ncol == 7:
            for i, c in enumerate(("red", "green", "blue")):
                data.fields[c] = table[:, 4 + i]
    return data


def _colours(triple):
    """Whether the columns ``triple`` (n, 3) are 8-bit colours rather than normals: whole
    numbers 0-255 with more than a unit vector's length somewhere (a unit normal's
    coordinates are whole numbers only along the axes)."""
    whole = np.all((triple >= 0) & (triple <= 255) & (triple == np.round(triple)))
    return bool(whole and np.any(np.abs(triple).sum(axis=1) > 1))


def _unit_length(triple):
    """Whether the rows of ``triple`` (n, 3) are unit vectors, as written with 3 or more
    decimals."""
    return bool(np.median(np.abs(np.linalg.norm(triple, axis=1) - 1.0)) < 1e-3)


readers = {".xyz": read_xyz, ".pts": read_xyz}
