"""Text point clouds (.xyz, Leica .pts): whitespace- or comma-separated columns."""

from collections import Counter

import numpy as np

from .data import MeshData

__all__ = ["read_xyz", "readers"]


def read_xyz(path):
    """Read a whitespace- or comma-separated text point cloud (.xyz, .pts).

    Columns: 3 = ``x y z``; 6 = ``x y z nx ny nz``; 4 or 7 = ``x y z intensity [r g b]`` (Leica
    PTS; the extra columns are kept in ``fields``). A first line holding a single integer is
    the point count (PTS) and must match the number of rows; ``#`` comments are skipped.
    """
    with open(path, "r", encoding="utf-8", errors="strict") as fh:
        lines = [ln.split("#", 1)[0].replace(",", " ").split() for ln in fh]
    lines = [ln for ln in lines if ln]
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
    if ncol not in (3, 4, 6, 7):
        raise ValueError(f"expected 3 (x y z), 6 (x y z nx ny nz), 4 or 7 (PTS) columns, "
                         f"got {ncol}")
    table = np.array(lines, dtype=np.float64)
    data = MeshData(vertices=np.ascontiguousarray(table[:, :3]), path=path)
    if ncol == 6:
        data.normals = np.ascontiguousarray(table[:, 3:6])
    elif ncol >= 4:
        data.fields["intensity"] = table[:, 3]
        if ncol == 7:
            for i, c in enumerate(("red", "green", "blue")):
                data.fields[c] = table[:, 4 + i]
    return data


readers = {".xyz": read_xyz, ".pts": read_xyz}
