"""Clean, finely sampled surfaces: each row's curvature moved towards its ring jet's where the
jet is measurably the more accurate.

The circle fits of a ball of ~100 points fit arcs of constant curvature to its normal
sections; where the curvature varies across the ball (ellipsoids, random samplings of curved
surfaces) they keep a bias that shrinks with the radius only while the balls keep enough
points. A quartic height fit over a vertex's 3-ring (:mod:`meshcurv.fit.ring_jet`; a cloud
point's :data:`CLOUD_NEIGHBORS` nearest) has a curvature error of the sampling's order h^3
there, and under noise multiplies it. Each row takes

    S = S_circles + w (S_jet - S_circles),   w = max(0, 1 - sigmas^2 e^2 / d^2)

with d the difference of the two shape operators and e the jet's expected error: an error
its residuals explain, plus its change from the small support to the larger one (the share
of the shape beyond the quartic that the residuals miss: trimesh's coarse tori, where the
3-ring turns far around the tube). With sigmas = 1, w is the inverse-variance weight of the
two estimates when d^2 is the sum of their squared errors; larger margins take the jet only
where it differs from the circle fits by more than sigmas times its own expected error, and
then only by the part beyond: under noise d is of the order of e and the jet is passed by.
Rows with w = 0 keep their bits. The residuals' part and the margin depend on the support:

- a mesh's 3-ring (:data:`MESH_SIGMAS` = 3): the standard error independent residuals give,
  :func:`meshcurv.fit.ring_jet.ring_jet`'s misfit bound over sqrt(rows - 15). Rings are
  whole, nearly symmetric about the vertex, and there the error the residuals do not show
  is small: the actual error over that standard error had a median of 0.4-0.9 on clean
  ellipsoid icospheres and decimated meshes and 0.7-0.9 under noise, whose 90 % quantile
  (1.4-1.7) three standard errors clear.
- a cloud's nearest points (:data:`CLOUD_SIGMAS` = 2): the misfit bound itself, the most
  the residuals could move the entries were they the shape's rather than noise. A set of
  nearest points ends where a regular grid's rows happen to end, asymmetric about the point,
  and the jet takes up the grid's odd-order pattern, which the residuals hide: on torus
  grids of 120 x 30 and 240 x 60 points the actual error over the standard error had a
  median of 1.7-2.5 and a 90 % quantile of 6; with the standard error and a margin of 3
  (or 4) those clouds lost 1.16x and 1.32x (1.06x, 1.15x), with the bound and a margin of 1
  1.06x and 1.22x.

Measured once with a script (mean |dk|, circle fits -> blended, MeshLab's best on the same
mesh in brackets; ``--accuracy-cases`` of ``scripts/compare_meshlab.py``): clean ellipsoid
3 / 1 / 0.5 icospheres of 2562 / 10242 vertices 0.096 / 0.016 -> 0.031 / 0.0048 (QF 0.017 /
0.0052), 2 / 1.5 / 1 of 642 / 2562 0.013 / 0.0018 -> 0.0069 / 0.0013, 642 random points
0.041 -> 0.034 (APSS 0.030), MeshLab's 2 % decimation 0.047 -> 0.029 (APSS 0.013); the
benchmark clouds with exact positions, mean |dH| 0.0002-0.0006 -> 0.00012-0.00046 (their
normals exact) and 0.0023-0.015 -> 0.00004-0.00095 (normals of sigma_xi 0.1 and 0.2: the
jet uses positions alone); ellipsoid 3 / 2 / 1 of 5000 random points 0.017 / 0.019 ->
0.0046 / 0.0077 (mesh / points), random monkey saddle points 0.0064 -> 0.00001; every noisy
case of the script, trimesh's coarse tori, icosahedra, spikes and terrains keep their mean
|dk| (to 1e-9), and no row took a jet on noisy tori, ellipsoids and egg crates (noise 0.003 %
to 0.3 % of the diagonal, meshes and points) and the benchmark's torus_010000 and
goursat_025000 with position noise 0.1 (no normals). Where the mesh rule loses: MeshLab's decimations of a torus to 20 % and 5 %, 1.01x and
1.003x (38 and 1 rows of 2880 and 720 take a jet, the circle fits were 3x more accurate
there). The bound at 2 on meshes too (the rule before): the ellipsoids above 0.044 / 0.0070,
0.011 / 0.0017, 0.036, 0.044. Also measured: on clouds the standard error let noise in at 2
(a terrain cloud's maximum |dk| 0.06 -> 1.7).
"""

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from .fit import ring_jet as ring_jet_kernel
from .neighbors import kring, power_of_two_scale
from .neighbors.grid import spatial_order
from .pipeline import BLOCK
from .result import Status

__all__ = ["MESH_SIGMAS", "CLOUD_SIGMAS", "MESH_RINGS", "CLOUD_NEIGHBORS", "MAX_RING",
           "ring_jets", "jet_blocks", "blend"]

# The margin of the jet's expected error its difference from the circle fits must exceed:
# three standard errors on a mesh's rings, twice the misfit bound on a cloud's nearest points
# (see the module's docstring).
MESH_SIGMAS = 3.0
CLOUD_SIGMAS = 2.0
# The supports: a mesh vertex's 3-ring and 4-ring (by hops over edges), a cloud point's
# nearest neighbours in the number those rings hold on a regular triangle mesh (36 and 60
# besides the vertex).
MESH_RINGS = 4
CLOUD_NEIGHBORS = (36, 60)
# The most vertices a mesh vertex's 4-ring may hold for a jet: 16 times a regular mesh's 60.
# Beyond, near the hub of a fan (a cylinder's cap triangulated from its centre, a UV
# sphere's pole of many sections) the rings reach around the fan and the vertex gets no jet:
# this bounds the lists at 1024 entries a vertex.
MAX_RING = 1024


def ring_jets(v, f, query, normals, unit=1.0, cell=None, block=BLOCK):
    """The ring jets at the vertices ``query`` ((m,) int64 rows of ``v`` (n, 3)) along their
    unit ``normals`` (m, 3): ``(small, large, error, frame_u, rows_small)`` as
    :func:`meshcurv.fit.ring_jet.ring_jet` gives them, over each vertex's 3- and 4-ring of the
    faces ``f`` or, without faces (None), its :data:`CLOUD_NEIGHBORS` nearest points; of
    ``v * unit`` (a power of two that keeps the squares of the supports' sizes in float64,
    :func:`meshcurv.neighbors.power_of_two_scale`): curvatures in units of ``1 / unit``
    model units. ``cell`` and ``block`` as in :func:`jet_blocks`, whose blocks these are."""
    m = len(query)
    small, large = np.empty((m, 3)), np.empty((m, 3))
    error, frame_u = np.empty(m), np.empty((m, 3))
    rows_small = np.zeros(m, dtype=np.int64)
    for at, *fits in jet_blocks(v, f, query, normals, unit, cell, block):
        small[at], large[at], error[at], frame_u[at], rows_small[at] = fits
    return small, large, error, frame_u, rows_small


def jet_blocks(v, f, query, normals, unit=1.0, cell=None, block=BLOCK):
    """:func:`ring_jets` a block of at most ``block`` rows at a time: yields ``(at, small,
    large, error, frame_u, rows_small)``, ``at`` the block's positions in ``query`` and the
    others its rows of :func:`ring_jets`' arrays. A cloud's rows are searched and fitted
    grid cell by grid cell of edge ``cell`` (scaled units; None: in their order), which keeps
    each block's neighbours in cache (300k random-order points: the k-d tree's queries 1.7
    -> 1.1 s); each row's result is its own whatever the order."""
    m = len(query)
    points = np.ascontiguousarray(np.asarray(v, dtype=np.float64) * unit)
    order = np.arange(m)
    if f is not None:
        adjacency = kring.edge_adjacency(f, len(v))
        work = kring.KringWork(len(v))
    else:
        finite = np.flatnonzero(np.isfinite(points).all(axis=1))
        # over the scaled points themselves where all are finite (no copy)
        tree = None if len(finite) < 2 else cKDTree(
            points if len(finite) == len(points) else points[finite], copy_data=False)
        if cell is not None:
            order = spatial_order(points[query], cell)
    for lo in range(0, m, block):
        at = order[lo:lo + block]
        rows = query[at]
        if f is not None:
            indptr, indices, inner = kring.hop_rings(
                adjacency[0], adjacency[1], rows, MESH_RINGS, work.stamp, work.queue,
                work.take_tags(len(rows)), MAX_RING)
        else:
            indptr, indices, inner = _nearest(points, finite, tree, rows)
        out = (np.empty((len(at), 3)), np.empty((len(at), 3)), np.empty(len(at)),
               np.empty((len(at), 3)), np.empty(len(at), dtype=np.int64))
        ring_jet_kernel.ring_jet(points, rows, np.ascontiguousarray(normals[at]), indptr,
                                 indices, inner, *out)
        yield (at, *out)


def _nearest(points, finite, tree, rows):
    """CSR lists of the :data:`CLOUD_NEIGHBORS` nearest finite points of each row (itself
    left in: the kernel skips it; none for a row that is not finite, and only those the
    k-d tree finds at a finite distance), and the small support's share of each list."""
    counts = np.zeros(len(rows), dtype=np.int64)
    indices = np.zeros(0, dtype=np.int64)
    x = points[rows]
    ok = np.isfinite(x).all(axis=1)
    if tree is not None and ok.any():
        k = min(CLOUD_NEIGHBORS[1] + 1, len(finite))
        with np.errstate(over="ignore", invalid="ignore"):
            _, near = tree.query(x[ok], k=k, workers=-1)
        near = near.reshape(-1, k)
        found = near < len(finite)           # beyond float64's range: reported as missing
        counts[ok] = found.sum(axis=1)
        indices = finite[near[found]]
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return indptr, indices, np.minimum(counts, CLOUD_NEIGHBORS[0] + 1)


def blend(result, v, f, query):
    """``result`` (rows ``query`` of ``v``, the circle fits' estimate, with its normals) with
    each valid row moved towards its ring jet's curvature by the weight w of the module's
    docstring, and w as its ``jet_share`` ((m,) in [0, 1], 0 where the row is not valid): k1,
    k2, d1 and d2 of rows with w > 0 replaced (d2 = n x d1, the normal kept), the other rows'
    bits kept. A block of rows at a time (:func:`jet_blocks`): beyond the outputs' copies,
    memory for one block's fits."""
    out = replace(result, jet_share=np.zeros(len(result)))
    rows = np.flatnonzero(result.status == Status.OK)
    if not len(rows):
        return out
    # in the units of coordinates scaled by a power of two (exact), where the shape
    # operators' squares stay in float64 whatever the input's scale
    unit = power_of_two_scale(result.radius)
    copied = False
    for at, small, large, error, tu, rows_small in jet_blocks(
            v, f, np.asarray(query)[rows], result.normals[rows], unit, result.radius * unit):
        at = rows[at]
        n = result.normals[at]
        tv = np.cross(n, tu)
        circles = _shape_in_frame(result.k1[at] / unit, result.k2[at] / unit, result.d1[at],
                                  tu, tv)
        diff = small - circles
        with np.errstate(invalid="ignore", divide="ignore"):
            if f is None:
                sigmas, expected = CLOUD_SIGMAS, error ** 2
            else:
                sigmas = MESH_SIGMAS
                expected = error ** 2 / (rows_small - ring_jet_kernel.COEFFICIENTS)
            expected = expected + _norm2(small - large)
            weight = np.clip(1.0 - sigmas ** 2 * expected / _norm2(diff), 0.0, 1.0)
        weight = np.where(np.isfinite(weight), weight, 0.0)
        took = weight > 0.0
        if not took.any():
            continue
        if not copied:
            out.k1, out.k2 = result.k1.copy(), result.k2.copy()
            out.d1, out.d2 = result.d1.copy(), result.d2.copy()
            copied = True
        k1, k2, c, si = _eigen(circles[took] + weight[took, None] * diff[took])
        d1 = c[:, None] * tu[took] + si[:, None] * tv[took]
        at = at[took]
        out.k1[at], out.k2[at], out.d1[at] = k1 * unit, k2 * unit, d1
        out.d2[at] = np.cross(n[took], d1)
        out.jet_share[at] = weight[took]
    return out


def _shape_in_frame(k1, k2, d1, tu, tv):
    """``(S_uu, S_uv, S_vv)`` (m, 3) of the shape operator with curvatures k1 >= k2 and first
    direction d1 (unit, in the plane of tu, tv) in the frame (tu, tv)."""
    c = np.einsum("ij,ij->i", d1, tu)
    s = np.einsum("ij,ij->i", d1, tv)
    return np.column_stack([k1 * c * c + k2 * s * s, (k1 - k2) * c * s,
                            k1 * s * s + k2 * c * c])


def _norm2(s):
    """Half the squared Frobenius norm of shape operators given as (S_uu, S_uv, S_vv) rows:
    the mean of the squared eigenvalues."""
    return 0.5 * (s[:, 0] ** 2 + 2.0 * s[:, 1] ** 2 + s[:, 2] ** 2)


def _eigen(s):
    """Eigenvalues k1 >= k2 of shape operators (S_uu, S_uv, S_vv) (m, 3) and (cos, sin) of the
    first eigenvector's angle in the frame."""
    mean = 0.5 * (s[:, 0] + s[:, 2])
    half = 0.5 * (s[:, 0] - s[:, 2])
    amp = np.hypot(half, s[:, 1])
    theta = 0.5 * np.arctan2(s[:, 1], half)
    return mean + amp, mean - amp, np.cos(theta), np.sin(theta)
