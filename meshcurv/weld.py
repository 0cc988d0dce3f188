"""Coincident vertices of a mesh, joined for the estimator's neighbourhoods.

A mesh may store one surface point as several vertices: a triangle soup (STL corners, each
face with vertices of its own) or a mesh split along texture seams and hard edges (what
trimesh keeps when vertices differ in texture coordinates or normals). Mesh edges then stop
at the copies, so a vertex's k-ring holds only its own side of a seam, or only its own
triangle: measured on a torus 240 x 60 at R 0.3, one seam split into 60 copies made the mean
|dk| of the vertices near it 0.0028 instead of 0.0006, and a triangle soup gave no estimate
at all. :func:`meshcurv.principal_curvatures` therefore estimates on the mesh with coincident
vertices joined (exactly equal finite coordinates; the first vertex of each position stands
for it, in input order) and gives every copy its position's row. Meshes without coincident
vertices are not touched.
"""

from dataclasses import fields, replace
from typing import NamedTuple

import numpy as np

__all__ = ["Welding", "coincident_vertices", "welded_mesh", "welded_queries", "expand_rows"]


class Welding(NamedTuple):
    """How the n vertices of a mesh map onto its k distinct positions.

    ``keep`` (k,) int64 ascending: the first vertex of each position, i.e. the welded mesh's
    vertices in input order; ``index`` (n,) int64: each vertex's row in the welded mesh
    (``keep[index[i]]`` is the first vertex at ``vertices[i]``).
    """

    keep: np.ndarray
    index: np.ndarray


def coincident_vertices(vertices):
    """The :class:`Welding` of ``vertices`` ((n, 3) float64), or None when no two finite rows
    are equal (then nothing is to be joined). Rows with NaN or inf stay their own.

    Rows are grouped by a 64-bit hash of their coordinates (one sort of n integers, ~0.1 s
    per million vertices) and the groups checked coordinate by coordinate; should two
    positions share a hash, the rows are sorted by their coordinates instead.
    """
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    rows = np.flatnonzero(np.isfinite(v).all(axis=1))
    if len(rows) < 2:
        return None
    # + 0.0 turns -0.0 into 0.0: equal coordinates, equal bits
    bits = (v[rows] + 0.0).view(np.uint64)
    key = _mix(_mix(_mix(bits[:, 0]) ^ bits[:, 1]) ^ bits[:, 2])
    by_key = np.argsort(key)
    tie = key[by_key[1:]] == key[by_key[:-1]]
    if not tie.any():
        return None
    order = rows[by_key]
    same = tie & (v[order[1:]] == v[order[:-1]]).all(axis=1)
    if (tie & ~same).any():
        order = rows[np.lexsort((v[rows, 2], v[rows, 1], v[rows, 0]))]
        same = (v[order[1:]] == v[order[:-1]]).all(axis=1)
        if not same.any():
            return None
    # each run of equal rows stands for one position: its smallest index leads
    starts = np.flatnonzero(np.r_[True, ~same])
    lead = np.minimum.reduceat(order, starts)
    canonical = np.arange(n, dtype=np.int64)
    canonical[order] = np.repeat(lead, np.diff(np.r_[starts, len(order)]))
    keep = np.flatnonzero(canonical == np.arange(n))
    return Welding(keep, np.searchsorted(keep, canonical))


def _mix(x):
    """SplitMix64's finaliser of (k,) uint64: every input bit moves about half the output
    bits, so that mirror-image coordinates (which differ in the sign bit only) do not
    share a hash."""
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def welded_mesh(vertices, faces, normals, welding):
    """``(vertices, faces, normals)`` of the welded mesh: the ``welding.keep`` rows of
    ``vertices``, ``faces`` renumbered, and per position the copies' unit ``normals``
    averaged and normalised (the copies of a hard edge or a triangle soup carry their own
    faces' normals; their mean is the surface's), NaN copies left out; where the copies'
    normals cancel, the first copy's. ``normals`` may be None."""
    vw = vertices[welding.keep]
    fw = welding.index[faces]
    if normals is None:
        return vw, fw, None
    k = len(welding.keep)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    usable = np.isfinite(unit).all(axis=1)
    total = np.column_stack([np.bincount(welding.index[usable], unit[usable, a], minlength=k)
                             for a in range(3)])
    length = np.linalg.norm(total, axis=1)
    nw = normals[welding.keep]
    copies = np.bincount(welding.index, minlength=k)
    mean = (copies > 1) & (length > 1e-6 * np.bincount(welding.index[usable], minlength=k))
    nw[mean] = total[mean] / length[mean, None]
    return vw, fw, nw


def welded_queries(query, welding):
    """``(rows, where)``: the welded mesh's rows to estimate at for the vertex indices
    ``query`` (q,) (each position once, ascending), and the row of ``rows`` that answers
    each query entry."""
    rows, where = np.unique(welding.index[query], return_inverse=True)
    return rows, where.ravel()


def expand_rows(result, where):
    """``result`` (a :class:`meshcurv.CurvatureResult`, or a list of them) with its per-row
    arrays taken at ``where``: one row per query entry again."""
    if isinstance(result, list):
        return [expand_rows(r, where) for r in result]
    n = len(result)
    return replace(result, **{f.name: getattr(result, f.name)[where] for f in fields(result)
                              if isinstance(getattr(result, f.name), np.ndarray)
                              and len(getattr(result, f.name)) == n})
