"""Pieces the readers share: fan triangulation of polygons, a text file read as text, and
coordinate rows parsed with the row that fails named."""

import numpy as np

__all__ = ["triangulate", "read_text", "parse_coordinates", "is_number"]


def triangulate(polygons):
    """Fan-triangulate index polygons (sequences of ints) into an (m, 3) int64 array.

    Polygons with fewer than 3 corners are dropped; vertices are left untouched.

    >>> triangulate([[0, 1, 2, 3], [4, 5]]).tolist()
    [[0, 1, 2], [0, 2, 3]]
    """
    tris = []
    for p in polygons:
        p = [int(i) for i in p]
        tris.extend((p[0], p[j], p[j + 1]) for j in range(1, len(p) - 1))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def read_text(path, what):
    """The file as text (latin-1: never fails on odd bytes in comments); ValueError on NUL
    bytes, which no text format holds. ``what`` names the format in the message."""
    with open(path, "rb") as fh:
        raw = fh.read()
    nul = raw.find(b"\0")
    if nul >= 0:
        raise ValueError(f"binary data where {what} text was expected (byte {nul} is NUL)")
    return raw.decode("latin-1")


def parse_coordinates(rows, what):
    """(n, 3) float64 from the first three number strings of each row; ValueError naming the
    first row that does not parse (``what`` 1-based, e.g. "vertex 3")."""
    try:
        return np.array([r[:3] for r in rows], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        for k, r in enumerate(rows):
            try:
                [float(t) for t in r[:3]]
            except ValueError:
                raise ValueError(f"{what} {k + 1}: {' '.join(r[:3])!r} is not three "
                                 f"numbers") from None
        raise


def is_number(token):
    """Whether ``token`` (str or bytes) parses as a float."""
    try:
        float(token)
    except ValueError:
        return False
    return True
