"""Faces wound coherently and outward: where a mesh's triangles are wound against their
neighbours (two faces running through a shared edge in the same direction), the face
normals - and with them the normals' orientation and every curvature's sign - flip from face
to face; where a closed surface is wound inward (a mirrored model), every sign is flipped.
:func:`coherent_faces` turns such faces so that each connected piece is wound one way,
outward where the piece is closed (positive enclosed volume), and as most of its area was
wound where it is open; what MeshLab's "Re-Orient all faces coherently" and trimesh's
``repair.fix_winding`` and ``fix_inversion`` do. Coherent open meshes and outward closed
ones are not touched. A triangle listed twice (a double-sided export, the same triangle wound
both ways; a mesh merged with part of itself) counts once, as first listed: its copies would
otherwise cancel or double its face normal and join nothing in the winding."""

import numpy as np
from numba import njit

from ..neighbors.kring import edge_adjacency

__all__ = ["coherent_faces", "directed_edge_counts"]


@njit(cache=True)
def directed_edge_counts(faces, indptr, indices):
    """How many faces run through each directed edge: (nnz,) int32 aligned with ``indices``.

    ``faces`` (m, 3) int64; ``indptr, indices`` the mesh's
    :func:`meshcurv.neighbors.edge_adjacency` (rows sorted). Each directed edge a -> b of a
    face is counted at b's place in a's row. A count above 1: faces wound against each
    other; 0: an edge of one face only (a border) or run through one way only. Degenerate
    edges (a == b) are skipped.
    """
    count = np.zeros(indices.shape[0], dtype=np.int32)
    for f in range(faces.shape[0]):
        for c in range(3):
            a = faces[f, c]
            b = faces[f, (c + 1) % 3]
            if a == b:
                continue
            lo = indptr[a]
            hi = indptr[a + 1]
            while lo < hi:                      # b's place in a's sorted row
                mid = (lo + hi) // 2
                if indices[mid] < b:
                    lo = mid + 1
                else:
                    hi = mid
            count[lo] += 1
    return count


@njit(cache=True)
def _piece_volumes(vertices, faces, piece, n_pieces, origin):
    """Signed volume (times 6) enclosed by each piece's faces about ``origin`` (3,), and the
    sum of the faces' absolute contributions: two (n_pieces,) float64 arrays; faces with a
    non-finite corner are left out."""
    volume = np.zeros(n_pieces)
    scale = np.zeros(n_pieces)
    for f in range(faces.shape[0]):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        a0, a1, a2 = (vertices[i, 0] - origin[0], vertices[i, 1] - origin[1],
                      vertices[i, 2] - origin[2])
        b0, b1, b2 = (vertices[j, 0] - origin[0], vertices[j, 1] - origin[1],
                      vertices[j, 2] - origin[2])
        c0, c1, c2 = (vertices[k, 0] - origin[0], vertices[k, 1] - origin[1],
                      vertices[k, 2] - origin[2])
        det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
        if np.isfinite(det):
            volume[piece[f]] += det
            scale[piece[f]] += abs(det)
    return volume, scale


@njit(cache=True)
def _propagate_turns(indptr, indices, clash, n_faces):
    """Breadth-first over the faces joined by manifold edges: ``turn[g]`` (0/1) such that
    faces whose edge ``clash`` says they run the same way (1) end up opposite; returns
    ``(turn, piece)``, the piece (connected component) of each face, numbered in the order
    of its lowest face. Any graph's pieces, with ``clash`` 0."""
    turn = np.zeros(n_faces, dtype=np.int8)
    piece = np.full(n_faces, -1, dtype=np.int64)
    queue = np.empty(n_faces, dtype=np.int64)
    n_pieces = 0
    for start in range(n_faces):
        if piece[start] >= 0:
            continue
        piece[start] = n_pieces
        head = 0
        tail = 1
        queue[0] = start
        while head < tail:
            g = queue[head]
            head += 1
            for j in range(indptr[g], indptr[g + 1]):
                h = indices[j]
                if piece[h] < 0:
                    piece[h] = n_pieces
                    turn[h] = turn[g] ^ clash[j]
                    queue[tail] = h
                    tail += 1
        n_pieces += 1
    return turn, piece


def coherent_faces(vertices, faces, adjacency=None):
    """``(faces, n_turned, n_repeated)``: ``faces`` ((m', 3) int64) with the rows that were
    wound against their neighbours, or inward on a closed piece, reversed, and how many;
    ``faces`` itself and 0, 0 where there are none. Faces repeating an earlier face's three
    vertices, in any order and winding, are left out (``n_repeated`` of them, m' = m -
    n_repeated).

    Each connected piece (faces joined through edges two faces share) is wound like its first
    face, then turned as a whole to face outward where it is closed (no edge with one face:
    positive enclosed volume), else to keep the winding of most of its area. Edges of three
    or more faces join nothing; a piece that cannot be wound coherently (a Moebius strip)
    keeps the winding its spanning tree gives.
    ``adjacency``: the mesh's :func:`meshcurv.neighbors.edge_adjacency`, if already made.
    """
    f = np.asarray(faces, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    if len(f) == 0:
        return f, 0, 0
    indptr, indices = edge_adjacency(f, len(v)) if adjacency is None else adjacency
    counts = directed_edge_counts(f, indptr, indices)
    # a repeated face runs through an edge one way a second time (its copy wound alike, or a
    # neighbour across an edge wound like its reversed copy): only lone triangles listed both
    # ways take the first path with a repeat (their face normals cancel: NaN there)
    if not (counts > 1).any():
        return (*_outward_closed_pieces(v, faces, indptr, indices, counts), 0)
    first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)[1]
    n_repeated = len(f) - len(first)
    if n_repeated:
        f = f[np.sort(first)]
    m = len(f)
    a = f.ravel()
    b = f[:, [1, 2, 0]].ravel()
    owner = np.repeat(np.arange(m), 3)
    proper = a != b
    a, b, owner = a[proper], b[proper], owner[proper]
    key = np.minimum(a, b) * len(v) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    key, forward, owner = key[order], (a < b)[order], owner[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    size = np.diff(np.r_[starts, len(key)])
    pairs = starts[size == 2]
    g, h = owner[pairs], owner[pairs + 1]
    clash = (forward[pairs] == forward[pairs + 1]).astype(np.int8)
    # the faces' graph through those edges, CSR
    rows, cols = np.r_[g, h], np.r_[h, g]
    by_row = np.argsort(rows, kind="stable")
    graph_ptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=m))]
    turn, piece = _propagate_turns(graph_ptr, cols[by_row], np.r_[clash, clash][by_row], m)
    # each piece as a whole: outward where closed, else as most of its area was wound
    oriented = np.where(turn[:, None] == 1, f[:, ::-1], f)
    with np.errstate(invalid="ignore", over="ignore"):      # NaN vertices: NaN, left out
        p = v[oriented] - np.nanmean(v, axis=0)
        cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        volume = np.einsum("ij,ij->i", p[:, 0], cross)
        area = np.linalg.norm(cross, axis=1)
    n_pieces = int(piece.max()) + 1
    open_piece = np.zeros(n_pieces, dtype=bool)
    open_piece[piece[owner[starts[size == 1]]]] = True
    volume_sum = np.bincount(piece, weights=np.nan_to_num(volume), minlength=n_pieces)
    turned_area = np.bincount(piece, weights=np.nan_to_num(area) * turn, minlength=n_pieces)
    kept_area = np.bincount(piece, weights=np.nan_to_num(area) * (1 - turn), minlength=n_pieces)
    flip_piece = np.where(open_piece, turned_area > kept_area, volume_sum < 0)
    turn = turn.astype(bool) ^ flip_piece[piece]
    out = f.copy()
    out[turn] = f[turn][:, ::-1]
    return out, int(turn.sum()), n_repeated


def _outward_closed_pieces(v, faces, indptr, indices, counts):
    """:func:`coherent_faces` of a coherently wound mesh: the pieces (vertices joined by
    edges) that are closed (every edge run through both ways) and enclose a negative volume
    - wound inward, e.g. after a mirroring - turned; ``faces`` itself where there is none."""
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    # the pieces of the vertices' graph: its breadth-first search with nothing to turn
    vertex_piece = _propagate_turns(indptr, indices, np.zeros(len(indices), np.int8), n)[1]
    n_pieces = int(vertex_piece.max(initial=-1)) + 1
    border = np.zeros(n_pieces, dtype=bool)
    one_way = np.flatnonzero(counts == 0)          # entries of border edges: their rows
    border[vertex_piece[np.searchsorted(indptr, one_way, side="right") - 1]] = True
    if border.all():
        return faces, 0
    piece = vertex_piece[f[:, 0]]
    with np.errstate(invalid="ignore"):
        origin = np.nanmean(v, axis=0)
    volume, scale = _piece_volumes(v, f, piece, n_pieces, origin)
    inward = ~border & (volume < -1e-9 * scale)
    if not inward.any():
        return faces, 0
    turn = inward[piece]
    out = f.copy()
    out[turn] = f[turn][:, ::-1]
    return out, int(turn.sum())
